"""Assistive devices (``docs/assistance.md``): the device torque taken off the inverse-dynamics
moments, its sign convention, its work, the profile files and their errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from musclemetab.redundancy.assistance import (
    CYCLE_AXIS_HEADER,
    apply_assistance,
    augmentation_factor_W_per_kg,
    device_work,
    plantarflexion_assistance,
    read_assistance,
)
from musclemetab.errors import DataMismatchError, InputFileError, OptionError, UnknownCoordinateError
from musclemetab.io import read_table, storage_from_arrays, write_storage

#: a short window of the normal trial's push-off (toe-off about 1.28 s), where the ankle moment peaks
SIGN_WINDOW = (1.05, 1.25)
PLANTARFLEXORS = ("soleus_r", "gasmed_r", "gaslat_r")


def _write_profile(path, x, columns, header=()):
    write_storage(path, storage_from_arrays(x, columns), comments=list(header))
    return path


# ---------------------------------------------------------------------------- files, no solve
def test_plantarflexion_profile_peaks_at_the_given_percent_with_the_given_torque(tmp_path):
    """The generator's file: 0.2 N m/kg x 72.6 kg = 14.52 N m of plantarflexion (negative
    ankle_angle_r) at 50 % of the cycle, zero before 25 % and after 62.5 %, over the cycle."""
    p = plantarflexion_assistance(tmp_path / "pf.sto", 72.6)
    assert CYCLE_AXIS_HEADER in p.read_text()
    prof = read_assistance(p)
    assert prof.axis == "cycle_pct" and prof.coordinates == ("ankle_angle_r",)
    x, tau = prof.x, prof.torque_Nm[:, 0]
    assert tau[np.argmin(tau)] == pytest.approx(-14.52) and x[np.argmin(tau)] == pytest.approx(50.0)
    assert np.all(tau[(x < 25) | (x > 62.5)] == 0) and np.all(tau <= 0)
    # mapped onto a cycle 0.62-1.70 s: 50 % is 1.16 s; 110 % wraps to 10 % (zero)
    at = prof.torque_at([1.16, 0.62 + 1.1 * 1.08], ["ankle_angle_r", "knee_angle_r"], 2.0, (0.62, 1.70))
    assert at.tolist() == [[pytest.approx(-29.04), 0.0], [0.0, 0.0]]


def test_csv_profile_over_time_and_over_the_cycle(tmp_path):
    (tmp_path / "t.csv").write_text("time,knee_angle_r_moment\n0,1\n1,3\n")
    prof = read_assistance(tmp_path / "t.csv")
    assert prof.axis == "time_s" and prof.coordinates == ("knee_angle_r",)
    assert prof.torque_at([0.5, 2.0], ["knee_angle_r"]).ravel().tolist() == [2.0, 3.0]  # held after its end
    (tmp_path / "c.csv").write_text("cycle_pct,knee_angle_r\n0,0\n50,10\n100,0\n")
    prof = read_assistance(tmp_path / "c.csv")
    assert prof.axis == "cycle_pct"
    assert prof.torque_at([1.5, 2.5], ["knee_angle_r"], cycle_s=(1.0, 2.0)).ravel().tolist() == [10.0, 10.0]


def test_bad_profiles_are_refused_naming_file_and_column(tmp_path):
    moments = np.zeros((11, 2))
    t = np.linspace(0.5, 1.5, 11)
    dofs = ["ankle_angle_r", "knee_angle_r"]
    model = dofs + ["hip_flexion_r", "ankle_angle_l"]
    kw = dict(window_s=(0.6, 1.4), side="r", model_coordinates=model, body_mass_kg=70.0)
    ok = _write_profile(tmp_path / "ok.sto", [0.5, 1.5], {"ankle_angle_r": [-10.0, -10.0], "ankle_angle_l": [5, 5]})
    out = apply_assistance(t, moments, dofs, read_assistance(ok), 0.5, **kw)  # the left column: the left leg's
    assert np.allclose(out[:, 0], 5.0) and np.allclose(out[:, 1], 0.0)
    bad = _write_profile(tmp_path / "typo.sto", [0.5, 1.5], {"ankle_angel_r": [1.0, 2.0]})
    with pytest.raises(UnknownCoordinateError, match=r"typo\.sto: column 'ankle_angel_r'.*near: ankle_angle_r"):
        apply_assistance(t, moments, dofs, read_assistance(bad), 1.0, **kw)
    hip = _write_profile(tmp_path / "hip.sto", [0.5, 1.5], {"hip_flexion_r": [10.0, 20.0]})
    with pytest.raises(OptionError, match=r"hip\.sto: column 'hip_flexion_r' is not a DOF of this problem"):
        apply_assistance(t, moments, dofs, read_assistance(hip), 1.0, **kw)
    short = _write_profile(tmp_path / "short.sto", [0.7, 1.5], {"ankle_angle_r": [10.0, 20.0]})
    with pytest.raises(DataMismatchError, match=r"short\.sto: the assistance profile covers 0\.7-1\.5 s but the solve "
                                                r"window is 0\.6-1\.4 s"):
        apply_assistance(t, moments, dofs, read_assistance(short), 1.0, **kw)
    per_kg = _write_profile(tmp_path / "perkg.sto", [0.5, 1.5], {"ankle_angle_r": [-0.2, 0.0]})
    with pytest.raises(DataMismatchError, match=r"perkg\.sto: .*'ankle_angle_r'.*normalised to body mass"):
        apply_assistance(t, moments, dofs, read_assistance(per_kg), 1.0, **kw)
    nmm = _write_profile(tmp_path / "nmm.sto", [0.5, 1.5], {"ankle_angle_r": [-14000.0, 0.0]})
    with pytest.raises(DataMismatchError, match=r"nmm\.sto: column 'ankle_angle_r' reaches.*not N mm"):
        apply_assistance(t, moments, dofs, read_assistance(nmm), 1.0, **kw)
    pct = _write_profile(tmp_path / "pct.sto", [0.0, 120.0], {"ankle_angle_r": [1.0, 2.0]}, [CYCLE_AXIS_HEADER])
    with pytest.raises(DataMismatchError, match=r"pct\.sto: a profile over the gait cycle runs from 0 to 100 %"):
        read_assistance(pct)
    (tmp_path / "nan.csv").write_text("time,ankle_angle_r\n0,1\n1,nan\n")
    with pytest.raises(InputFileError, match=r"nan\.csv: column 'ankle_angle_r' is nan at data row 2"):
        read_assistance(tmp_path / "nan.csv")
    with pytest.raises(OptionError, match="--assistance-gain = nan is not a factor on the device torque"):
        apply_assistance(t, moments, dofs, read_assistance(ok), float("nan"), **kw)
    # a profile of the other leg alone would do nothing to this leg: refused, unless that leg is solved too
    left = _write_profile(tmp_path / "left.sto", [0.5, 1.5], {"ankle_angle_l": [-10.0, -10.0]})
    with pytest.raises(OptionError, match=r"left\.sto: its columns \(ankle_angle_l\) name none of the solved leg's "
                                          r"coordinates \(side r: ankle_angle_r, knee_angle_r\)"):
        apply_assistance(t, moments, dofs, read_assistance(left), 1.0, **kw)
    assert np.all(apply_assistance(t, moments, dofs, read_assistance(left), 1.0, other_leg_solved=True, **kw) == 0.0)


def test_device_work_of_a_constant_torque_on_a_sine_motion(tmp_path):
    """Hand-worked: a constant torque tau about a joint moving as q = A sin(2 pi t / T) over one
    period does tau * 2A of positive work (q rising from -A to A) and -tau * 2A of negative work
    (q falling from A to -A); mean powers over T. Augmentation factor: (P+ - |P-|)/0.41."""
    tau, amp, period = 10.0, 0.3, 1.0
    t = np.arange(0.0, 3.0 + 1e-9, 0.01)
    q = amp * np.sin(2 * np.pi * t / period)[:, None]
    prof = read_assistance(_write_profile(tmp_path / "c.sto", [0.0, 3.0], {"knee_angle_r": [tau, tau]}))
    work = device_work(prof, 1.0, ["knee_angle_r"], t, q, (1.0 + 0.25, 2.0 + 0.25))  # q from A down and up again
    assert work["positive_work_J"] == pytest.approx(tau * 2 * amp, rel=2e-3)
    assert work["negative_work_J"] == pytest.approx(-tau * 2 * amp, rel=2e-3)
    assert work["mean_positive_power_W"] == pytest.approx(tau * 2 * amp / period, rel=2e-3)
    half = device_work(prof, 0.5, ["knee_angle_r"], t, q, (1.25, 2.25))
    assert half["positive_work_J"] == pytest.approx(0.5 * work["positive_work_J"])
    assert augmentation_factor_W_per_kg(0.1, -0.02) == pytest.approx(0.08 / 0.41)
    assert augmentation_factor_W_per_kg(0.1, -0.02, carried_cost_W_per_kg=0.05) == pytest.approx(0.08 / 0.41 - 0.05)


# ---------------------------------------------------------------------------- the sign convention
@pytest.fixture(scope="module")
def ankle_device(example, tmp_path_factory):
    """A 'device' whose torque is the ID ankle moment itself (the ID file's samples, column
    ankle_angle_r_moment)."""
    id_table = read_table(example.id["normal"])
    path = tmp_path_factory.mktemp("device") / "ankle_id.sto"
    return _write_profile(path, id_table.index, {"ankle_angle_r_moment": id_table["ankle_angle_r_moment"]})


@pytest.mark.opensim
def test_a_device_supplying_the_ankle_moment_silences_the_ankle_muscles(example, ankle_device):
    """Sign convention: a device torque equal to the ID ankle moment (gain 1) leaves the ankle's net
    moment to no one: the triceps surae, which supply the push-off's
    plantarflexion moment unassisted, fall below 15 % of their unassisted activity (time
    integral of the activations; what stays balances the stretched muscles' passive force) and
    the ankle reserve grows by no more than 0.5 N m. Had the device been added to the ID moment
    (the opposite sign), they would supply twice the moment and be more active than unassisted."""
    from musclemetab.redundancy.run import solve_files

    files = (example.model, example.ik["normal"], example.id["normal"], "effort-gen")
    free = solve_files(*files, window=SIGN_WINDOW)
    held = solve_files(*files, window=SIGN_WINDOW, assistance=ankle_device)
    def triceps(sol):  # the time integral of the triceps surae's activations
        return float(np.trapezoid(sol.activation[:, [sol.muscles.index(m) for m in PLANTARFLEXORS]].sum(axis=1),
                                  sol.time_s))

    activity = {"free": triceps(free), "held": triceps(held)}
    assert activity["held"] < 0.15 * activity["free"], activity
    assert held.record.reserve_max_abs_Nm["ankle_angle_r"] <= free.record.reserve_max_abs_Nm["ankle_angle_r"] + 0.5
    device = held.record.assistance
    assert device.gain == 1.0 and device.dofs == ("ankle_angle_r",) and device.axis == "time_s"
    # the device's recorded torque is the ID's ankle moment at the nodes
    id_table = read_table(example.id["normal"])
    assert np.allclose(device.torque_Nm["ankle_angle_r"],
                       np.interp(held.time_s, id_table.index, id_table["ankle_angle_r_moment"]))


def test_solve_command_refuses_a_bad_device_in_one_line(example, tmp_path, capsys):
    """``musclemetab solve --assistance``: a column naming no coordinate of the model is one error
    line naming the file and the column, status 1, nothing written; a gain without a device too."""
    from musclemetab.commands import main

    bad = _write_profile(tmp_path / "device.sto", [0.5, 2.0], {"ankle_angel_r": [-10.0, -10.0]})
    base = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]),
            "--window", "1.05:1.25", "--no-progress"]
    assert main(base + ["--assistance", str(bad), "--out", str(tmp_path / "a")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{bad}: column 'ankle_angel_r' names no coordinate of the model" in err[0], err
    assert not (tmp_path / "a" / "solution.sto").exists()
    assert main(base + ["--assistance-gain", "2", "--out", str(tmp_path / "b")]) == 1
    assert "--assistance-gain belongs to a device: give --assistance DEVICE.sto" in capsys.readouterr().err
    # the left ankle's profile on the right leg's solve: it did nothing (0 J, the unassisted objective)
    left = plantarflexion_assistance(tmp_path / "exo_left.sto", example.body_mass_kg, dof="ankle_angle_l")
    assert main(base + ["--assistance", str(left), "--out", str(tmp_path / "c")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{left}: its columns (ankle_angle_l) name none of the solved leg's coordinates " \
        "(side r: ankle_angle_r, knee_angle_r, hip_flexion_r" in err[0], err
    # a profile over the cycle on a window holding no gait cycle: the cycle must be given
    pf = plantarflexion_assistance(tmp_path / "exo.sto", example.body_mass_kg)
    assert main(base + ["--assistance", str(pf), "--out", str(tmp_path / "d")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{pf}: a profile over the gait cycle needs the gait cycle, and none was found in the " \
        "solve window 1.05-1.25 s" in err[0] and err[0].endswith("--assistance-cycle T0:T1 (or --cycle)"), err
    assert not any((tmp_path / d / "solution.sto").exists() for d in "cd")


def test_a_study_refuses_a_device_of_the_other_leg_when_read(example, tmp_path):
    """The subject's right leg with a profile of the left ankle alone: refused when the study file
    is read (it ran, and every assisted trial reported a saving of 0), naming the file and its
    columns; the same file is a leg's device when the subject's two legs are solved."""
    from musclemetab.study import study_from_dict

    left = plantarflexion_assistance(tmp_path / "exo_left.sto", example.body_mass_kg, dof="ankle_angle_l")
    with pytest.raises(OptionError, match=r"subject 'sub1': 'assistance': .*exo_left\.sto: its columns "
                                          r"\(ankle_angle_l\) name none of the right leg's coordinates \(side \"r\"\)"):
        _assisted_study(example, left, tmp_path / "study")
    per_kg = _write_profile(tmp_path / "perkg.sto", [0.0, 100.0], {"ankle_angle_r": [-0.2, 0.0]}, [CYCLE_AXIS_HEADER])
    with pytest.raises(DataMismatchError, match=r"subject 'sub1': 'assistance': .*perkg\.sto: .*normalised to body "
                                                r"mass"):
        _assisted_study(example, per_kg, tmp_path / "study")
    both = _assisted_study(example, left, tmp_path / "study", side="both", trial_keys={"cycle": "auto"})
    assert [t.name for t in both.subjects[0].trials] == ["normal", "normal_assist-1"]


def test_a_study_refuses_a_device_column_of_no_coordinate_before_any_unit_runs(example, tmp_path):
    """A column naming no coordinate of the subject's model (it needs the model): the study refuses
    to run, one line naming the study's trial, the file and the column, before any unit runs (the
    unassisted units ran, then the assisted ones failed)."""
    from musclemetab.study.runner import run_study

    bad = _write_profile(tmp_path / "bad.sto", [0.0, 100.0], {"ankle_angle_r": [-10.0, 0.0], "hip_flexion_rr": [1, 1]},
                         [CYCLE_AXIS_HEADER])
    study = _assisted_study(example, bad, tmp_path / "study")
    with pytest.raises(UnknownCoordinateError) as err:
        run_study(study, workers=1, progress=False)
    assert str(err.value).startswith(f"subject 'sub1', trial 'normal_assist-1': 'assistance': {bad}: column "
                                     "'hip_flexion_rr' names no coordinate of the model (near: hip_flexion_r")
    assert "\n" not in str(err.value) and not (tmp_path / "study" / "units").exists()


# ---------------------------------------------------------------------------- a study's gain sweep
GAINS = (0.5, 1.0, 1.5)
TRICEPS = ("soleus_r", "gasmed_r", "gaslat_r")


def _assisted_study(example, profile, out, side="r", trial_keys=(), **assistance):
    from musclemetab.study import study_from_dict

    trial = {"name": "normal", "ik": str(example.ik["normal"]), "id": str(example.id["normal"]),
             "assistance": {"file": str(profile), **assistance}, **dict(trial_keys)}
    return study_from_dict({"name": "exo", "workflows": ["effort-gen"], "models": ["UM10", "BH04"],
                            "subjects": [{"name": "sub1", "model": str(example.model), "side": side,
                                          "body_mass_kg": example.body_mass_kg, "height_m": example.height_m,
                                          "trials": [trial]}]}, base="/", output=out)


@pytest.fixture(scope="module")
def exo_study(example, tmp_path_factory):
    """The example subject's normal trial unassisted and with the documented plantarflexion profile
    (0.2 N m/kg at 50 % of the cycle) at gains 0.5, 1 and 1.5: a study of four units."""
    from musclemetab.study.runner import run_study

    root = tmp_path_factory.mktemp("exo")
    profile = plantarflexion_assistance(root / "plantarflexion.sto", example.body_mass_kg, peak_Nm_per_kg=0.2,
                                        peak_percent=50.0)
    study = _assisted_study(example, profile, root / "study", gains=list(GAINS))
    run = run_study(study, workers=1, progress=False)
    assert not run.failed, run.failed
    return study


@pytest.mark.opensim
def test_plantarflexion_assistance_saves_triceps_energy_and_the_sweep_is_monotone(exo_study):
    """The documented example: the triceps surae's energy falls at every gain and model; the
    whole-body saving and the device's positive work grow with the gain (the work in proportion
    to it: the power is the torque times the IK's velocity); the saving is the unassisted row's
    rate less the assisted row's; the muscles' changes add up to the leg's, as do the phases'."""
    import pandas as pd

    out = exo_study.output
    results = pd.read_csv(out / "results.csv")
    assisted = results[results["assisted_from"].notna()].sort_values(["model", "assistance_gain"])
    assert set(results["trial"]) == {"normal"} | {f"normal_assist-{g:g}" for g in GAINS}
    assert (assisted["assisted_from"] == "normal").all()
    assert assisted["solve_start"].str.startswith("warm from normal (effort-gen)").all()
    for model, rows in assisted.groupby("model"):
        free = results[(results["trial"] == "normal") & (results["model"] == model)].iloc[0]
        assert rows["metabolic_saving_W_per_kg"].tolist() == pytest.approx(
            (free["whole_body_W_per_kg"] - rows["whole_body_W_per_kg"]).tolist())
        assert np.all(np.diff(rows["metabolic_saving_W_per_kg"]) > 0) and rows["metabolic_saving_W_per_kg"].min() > 0
        work = rows["device_positive_work_J"].to_numpy()
        assert np.all(np.diff(work) > 0) and work == pytest.approx(work[1] * np.asarray(GAINS), rel=1e-9)
        assert rows["augmentation_factor_W_per_kg"].tolist() == pytest.approx(
            ((rows["device_positive_power_W_per_kg"] - rows["device_negative_power_W_per_kg"].abs()) / 0.41).tolist())
    breakdown = pd.read_csv(out / "assistance.csv")
    muscles = breakdown[breakdown["level"] == "muscle"]
    triceps = muscles[muscles["part"].isin(TRICEPS)]
    assert len(triceps) == 3 * len(GAINS) * 2 and (triceps["change_J"] < 0).all(), triceps
    for (trial, model), rows in breakdown.groupby(["trial", "model"]):
        leg = rows[rows["level"] == "leg"]["change_J"].iloc[0]
        assert rows[rows["level"] == "muscle"]["change_J"].sum() == pytest.approx(leg, rel=1e-6, abs=1e-9)
        assert rows[rows["level"] == "phase"]["change_J"].sum() == pytest.approx(leg, rel=1e-6, abs=1e-9)
        assert rows[rows["level"] == "group"]["change_J"].sum() == pytest.approx(leg, rel=1e-6, abs=1e-9)


@pytest.mark.opensim
def test_the_report_draws_the_assistance_figure(exo_study, tmp_path):
    """A study with assisted trials gets the assistance figure after the others (a study without
    them has none: tests/test_report.py counts FIGURE_NAMES)."""
    from musclemetab.report.draw import draw_figure
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.plan import FIGURE_NAMES, plan_figures

    folder = read_study_folder(exo_study.output)
    assert list(plan_figures(folder)) == [*FIGURE_NAMES, "assistance"]
    entry = draw_figure(folder, tmp_path, ("png",), "assistance")
    assert entry.paths and Path(entry.paths["png"]).stat().st_size > 10_000, entry


# ---------------------------------------------------------------------------- a study trial's `states`
@pytest.mark.opensim
def test_a_study_trial_of_opensim_states_gives_the_numbers_of_the_command(exo_study, example, tmp_path):
    """A trial with ``states`` (and ``controls``) of the subject's model: one unit (workflow
    "states") whose whole-body and per-muscle tables are those ``musclemetab metabolics --states
    --cycle`` writes for the same files (the states and controls OpenSim files of the unassisted unit,
    its model.osim) over the trial's gait cycle (unit.json), and a results row with the phases and
    groups. The whole-body rate is the mean over the cycle's states worked here from the command's
    rates at every state: 2 legs x trapezoidal mean of the leg's muscles over the states inside the
    cycle / body mass + 1.2 W/kg."""
    import json

    import pandas as pd

    from musclemetab.commands import main
    from musclemetab.io import read_table
    from musclemetab.study import study_from_dict
    from musclemetab.study.runner import run_study

    unit = exo_study.output / "units" / "sub1" / "normal" / "effort-gen"
    trial = {"name": "normal", "ik": str(example.ik["normal"]), "id": str(example.id["normal"]),
             "states": str(unit / "states.sto"), "controls": str(unit / "controls.sto")}
    study = study_from_dict({"name": "states", "workflows": ["effort-gen", "effort-ten"], "models": ["UM10", "BH04"],
                             "subjects": [{"name": "sub1", "model": str(unit / "model.osim"),
                                           "body_mass_kg": example.body_mass_kg, "height_m": example.height_m,
                                           "trials": [trial]}]}, base="/", output=tmp_path / "study")
    run = run_study(study, workers=1, progress=False)
    assert not run.failed and len(run.ran) == 1, (run.failed, run.ran)
    folder = tmp_path / "study" / "units" / "sub1" / "normal" / "states"
    c = json.loads((folder / "unit.json").read_text())["cycle"]
    events = f"{c['start_s']!r},{c['toe_off_s']!r},{c['end_s']!r}"
    common = ["--states", str(unit / "states.sto"), "--controls", str(unit / "controls.sto"), "--model",
              str(unit / "model.osim"), "--mass", str(example.body_mass_kg), "--height", str(example.height_m),
              "--models", "UM10,BH04"]
    assert main(["metabolics", *common, "--cycle", events, "--out", str(tmp_path / "cli")]) == 0
    assert main(["metabolics", *common, "--out", str(tmp_path / "every")]) == 0
    cli = pd.read_csv(tmp_path / "cli" / "whole_body.csv").set_index("model")
    mine = pd.read_csv(folder / "whole_body.csv").set_index("model")
    pd.testing.assert_frame_equal(mine[cli.columns], cli)  # the study adds the costs of transport (its speed)
    cols = ["model", "muscle", "muscle_W", "muscle_W_per_kg", "share_of_leg_pct", "work_mean_W", "energy_per_cycle_J"]
    pd.testing.assert_frame_equal(pd.read_csv(folder / "per_muscle.csv")[cols],
                                  pd.read_csv(tmp_path / "cli" / "per_muscle.csv")[cols])
    # by hand, from the rates at every state (UM10); BH04's activation-heat decay counts the time since
    # the stimulation's onset from the first state evaluated, so its rates are those of the cycle's run
    every = read_table(tmp_path / "every" / "metabolics.sto")
    t = np.asarray(every.index, dtype=float)
    inside = (t >= c["start_s"] - 1e-9) & (t <= c["end_s"] + 1e-9)
    assert t[0] < c["start_s"] - 0.02 and inside.sum() < t.size  # the file's states span more than the cycle
    whole = pd.read_csv(tmp_path / "every" / "whole_body.csv").set_index("model")
    over_cycle = read_table(tmp_path / "cli" / "metabolics.sto")
    np.testing.assert_allclose(np.asarray(over_cycle.index, dtype=float), t[inside], atol=1e-12)
    for model, rates, rows in (("UM10", every, inside), ("BH04", over_cycle, slice(None))):
        muscles = [k for k in rates.columns if k.startswith(f"{model}/") and k.endswith("/total_no_basal")]
        li = rates.to_dataframe()[muscles].to_numpy().sum(axis=1)[rows]
        ti = t[inside]
        mean = np.sum((li[1:] + li[:-1]) / 2 * np.diff(ti)) / (ti[-1] - ti[0])
        want = 2 * mean / example.body_mass_kg + 1.2
        assert mine.loc[model, "whole_body_W_per_kg"] == pytest.approx(want, rel=1e-9)
        assert mine.loc[model, "duration_s"] == pytest.approx(ti[-1] - ti[0], abs=1e-9)
        assert abs(whole.loc[model, "whole_body_W_per_kg"] - want) > 1e-3  # the whole file differs
    results = pd.read_csv(tmp_path / "study" / "results.csv").set_index("model")
    assert set(results["workflow"]) == {"states"}
    assert results.loc["UM10", "whole_body_W_per_kg"] == pytest.approx(cli.loc["UM10", "whole_body_W_per_kg"])
    assert results.loc["UM10", "share_PF_pct"] > 0


@pytest.mark.opensim
def test_a_study_trial_of_opensim_states_takes_the_fiber_velocity_option(exo_study, example, tmp_path):
    """A states trial's ``fiber_velocity = "equilibrium"`` gives the rates ``musclemetab metabolics
    --states --fiber-velocity equilibrium`` writes for the same files and cycle, other than the
    default's (the derivative): the study does not ignore it. (``muscle_parameters``:
    tests/test_metabolics_states.py, on a model with metabolic probes.)"""
    import json

    import pandas as pd

    from musclemetab.commands import main
    from musclemetab.study import study_from_dict
    from musclemetab.study.runner import run_study

    unit = exo_study.output / "units" / "sub1" / "normal" / "effort-gen"
    files = {"states": str(unit / "states.sto"), "controls": str(unit / "controls.sto")}
    trials = [{"name": name, "ik": str(example.ik["normal"]), "id": str(example.id["normal"]), **files, **options}
              for name, options in (("equilibrium", {"fiber_velocity": "equilibrium"}), ("default", {}))]
    study = study_from_dict({"name": "states", "workflows": ["effort-gen"], "models": ["UM10", "BH04"],
                             "subjects": [{"name": "sub1", "model": str(unit / "model.osim"),
                                           "body_mass_kg": example.body_mass_kg, "height_m": example.height_m,
                                           "trials": trials}]}, base="/", output=tmp_path / "study")
    run = run_study(study, workers=1, progress=False)
    assert not run.failed and len(run.ran) == 2, (run.failed, run.ran)
    folder = tmp_path / "study" / "units" / "sub1" / "equilibrium" / "states"
    c = json.loads((folder / "unit.json").read_text())["cycle"]
    assert main(["metabolics", "--states", files["states"], "--controls", files["controls"], "--model",
                 str(unit / "model.osim"), "--mass", str(example.body_mass_kg), "--height", str(example.height_m),
                 "--models", "UM10,BH04", "--fiber-velocity", "equilibrium", "--cycle",
                 f"{c['start_s']!r},{c['toe_off_s']!r},{c['end_s']!r}", "--out", str(tmp_path / "cli")]) == 0
    cli = pd.read_csv(tmp_path / "cli" / "whole_body.csv").set_index("model")
    mine = pd.read_csv(folder / "whole_body.csv").set_index("model")
    pd.testing.assert_frame_equal(mine[cli.columns], cli)
    default = pd.read_csv(tmp_path / "study" / "units" / "sub1" / "default" / "states" / "whole_body.csv")
    assert (mine["whole_body_W_per_kg"] - default.set_index("model")["whole_body_W_per_kg"]).abs().max() > 0.1


def test_the_states_options_go_with_states_and_are_checked(example):
    """``fiber_velocity`` and ``muscle_parameters`` on a solved trial are refused naming the trial,
    the keys and the remedy; a value that is not one of the command's choices names them; absent,
    the unit keys of earlier studies stay as they were."""
    from musclemetab.study import plan_units, study_from_dict
    from musclemetab.study.units import unit_key

    def data(**trial):
        return {"workflows": ["effort-gen"], "models": ["UM10"],
                "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": 72.6,
                              "trials": [{"name": "normal", "ik": str(example.ik["normal"]),
                                          "id": str(example.id["normal"]), **trial}]}]}

    with pytest.raises(OptionError) as info:
        study_from_dict(data(fiber_velocity="equilibrium", muscle_parameters="package"), base="/")
    for words in ("trial 'normal'", "'fiber_velocity' and 'muscle_parameters' go with 'states'", "drop them"):
        assert words in str(info.value), str(info.value)
    states = {"states": str(example.ik["normal"])}
    for key, value, allowed in (("fiber_velocity", "centred", "'auto', 'trajectory', 'derivative', 'equilibrium'"),
                                ("muscle_parameters", "model", "'probes', 'package'")):
        with pytest.raises(OptionError) as info:
            study_from_dict(data(**states, **{key: value}), base="/")
        assert f"trial 'normal': {key} must be one of {allowed}, not '{value}'" in str(info.value), str(info.value)

    def key(**trial):
        study = study_from_dict(data(**states, **trial), base="/", output="/tmp/out")
        (unit,) = plan_units(study)[1]
        return unit_key(study, unit)

    plain = key()
    assert key(fiber_velocity="equilibrium") != plain != key(muscle_parameters="package")
    assert key(fiber_velocity=None) == plain


@pytest.mark.opensim
def test_the_sensitivities_rebuild_an_assisted_problem_with_its_device(exo_study):
    """The problem the sensitivities rebuild from an assisted solution's folder is the solved one:
    the solution's muscle moments (moment arms x tendon forces) plus its reserves give the rebuilt
    problem's moments at every node, the device's torque taken off (it misses them by the device's
    torque, 22 N m, when rebuilt from the ID alone)."""
    from musclemetab.redundancy.sensitivity import problem_of_solution

    prob = problem_of_solution(exo_study.output / "units" / "sub1" / "normal_assist-1.5" / "effort-gen")
    sol, inputs = prob.solution, prob.inputs
    supplied = np.einsum("ndm,nm->nd", inputs.moment_arms_m, sol.tendon_force_N) + sol.reserve_Nm
    assert np.max(np.abs(supplied - inputs.moments_Nm)[:-1]) < 1e-3  # the last node repeats the one before


@pytest.mark.opensim
def test_the_assistance_figure_has_no_layout_problems(exo_study):
    """The figure as the report saves it: no text cut by the edge, no two texts touching (the
    rotated tick labels of the leg, phases and groups panel did: 'stance (phase)' over its
    neighbours, a FigureLayoutWarning on every report)."""
    import matplotlib.pyplot as plt

    from musclemetab.report.assistance_figure import assistance_figure
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.layout_check import figure_problems

    folder = read_study_folder(exo_study.output)
    fig = assistance_figure(folder.ok, exo_study.output)
    labels = [t.get_text() for t in fig.axes[2].get_yticklabels()]
    assert "stance (phase)" in labels and "swing (phase)" in labels, labels
    assert figure_problems(fig) == []
    plt.close(fig)


@pytest.mark.opensim
def test_the_command_maps_a_cycle_profile_onto_the_cycle_the_study_takes(exo_study, example, tmp_path, capsys):
    """The study's profile solved by ``musclemetab solve`` without --cycle or --assistance-cycle: it
    is mapped onto the cycle the study takes for the ID-file trial (0.62-1.70 s, the window less
    0.05 s at each end; it took the padded window 0.57-1.75 s, 2.50 / -1.44 J), the output line
    says so, and the device's work and mean power are the study's gain-1 row's: the documented
    2.21 J positive / -1.33 J negative, 2.21 J / 1.08 s of mean positive power."""
    import json

    import pandas as pd

    from musclemetab.commands import main

    profile = exo_study.subjects[0].trials[1].assistance
    assert main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                 str(example.id["normal"]), "--assistance", str(profile), "--no-progress",
                 "--out", str(tmp_path / "cli")]) == 0
    line = capsys.readouterr().out
    assert "device (gain 1) 2.21 J positive / -1.33 J negative work per cycle (profile mapped onto and work over " \
           "the gait cycle 0.620-1.700 s: estimated from the IK window and the ankle moment (no ground reaction " \
           "forces))" in line, line  # the cycle and the words of analyse and a study (events.cycle_of_trial)
    device = json.loads((tmp_path / "cli" / "summary.json").read_text())["assistance"]
    assert device["cycle_s"] == pytest.approx([0.62, 1.70]) and device["duration_s"] == pytest.approx(1.08)
    results = pd.read_csv(exo_study.output / "results.csv")
    row = results[results["trial"] == "normal_assist-1"].iloc[0]
    assert device["positive_work_J"] == pytest.approx(row["device_positive_work_J"], rel=1e-9)
    assert device["negative_work_J"] == pytest.approx(row["device_negative_work_J"], rel=1e-9)
    assert (device["positive_work_J"], device["negative_work_J"]) == (pytest.approx(2.21, abs=0.005),
                                                                        pytest.approx(-1.33, abs=0.005))
    assert device["mean_positive_power_W"] == pytest.approx(device["positive_work_J"] / 1.08)
    mass = example.body_mass_kg  # results.csv: both legs per kg
    assert row["device_positive_power_W_per_kg"] == pytest.approx(2 * device["mean_positive_power_W"] / mass, rel=1e-9)

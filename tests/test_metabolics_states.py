"""``musclemetab metabolics --states``: the energy of an OpenSim motion, against OpenSim's own probes.

Two states files of two muscle models, each with OpenSim's ``Umberger2010MuscleMetabolicsProbe``
(UM10 settings) and ``Bhargava2004MuscleMetabolicsProbe`` (BH04 settings) added to the model by
tests/opensim_states.py (per-muscle slow-twitch ratios, OpenSim's specific tension 0.25 MPa,
one provided mass):

* gait2392 (Thelen2003Muscle, 92 muscles, both legs): states made in OpenSim from the IK motion
  (0.6-0.7 s, 6 states), activations set by formula, fiber lengths from OpenSim's equilibrium;
  no controls file (excitation = activation);
* gait2392 lumped to 9 muscles per leg (tests/opensim_models.py): DeGrooteFregly2016 on the
  right (compliant tendon, normalised tendon force states), Millard2012 with a rigid tendon on
  the left (fiber length and velocity from the geometry); states made likewise;
* the example subject's exported solution (the session's ``demo`` fixture, preferred speed,
  EFFORT-GEN): ``model.osim`` (DeGrooteFregly2016Muscle, normalised tendon force states),
  ``states.sto`` and ``controls.sto``.

Oracles: the activations set, the probes' per-muscle outputs (the package's UM10 with the
slow-twitch cap and BH04 without the activation-heat decay, docs/metabolics.md section 6, fed the
probes' masses and ratios, agree to 1e-6 relative wherever OpenSim's fiber velocity stays on its
force-velocity curve), the probe's mass rule worked here (``F0 / 0.25 MPa x 1059.7 kg/m^3 x lMo``).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.opensim

SCRIPT = Path(__file__).with_name("opensim_states.py")
sys.path.insert(0, str(SCRIPT.parent))
import opensim_states as script  # noqa: E402

OPTIONS = {"UM10": {"slow_twitch_shortening_cap": True}, "BH04": {"activation_heat_decay": False}}


_STEPS = """
import sys
sys.path.insert(0, {tests!r})
import opensim
opensim.Logger.setLevelString("error")
import opensim_models, opensim_states
for module, function, args, kwargs in {steps!r}:
    getattr(sys.modules[module], function)(*args, **kwargs)
"""


def _run(*steps):
    """Each step ``(function of tests/opensim_states.py or opensim_models.py, *arguments)`` in
    turn, in one process of its own (OpenSim only, as those scripts run)."""
    funcs = {"probes": ("opensim_states", "add_probes"), "thelen": ("opensim_states", "thelen_states"),
             "lumped": ("opensim_models", "lumped_sagittal")}
    plan = []
    for name, *args in steps:
        kwargs = {"rigid_left": True} if "--rigid-left" in args else {}
        args = [a if isinstance(a, (int, float)) else str(a) for a in args if a != "--rigid-left"]
        plan.append((*funcs[name], tuple(args), kwargs))
    code = _STEPS.format(tests=str(SCRIPT.parent), steps=plan)
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


@pytest.fixture(scope="module")
def thelen(gait2392, tmp_path_factory):
    folder = tmp_path_factory.mktemp("thelen")
    model, states = folder / "probes.osim", folder / "states.sto"
    _run(("probes", gait2392.model, model), ("thelen", model, gait2392.ik, states, 0.6, 0.7, 6))
    return model, states


@pytest.fixture(scope="module")
def dgf(demo, tmp_path_factory):
    out, table = demo
    folder = out / table[(table.trial == "normal") & (table.workflow == "effort-gen")].unit_dir.iloc[0]
    model = tmp_path_factory.mktemp("dgf") / "probes.osim"
    _run(("probes", folder / "model.osim", model))
    return model, folder / "states.sto", folder / "controls.sto", folder


def _evaluate(read, body_mass_kg=72.6):
    from musclemetab.metabolics.opensim_states import probe_muscle_properties, split_sides
    from musclemetab.metabolics.solution import metabolics_from_legs

    masses, fst, _ = probe_muscle_properties(read)
    res = metabolics_from_legs(split_sides(read.states), body_mass_kg, None, models="UM10,BH04", trim=(0, 0),
                               muscle_masses_kg=masses, slow_twitch_fractions=fst, model_options=OPTIONS)
    ours = {}
    for r in res.values():
        for model in r.models:
            rate = r.rates[model].total_without_basal()
            ours.setdefault(model, {}).update({m: rate[i] for i, m in enumerate(r.muscles)})
    return res, ours, masses, fst


def _agree_with_probes(read, ours, keep):
    probes = {p["name"]: p for p in read.probes}
    for model in ("UM10", "BH04"):
        theirs = np.array([probes[model]["rates"][m] for m in read.states.muscles])
        mine = np.array([ours[model][m] for m in read.states.muscles])
        np.testing.assert_allclose(mine[keep], theirs[keep], rtol=1e-6, atol=1e-9)
        assert theirs[keep].max() > 20.0  # not zeros


def _probe_masses_worked_here(read, masses, fst):
    # the evaluated muscles come first in the model (the one leg of a solution's model, then the other)
    muscles = read.states.muscles
    n_model = len(muscles) + len(read.skipped_muscles)
    for k, m in enumerate(muscles):
        p = read.states.parameters[m]
        want = script.PROVIDED_MASS_KG if k == 0 else (
            p["max_isometric_force_N"] / 0.25e6 * 1059.7 * p["optimal_fiber_length_m"])
        assert masses[m] == pytest.approx(want, rel=1e-12)
        assert fst[m] == pytest.approx(script.slow_twitch(k, n_model), rel=1e-12)


@pytest.mark.filterwarnings("error::musclemetab.errors.MuscleTableWarning")  # the probes place every muscle
def test_thelen_states_agree_with_opensims_probes(thelen):
    from musclemetab.metabolics.opensim_states import read_opensim_states

    model, states = thelen
    read = read_opensim_states(model, states)
    s = read.states
    assert len(s.muscles) == 92 and set(read.muscle_classes) == {"Thelen2003Muscle"}
    np.testing.assert_allclose(s.time_s, np.linspace(0.6, 0.7, 6), atol=1e-12)
    want = np.array([script.activation(k, s.time_s) for k in range(len(s.muscles))])
    np.testing.assert_allclose(s.states["activation"], want, rtol=1e-9)  # the activations set
    assert read.excitation_source == "activation"
    np.testing.assert_array_equal(s.states["excitation"], s.states["activation"])
    lmo = np.array([s.parameters[m]["optimal_fiber_length_m"] for m in s.muscles])[:, None]
    vmax = np.array([s.parameters[m]["max_contraction_velocity"] for m in s.muscles])[:, None]
    np.testing.assert_allclose(s.states["normalized_fiber_velocity"], read.fiber_velocity_m_per_s / (lmo * vmax),
                               rtol=1e-9, atol=1e-12)
    assert np.abs(s.states["normalized_fiber_velocity"]).max() > 0.05  # the motion moves the fibers
    assert not read.clamped.any()
    res, ours, masses, fst = _evaluate(read)
    assert set(res) == {"r", "l"}  # both legs' muscles, added
    _probe_masses_worked_here(read, masses, fst)
    _agree_with_probes(read, ours, np.ones(read.clamped.shape, dtype=bool))


def test_degroote_and_rigid_millard_states_agree_with_opensims_probes(gait2392, tmp_path):
    from musclemetab.metabolics.opensim_states import read_opensim_states

    lumped, model, states = tmp_path / "lumped.osim", tmp_path / "probes.osim", tmp_path / "states.sto"
    _run(("lumped", gait2392.model, lumped), ("probes", lumped, model, "--rigid-left"),
         ("thelen", model, gait2392.ik, states, 0.6, 0.7, 6))
    header = next(line for line in states.read_text().splitlines() if line.startswith("time"))
    assert header.count("/normalized_tendon_force") == 9 and "/fiber_length" not in header
    read = read_opensim_states(model, states, fiber_velocity="equilibrium")  # the probes' velocity
    assert read.muscle_classes == ("DeGrooteFregly2016Muscle",) * 9 + ("Millard2012EquilibriumMuscle",) * 9
    assert read.velocity_sources == ("equilibrium",) * 9 + ("geometry",) * 9
    s = read.states
    want = np.array([script.activation(k, s.time_s) for k in range(len(s.muscles))])
    np.testing.assert_allclose(s.states["activation"], want, rtol=1e-9)
    assert np.abs(s.states["normalized_fiber_velocity"][9:]).max() > 0.1  # the rigid tendons' fibers move
    assert not read.clamped.any()
    _, ours, masses, fst = _evaluate(read)
    _probe_masses_worked_here(read, masses, fst)
    _agree_with_probes(read, ours, np.ones(read.clamped.shape, dtype=bool))


def test_exported_degroote_states_agree_with_opensims_probes(dgf):
    from musclemetab.metabolics.opensim_states import read_opensim_states
    from musclemetab.redundancy import Solution

    model, states, controls, folder = dgf
    sol = Solution.load(folder)
    read = read_opensim_states(model, states, controls, fiber_velocity="equilibrium")  # the probes' velocity
    assert read.states.muscles == tuple(sol.muscles) and len(read.skipped_muscles) == 40  # the left leg
    assert read.skipped_reason == "no controls"
    assert set(read.muscle_classes) == {"DeGrooteFregly2016Muscle"}
    # the exported files hold the nodes where the Hill equilibrium holds: every node but the last
    n = read.states.states["activation"].shape[1]
    assert n == len(sol.time_s) - 1
    np.testing.assert_allclose(read.states.states["activation"], sol.activation[:n].T, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(read.states.states["excitation"], sol.excitation[:n].T, rtol=1e-9, atol=1e-12)
    # off the force-velocity curve (set to the bound) where a muscle is all but inactive: at the optimum the
    # muscles that are off have no active force to balance the tendon's; few states of the muscles in use
    act = read.states.states["activation"]
    assert read.clamped[act > 1e-3].mean() < 0.1 and np.quantile(act[read.clamped], 0.9) < 0.01
    res, ours, masses, fst = _evaluate(read)
    assert set(res) == {"r"}
    _probe_masses_worked_here(read, masses, fst)
    keep = ~read.clamped
    _agree_with_probes(read, ours, keep)


def _leg_mean_W(states, model):
    """The leg's muscles' rate (W, basal heat apart) averaged over the states, with the package's
    own masses and ratios (the exported model carries no probe): the solution's and the route's
    states are weighed alike."""
    from musclemetab.metabolics.opensim_states import split_sides
    from musclemetab.metabolics.solution import metabolics_from_legs

    legs = split_sides(states) if not states.side else {states.side: states}
    res = metabolics_from_legs(legs, 72.6, 1.743, models=model, trim=(0, 0))
    return float(next(iter(res.values())).rates[model].total_without_basal().sum(0).mean())


def test_the_packages_own_solution_round_trips_through_its_opensim_states(dgf):
    """The package's solution -> its OpenSim files (model.osim, states.sto, controls.sto) -> the states
    route gives the solution's rates. The states file holds no fiber velocity and the exported
    DeGrooteFregly2016 muscles carry OpenSim's curves, not the solution's, so OpenSim's force
    equilibrium puts about half the muscle-states off the force-velocity curve (BH04 +38 %); the route
    differentiates OpenSim's fiber lengths in time instead. The solution's velocity at node k is the
    forward-Euler slope from k to k+1 (its transcription), the route's the centred derivative at k: the
    rates of the solution's own states with the centred derivative of its own fiber lengths
    (independent of OpenSim) differ from its rates by 0.2 % (UM10) and 0.8 % (BH04); OpenSim's fiber
    lengths (its tendon curve) add 0.3 % and 0.6 %. Tolerances: 1.5 % against the centred reference,
    3 % against the solution (about twice the measured)."""
    from scipy.interpolate import CubicSpline

    from musclemetab.metabolics.opensim_states import read_opensim_states
    from musclemetab.metabolics.solution import SolutionStates, read_solution_states
    from musclemetab.muscle.curves import force_velocity

    _, states, controls, folder = dgf
    sol = read_solution_states(folder)
    read = read_opensim_states(folder / "model.osim", states, controls)
    assert set(read.velocity_sources) == {"derivative"} and not read.clamped.any()
    n = read.states.time_s.size  # every node but the last (the files hold the equilibrium nodes)
    np.testing.assert_allclose(read.states.time_s, sol.time_s[:n], atol=1e-9)
    own = {k: v[:, :n] for k, v in sol.states.items()}
    vmax = np.array([sol.parameters[m]["max_contraction_velocity"] for m in sol.muscles])[:, None]
    # the forward-Euler velocity is the slope of the solution's fiber lengths (to the solver's tolerance)
    slope = np.diff(sol.states["normalized_fiber_length"], axis=1) / np.diff(sol.time_s) / vmax
    np.testing.assert_allclose(slope, sol.states["normalized_fiber_velocity"][:, :-1], atol=1e-6)
    centred_v = CubicSpline(sol.time_s[:n], own["normalized_fiber_length"], axis=1)(sol.time_s[:n], 1) / vmax
    v = read.states.states["normalized_fiber_velocity"]
    assert np.median(np.abs(v - centred_v)) < 2e-3 and np.abs(v - centred_v).max() < 0.15
    centred = {**own, "normalized_fiber_velocity": centred_v, "force_velocity_multiplier": force_velocity(centred_v)}

    def of(values):
        return SolutionStates(time_s=sol.time_s[:n], muscles=sol.muscles, states=values, parameters=sol.parameters,
                              source=str(folder), side="r")

    for model in ("UM10", "BH04"):
        route, solution, reference = (_leg_mean_W(x, model) for x in (read.states, of(own), of(centred)))
        assert route == pytest.approx(reference, rel=0.015)
        assert route == pytest.approx(solution, rel=0.03)
    # OpenSim's force equilibrium, the other way: far off for these states
    eq = read_opensim_states(folder / "model.osim", states, controls, fiber_velocity="equilibrium")
    assert eq.clamped.mean() > 0.2
    assert _leg_mean_W(eq.states, "BH04") > 1.2 * _leg_mean_W(of(own), "BH04")


def test_states_without_controls_leave_out_the_muscles_at_the_models_defaults(dgf):
    """A one-leg solution's states file holds the other leg's muscles at the model's default states:
    read without its controls file, those muscles are not evaluated (not taken for a leg at rest)."""
    from musclemetab.metabolics.opensim_states import read_opensim_states
    from musclemetab.redundancy import Solution

    _, states, controls, folder = dgf
    read = read_opensim_states(folder / "model.osim", states)
    assert read.states.muscles == tuple(Solution.load(folder).muscles)
    assert len(read.skipped_muscles) == 40 and all(m.endswith("_l") for m in read.skipped_muscles)
    assert read.skipped_reason == "default states" and read.excitation_source == "activation"
    with_controls = read_opensim_states(folder / "model.osim", states, controls)
    np.testing.assert_array_equal(read.states.states["normalized_fiber_velocity"],
                                  with_controls.states.states["normalized_fiber_velocity"])


def test_command_records_the_probes_parameters(thelen, tmp_path, capsys):
    import pandas as pd

    from musclemetab.commands import main
    from musclemetab.metabolics.solution import read_metabolics_settings

    model, states = thelen
    argv = ["metabolics", "--states", str(states), "--model", str(model), "--mass", "72.6", "--models", "UM10,BH04"]
    assert main([*argv, "--out", str(tmp_path / "probes")]) == 0
    err = capsys.readouterr().err
    assert "from the model's metabolic probes" in err and "0.25 MPa" in err
    rec = read_metabolics_settings(tmp_path / "probes" / "r")["muscle_parameters"]  # each leg's folder
    assert "Umberger2010MuscleMetabolicsProbe 'UM10' (92 muscles, specific tension 0.25 MPa)" in rec
    assert main([*argv, "--muscle-parameters", "package", "--out", str(tmp_path / "package")]) == 0
    assert "metabolic probes" not in capsys.readouterr().err
    assert "muscle_parameters" not in read_metabolics_settings(tmp_path / "package" / "l")
    a = pd.read_csv(tmp_path / "probes" / "whole_body.csv").set_index("model")
    b = pd.read_csv(tmp_path / "package" / "whole_body.csv").set_index("model")
    assert set(a["legs"]) == {"r+l"}
    # 0.25 MPa against the tables' 0.6 MPa: heavier muscles, more heat
    assert (a["whole_body_no_basal_W_per_kg"] > 1.2 * b["whole_body_no_basal_W_per_kg"]).all()
    # a --muscle-properties row wins over the probes (the per-muscle basal heat is 1.2 W per kg of mass)
    (tmp_path / "m.csv").write_text("muscle,mass_kg\nsoleus,1.5\n")
    assert main([*argv, "--muscle-properties", str(tmp_path / "m.csv"), "--out", str(tmp_path / "csv")]) == 0
    pm = pd.read_csv(tmp_path / "csv" / "r" / "per_muscle.csv").set_index(["model", "muscle"])
    pa = pd.read_csv(tmp_path / "probes" / "r" / "per_muscle.csv").set_index(["model", "muscle"])
    assert pm.loc[("UM10", "soleus_r"), "basal_heat_mean_W"] == pytest.approx(1.2 * 1.5, rel=1e-9)
    assert pm.loc[("UM10", "glut_med1_r"), "basal_heat_mean_W"] == pytest.approx(1.2 * script.PROVIDED_MASS_KG, rel=1e-9)
    assert pa.loc[("UM10", "soleus_r"), "basal_heat_mean_W"] != pytest.approx(1.8, rel=1e-3)


def test_command_refuses_states_without_a_model(thelen, tmp_path, capsys):
    from musclemetab.commands import main

    _, states = thelen
    code = main(["metabolics", "--states", str(states), "--mass", "72.6", "--out", str(tmp_path / "o")])
    assert code != 0 and "--states needs --model" in capsys.readouterr().err
    code = main(["metabolics", "--solution", str(tmp_path), "--controls", str(states), "--mass", "72.6",
                 "--out", str(tmp_path / "o")])
    assert code != 0 and "--controls goes with --states" in capsys.readouterr().err
    code = main(["metabolics", "--solution", str(tmp_path), "--cycle", "0.6,0.65,0.7", "--mass", "72.6",
                 "--out", str(tmp_path / "o")])
    assert code != 0 and "--cycle goes with --states" in capsys.readouterr().err
    model = str(thelen[0])
    for cycle, says in (("0.6,0.7", "--cycle must be three times"), ("0.6,0.75,0.7", "--cycle 0.6,0.75,0.7: toe-off"),
                        ("0.5,0.65,0.7", "states.sto: the states spans 0.6-0.7 s but the gait cycle spans 0.5-0.7 s")):
        code = main(["metabolics", "--states", str(states), "--model", model, "--cycle", cycle, "--mass", "72.6",
                     "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code != 0 and says in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()


def test_command_refuses_states_of_another_model(thelen, dgf, tmp_path, capsys):
    from musclemetab.commands import main

    _, states = thelen
    code = main(["metabolics", "--states", str(states), "--model", str(dgf[0]), "--mass", "72.6",
                 "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code != 0 and "OpenSim cannot load these states" in err and "missing from the data" in err
    assert "/jointset/walker_knee_r/knee_angle_r/value" in err and not (tmp_path / "o").exists()


@pytest.mark.opensim
def test_a_study_trial_of_states_takes_the_muscle_parameters_option(dgf, example, tmp_path):
    """A states trial's ``muscle_parameters = "package"`` gives the rates of ``musclemetab metabolics
    --states --muscle-parameters package`` for the same files and cycle, and the default those of the
    model's metabolic probes (their masses differ: the rates do)."""
    import json

    import pandas as pd

    from musclemetab.commands import main
    from musclemetab.study import study_from_dict
    from musclemetab.study.runner import run_study

    model, states, controls, _ = dgf
    files = {"ik": str(example.ik["normal"]), "id": str(example.id["normal"]), "states": str(states),
             "controls": str(controls)}
    trials = [{"name": "package", **files, "muscle_parameters": "package"}, {"name": "probes", **files}]
    study = study_from_dict({"name": "states", "workflows": ["effort-gen"], "models": ["UM10", "BH04"],
                             "subjects": [{"name": "sub1", "model": str(model), "body_mass_kg": example.body_mass_kg,
                                           "height_m": example.height_m, "trials": trials}]},
                            base="/", output=tmp_path / "study")
    run = run_study(study, workers=1, progress=False)
    assert not run.failed and len(run.ran) == 2, (run.failed, run.ran)
    rates = {}
    for name, option in (("package", ["--muscle-parameters", "package"]), ("probes", [])):
        folder = tmp_path / "study" / "units" / "sub1" / name / "states"
        c = json.loads((folder / "unit.json").read_text())["cycle"]
        out = tmp_path / f"cli-{name}"
        assert main(["metabolics", "--states", str(states), "--controls", str(controls), "--model", str(model),
                     "--mass", str(example.body_mass_kg), "--height", str(example.height_m), "--models", "UM10,BH04",
                     *option, "--cycle", f"{c['start_s']!r},{c['toe_off_s']!r},{c['end_s']!r}", "--out", str(out)]) == 0
        cli = pd.read_csv(out / "whole_body.csv").set_index("model")
        mine = pd.read_csv(folder / "whole_body.csv").set_index("model")
        pd.testing.assert_frame_equal(mine[cli.columns], cli)
        rates[name] = mine["whole_body_W_per_kg"]
    assert (rates["package"] - rates["probes"]).abs().max() > 1e-3


def test_a_trajectorys_tendon_force_derivatives_give_its_fiber_velocity(dgf, tmp_path):
    """A states file that holds each muscle's tendon-force derivative (the columns
    ``<muscle path>/implicitderiv_normalized_tendon_force`` of a Moco solution file) gives the
    fiber velocity OpenSim computes from it in implicit tendon dynamics, as Moco solved the
    trajectory (against Moco's own on a MocoInverse of the example: 3e-5 vmax at most,
    benchmarks/moco_states.py and docs/metabolics.md 4.1).
    Here the package's exported solution with the time derivative of its normalized tendon forces
    (a cubic spline through the states): the velocities are those the derivative of the fiber
    lengths gives (two differentiations of one smooth trajectory, through OpenSim's tendon curve);
    with zero derivatives (the tendon force held) they are far from them, so the column is what
    sets them. ``"trajectory"`` without the columns names them; ``"derivative"`` ignores them."""
    from scipy.interpolate import CubicSpline

    from musclemetab.errors import DataMismatchError
    from musclemetab.io import read_table, write_storage
    from musclemetab.metabolics.opensim_states import read_opensim_states

    _, states, controls, folder = dgf
    table = read_table(states).to_dataframe()
    t = np.asarray(table.index, dtype=float)
    forces = [c for c in table.columns if c.endswith("/normalized_tendon_force")]
    assert len(forces) == 80  # both legs of the model; the controls drive the right leg's 40

    def with_derivatives(name, values):
        frame = table.copy()
        for c in forces:
            frame[c.replace("/normalized_tendon_force", "/implicitderiv_normalized_tendon_force")] = values(c)
        write_storage(tmp_path / name, frame, in_degrees=False)
        return read_opensim_states(folder / "model.osim", tmp_path / name, controls)

    spline = with_derivatives("spline.sto", lambda c: CubicSpline(t, table[c].to_numpy(float))(t, 1))
    held = with_derivatives("held.sto", lambda c: np.zeros_like(t))
    lengths = read_opensim_states(folder / "model.osim", states, controls)
    assert set(spline.velocity_sources) == {"trajectory"} and set(lengths.velocity_sources) == {"derivative"}
    ref = lengths.states.states["normalized_fiber_velocity"]
    inner = slice(2, -2)  # the splines' ends
    e_spline, e_held = (np.abs(r.states.states["normalized_fiber_velocity"] - ref)[:, inner] for r in (spline, held))
    # measured: median 5e-7 and 95th percentile 2.4e-4 vmax; held: 2.5e-3 and 0.048
    assert np.median(e_spline) < 1e-5 and np.percentile(e_spline, 95) < 1e-3
    assert np.percentile(e_held, 95) > 0.02
    ignored = read_opensim_states(folder / "model.osim", tmp_path / "spline.sto", controls, fiber_velocity="derivative")
    np.testing.assert_allclose(ignored.states.states["normalized_fiber_velocity"], ref, atol=1e-12)
    with pytest.raises(DataMismatchError, match="no column implicitderiv_normalized_tendon_force for addbrev_r"):
        read_opensim_states(folder / "model.osim", states, controls, fiber_velocity="trajectory")

"""The OpenSim files of a solution folder reproduce the solution in OpenSim.

Each solve here is one another test module solves with the same options (the session's solve
memo gives it for free); the command line then writes ``model.osim``, ``states.sto``,
``controls.sto`` and ``forces.sto`` beside the solution. Oracles: OpenSim itself (its
``DeGrooteFregly2016Muscle`` evaluated over the states, its ``JointReaction`` analysis), the
solution's own ``solution.sto``, the curve equations of docs/opensim_files.md worked here, and
the knee forces measured in instrumented knee implants (Kutzner et al. 2010, J Biomech
43:2164-2173: level walking, peak resultant force 2.61 body weights on average over five
subjects).

Tolerances (docs/opensim_files.md gives the measured values):

* the files hold the nodes where the solution's Hill equilibrium holds, every node but the last
  (``N``, reached by the forward Euler step without an equilibrium: its tendon force can be
  compressive);
* the tendon force OpenSim computes from ``states.sto`` is the solution's to 1e-9 F0 (the
  state is the normalised tendon force), except a slack tendon below OpenSim's curve (written at
  OpenSim's force for the solution's tendon length: within 0.05 F0);
* OpenSim's tendon force at the solution's fiber length (OpenSim's geometry and tendon curve)
  within 0.07 F0 at every node, 0.012 F0 rms: the tendon curves meet at one normalised force
  only (up to 0.04 F0 apart at the same length) and OpenSim's muscle-tendon lengths at the
  filtered coordinates are within 0.7 mm of the solve's filtered lengths;
* the fiber length OpenSim derives within 0.03 lMo (EFFORT-GEN) and 0.06 lMo (EFFORT-TEN, kT
  10.6 and 4.7: compliant tendons, where the curves differ most near slack).
"""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.opensim

KT_TS, KT_VA = 10.617977, 4.695786  # as tests/test_redundancy.py


def _solve(tmp_path, argv):
    from musclemetab.commands import main
    from musclemetab.redundancy import Solution

    out = tmp_path / "solution"
    assert main([*argv, "--out", str(out)]) == 0
    return Solution.load(out), out


@pytest.fixture(scope="module")
def solved(example, geometry_cache, tmp_path_factory, passive_csv):
    """``solved(workflow)``: the normal trial's EFFORT-GEN or EFFORT-TEN solve, as
    tests/test_redundancy.py asks for it, and its folder."""
    cache = {}

    def run(workflow):
        if workflow not in cache:
            argv = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                    str(example.id["normal"]), "--workflow", workflow, "--cache-dir", str(geometry_cache)]
            if workflow == "effort-ten":
                argv += ["--tendon-stiffness", f"soleus_r={KT_TS},gasmed={KT_TS},gaslat_r={KT_TS},"
                         f"vasint_r={KT_VA},vaslat_r={KT_VA},vasmed_r={KT_VA}", "--passive", str(passive_csv)]
            cache[workflow] = _solve(tmp_path_factory.mktemp(workflow), argv)
        return cache[workflow]

    return run


def test_strains_at_one_normalised_force_worked_by_hand():
    from musclemetab.muscle import passive_force_length, tendon_force_length
    from musclemetab.redundancy.export import passive_fiber_strain_at_one_norm_force, tendon_strain_at_one_norm_force

    # kT 35: exp(35 (l - 0.995)) / 5 - 0.25 = 1 -> l = 0.995 + ln(6.25)/35
    assert tendon_strain_at_one_norm_force(35.0) == pytest.approx(0.995 + np.log(6.25) / 35 - 1, rel=1e-12)
    # generic passive: exp(4 (l - 1)/0.6) = exp(4) - 1 + exp(-16/3)
    assert passive_fiber_strain_at_one_norm_force(4.0, 1.0, 0.6) == pytest.approx(
        0.15 * np.log(np.exp(4) - 1 + np.exp(-16 / 3)), rel=1e-12)
    for kt in (4.7, 10.6, 35.0, 60.0):  # the package's curves reach one normalised force there
        assert tendon_force_length(1 + tendon_strain_at_one_norm_force(kt), kt) == pytest.approx(1.0, rel=1e-12)
    for kpe, s0 in ((3.0, 0.8), (4.0, 1.0), (5.0, 1.2)):
        e = passive_fiber_strain_at_one_norm_force(kpe, s0, 0.6)
        assert passive_force_length(1 + e, kpe, s0, 0.6) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("workflow", ["effort-gen", "effort-ten"])
def test_opensim_reproduces_the_solution(solved, workflow):
    from musclemetab.opensim_bridge import call
    from musclemetab.redundancy.export import tendon_strain_at_one_norm_force

    sol, folder = solved(workflow)
    p = sol.parameters
    f0 = p.max_isometric_force_N[:, None]
    got = call("solution_model:muscles_over_states", str(folder / "model.osim"), str(folder / "states.sto"),
               list(sol.muscles), sol.fiber_length_m[:-1].T)
    # loaded with no assembly, no missing or extra column: every state finite, the node times but the last
    assert got["n_nan_states"] == 0
    np.testing.assert_allclose(got["time_s"], sol.time_s[:-1], atol=1e-12)
    np.testing.assert_allclose(got["activation"], sol.activation[:-1].T, rtol=1e-9, atol=1e-12)
    ft = sol.tendon_force_N[:-1].T
    err = np.abs(got["tendon_force_N"] - ft) / f0
    slack = ft / f0 < -0.19
    assert err[~slack].max() < 1e-9
    assert slack.sum() == 0  # the slack tendons were those of the last node, which the files leave out
    if slack.any():  # OpenSim's curve at the solution's tendon length there
        assert err[slack].max() < 0.05
    # OpenSim's geometry and tendon curve at the solution's fiber lengths
    at_fiber = np.abs(got["tendon_force_at_fiber_length_N"] - ft) / f0
    assert at_fiber.max() < 0.07 and np.sqrt(np.mean(at_fiber**2)) < 0.012
    # the fiber length OpenSim derives from the tendon force
    lm_err = np.abs(got["fiber_length_m"] - sol.fiber_length_m[:-1].T) / p.optimal_fiber_length_m[:, None]
    assert lm_err.max() < (0.03 if workflow == "effort-gen" else 0.06)
    # the model carries the solution's parameters: F0 and the tendon strain of the soleus
    i = sol.muscles.index("soleus_r")
    text = (folder / "model.osim").read_text()
    block = text[text.index('<DeGrooteFregly2016Muscle name="soleus_r">'):]
    block = block[: block.index("</DeGrooteFregly2016Muscle>")]
    strain = float(block.split("<tendon_strain_at_one_norm_force>")[1].split("<")[0])
    assert strain == pytest.approx(float(tendon_strain_at_one_norm_force(p.tendon_stiffness[i])), rel=1e-12)
    assert float(block.split("<max_isometric_force>")[1].split("<")[0]) == pytest.approx(p.max_isometric_force_N[i])
    assert "<fiber_damping>0</fiber_damping>" in block
    assert f"kT {p.tendon_stiffness[i]:.6g}" in text  # the comment on the mapping
    if workflow == "effort-ten":  # the personalised tendon: the soleus' peak force, not the generic model's
        assert p.tendon_stiffness[i] == pytest.approx(KT_TS)
        assert got["tendon_force_N"][i].max() == pytest.approx(ft[i].max(), rel=1e-9)


def test_forces_file_holds_every_actuator(solved, example):
    from musclemetab.io import read_storage

    sol, folder = solved("effort-gen")
    forces = read_storage(folder / "forces.sto")
    controls = read_storage(folder / "controls.sto")
    np.testing.assert_allclose(forces.index, sol.time_s[:-1], atol=1e-12)
    for i, m in enumerate(sol.muscles):
        np.testing.assert_allclose(forces[m], sol.tendon_force_N[:-1, i], rtol=1e-10)
        np.testing.assert_allclose(controls[f"/forceset/{m}"], sol.excitation[:-1, i], rtol=1e-10, atol=1e-12)
    for j, d in enumerate(sol.dofs):
        np.testing.assert_allclose(forces[f"reserve_{d}"], sol.reserve_Nm[:-1, j], rtol=1e-10, atol=1e-9)
    # muscles outside the solution carry nothing; the left hip its inverse-dynamics moment (no right-leg
    # muscle spans it), low-pass filtered as the solve filters the moments (6 Hz, 6th order Butterworth,
    # zero phase; worked here with SciPy's own padding, so within 0.5 N m, 0.15 N m away from the ends)
    import scipy.signal

    others = [c for c in forces.columns if c.endswith("_l") and not c.startswith("reserve_")]
    assert others and np.all(forces[others].to_numpy() == 0)
    raw = read_storage(example.id["normal"])
    t = raw.index.to_numpy()
    b, a = scipy.signal.butter(6, 6.0 / (0.5 / np.mean(np.diff(t))))
    for dof, peak in (("hip_flexion_l", 100.0), ("knee_angle_l", 80.0)):
        want = np.interp(sol.time_s[:-1], t, scipy.signal.filtfilt(b, a, raw[f"{dof}_moment"].to_numpy()))
        gap = np.abs(forces[f"reserve_{dof}"].to_numpy() - want)
        assert gap.max() < 0.5 and gap[10:-10].max() < 0.15 and np.ptp(want) > peak, dof
    # locked coordinates have no reserve (they are prescribed in the model)
    assert "reserve_subtalar_angle_r" not in forces.columns and "reserve_mtp_angle_r" not in forces.columns


def test_a_short_window_solve_hands_opensim_no_pushing_tendon(example, tmp_path):
    """A short window (0.6-0.85 s, as tests/test_cli_flow.py solves it): the solution's last node,
    which the forward Euler step reaches without a Hill equilibrium, carries compressive tendon
    forces (the package's tendon curve below slack); ``forces.sto`` and the normalised tendon
    forces of ``states.sto`` hold the nodes where the equilibrium holds, every force of a muscle
    positive, and their headers say which nodes and why."""
    from musclemetab.io import read_storage

    sol, folder = _solve(tmp_path, ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]),
                                    "--id", str(example.id["normal"]), "--window", "0.6:0.85", "--no-progress"])
    f0 = sol.parameters.max_isometric_force_N
    assert (sol.tendon_force_N[-1] / f0).min() < -0.05 and (sol.tendon_force_N[:-1] / f0).min() > 0
    forces = read_storage(folder / "forces.sto")
    np.testing.assert_allclose(forces.index, sol.time_s[:-1], atol=1e-12)
    muscle = forces[list(sol.muscles)].to_numpy()
    assert muscle.min() > 0, muscle.min()
    states = read_storage(folder / "states.sto")
    norm = states[[c for c in states.columns if c.endswith("/normalized_tendon_force")
                   and c.split("/")[-2] in sol.muscles]].to_numpy()
    assert norm.shape == (sol.time_s.size - 1, len(sol.muscles)) and norm.min() > 0
    n = sol.time_s.size
    for name in ("forces.sto", "states.sto", "controls.sto"):
        head = (folder / name).read_text().split("endheader")[0]
        assert f"nodes 0-{n - 2} of the solution's {n}" in head and f"node {n - 1} (0.85 s)" in head, name


def test_files_are_the_same_prepared_during_the_solve_and_from_the_cache(solved, example, geometry_cache, tmp_path,
                                                                         monkeypatch):
    """``musclemetab solve`` has the OpenSim worker prepare the solution's model while IPOPT
    solves (``solve_files``' ``before_solve`` calls ``prepare_opensim_files``); a write that finds
    the prepared model only writes it. The problem ``before_solve`` is told of is the solution's
    (mesh, parameters, DOFs), and the files are byte for byte those of a write that does all the
    model work itself.

    That model work is cached by content, the solved muscles' parameter values left out of the
    key: a cache filled by a write of the solution with other parameters (F0, lTs, kT and the
    passive curve changed) serves this solution with no OpenSim at all (the cached model text
    gets its parameters), with the same four files byte for byte; ``musclemetab solve`` with that
    cache starts no OpenSim worker."""
    from pathlib import Path

    from musclemetab.opensim_bridge import call
    from musclemetab.redundancy import problem, run
    from musclemetab.redundancy.export import OPENSIM_FILES, prepare_opensim_files, write_opensim_files

    _, folder = solved("effort-gen")  # written by the command, with the model prepared during its solve
    args = (example.model, example.ik["normal"], example.id["normal"], "effort-gen")
    sol = run.solve_files(*args, cache_dir=geometry_cache)  # the command's solution (the session's memo)
    told = {}

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    monkeypatch.setattr(problem, "solve_with_parameters", stop)  # the problem up to IPOPT, not solved again
    with pytest.raises(Stop):
        getattr(run.solve_files, "__wrapped__", run.solve_files)(
            *args, cache_dir=geometry_cache, before_solve=lambda **outline: told.update(outline))
    np.testing.assert_array_equal(told["time_s"], sol.time_s)
    assert tuple(told["dofs"]) == tuple(sol.dofs) and told["parameters"].names == sol.parameters.names
    from musclemetab.redundancy.parameters import PARAMETER_FIELDS

    for field in PARAMETER_FIELDS:
        np.testing.assert_array_equal(getattr(told["parameters"], field), getattr(sol.parameters, field), field)

    # an empty cache of the files' model work: the worker does it
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(tmp_path / "cache-prepared"))
    prepare_opensim_files(**told)
    prepared = call("solution_model:prepared_models")  # (waits for the preparation)
    write_opensim_files(sol, tmp_path / "prepared")
    assert call("solution_model:prepared_models") == prepared  # the write found the model prepared
    # the same model file under another path, another empty cache: nothing prepared for it, all the
    # work in the write
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(tmp_path / "cache-unprepared"))
    model = Path(sol.record.inputs["model"])
    copy = tmp_path / "copy" / model.name
    copy.parent.mkdir()
    copy.write_bytes(model.read_bytes())
    write_opensim_files(sol, tmp_path / "unprepared", model_path=copy)
    assert call("solution_model:prepared_models")[-1] not in prepared
    for name in OPENSIM_FILES:
        unprepared = (tmp_path / "unprepared" / name).read_bytes()
        assert (tmp_path / "prepared" / name).read_bytes() == unprepared, name
        assert (folder / name).read_bytes() == unprepared, name

    import dataclasses

    from musclemetab.commands import main
    from musclemetab.opensim_bridge import client

    p = sol.parameters
    other = dataclasses.replace(sol, parameters=dataclasses.replace(
        p, max_isometric_force_N=p.max_isometric_force_N * 1.5, tendon_slack_length_m=p.tendon_slack_length_m * 0.97,
        tendon_stiffness=p.tendon_stiffness * 0.5, passive_kpe=p.passive_kpe + 1.0))
    cache = tmp_path / "cache-other"
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(cache))
    write_opensim_files(other, tmp_path / "other")  # the worker does the model work, the cache keeps it
    assert len(list((cache / "geometry").glob("osimfiles-*.npz"))) == 1
    assert (tmp_path / "other" / "model.osim").read_bytes() != (folder / "model.osim").read_bytes()
    started = []

    def refuse():
        started.append(True)
        raise RuntimeError("the OpenSim worker was asked for although the cache holds the files' model work")

    monkeypatch.setattr(client, "_ensure_started", refuse)
    prepare_opensim_files(**told)
    write_opensim_files(sol, tmp_path / "warm")
    for name in OPENSIM_FILES:
        assert (tmp_path / "warm" / name).read_bytes() == (tmp_path / "unprepared" / name).read_bytes(), name
    # the command with --cache-dir finds the files' model work there (the entry is the same, by content)
    import shutil

    for entry in (cache / "geometry").glob("osimfiles-*.npz"):
        shutil.copy(entry, Path(geometry_cache) / entry.name)
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(tmp_path / "cache-unused"))  # not the one --cache-dir names
    out = tmp_path / "again"
    assert main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                 str(example.id["normal"]), "--workflow", "effort-gen", "--cache-dir", str(geometry_cache),
                 "--out", str(out)]) == 0  # the solve: the test run's memo
    for name in OPENSIM_FILES:
        assert (out / name).read_bytes() == (tmp_path / "unprepared" / name).read_bytes(), name
    assert started == []
    # a damaged entry: deleted with a warning, the work done again by OpenSim, the same files
    monkeypatch.undo()
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(cache))
    from musclemetab.errors import CacheWarning

    (entry,) = (cache / "geometry").glob("osimfiles-*.npz")
    entry.write_bytes(entry.read_bytes()[:-100])
    with pytest.warns(CacheWarning, match=f"{entry.name} cannot be read"):
        write_opensim_files(sol, tmp_path / "redone", model_path=copy)
    for name in OPENSIM_FILES:
        assert (tmp_path / "redone" / name).read_bytes() == (tmp_path / "unprepared" / name).read_bytes(), name
    assert np.load(entry)["model"].size > 0  # written again, readable


@pytest.fixture(scope="module")
def gait2392_right(gait2392, tmp_path_factory):
    """EFFORT-GEN on the right leg of gait2392, inverse dynamics computed by OpenSim from the
    ground forces (the right leg of tests/test_gait2392.py's both-leg solve)."""
    return _solve(tmp_path_factory.mktemp("g2392"), [
        "solve", "--model", str(gait2392.model), "--ik", str(gait2392.ik), "--external-loads",
        str(gait2392.external_loads), "--cycle", "auto", "--side", "r"])


def test_knee_contact_force_from_opensim_joint_reaction(gait2392, gait2392_right, tmp_path):
    """OpenSim's JointReaction over the solution's files, with the trial's ground forces.

    Oracle 1 (Newton's second law): with the muscles' forces set to zero and every coordinate's
    inverse-dynamics force on its reserve, the knee force on the tibia, the ground force and the
    weight of the shank and foot (masses from the model file) add up to the shank and foot's
    mass times their acceleration: within 0.15 body weights at every stance node, 0.06 rms
    (measured 0.10 and 0.04). Oracle 2: with the solution's forces, the knee's axial force
    peaks within 2-8 body weights in stance. Measured: 7.1 body weights at 1.22 s (push-off),
    where the knee-crossing muscles of this EFFORT-GEN solution carry 6.2 body weights
    (gastrocnemius medialis 1.44 kN, semimembranosus, rectus femoris, tensor fasciae latae,
    biceps short head): above the 2.61 body weights that instrumented knee implants measured on
    average in level walking (Kutzner et al. 2010), as models without ligaments that minimise
    effort often are.
    """
    import shutil
    import xml.etree.ElementTree as ET

    from musclemetab.io import read_storage, write_storage
    from musclemetab.model import read_model
    from musclemetab.redundancy.export import inverse_dynamics_at, joint_reaction

    sol, folder = gait2392_right
    t = sol.time_s[:-1]  # the files' nodes: those where the Hill equilibrium holds (docs/opensim_files.md)
    weight = read_model(gait2392.model).body_mass_kg * 9.80665
    grf = read_storage(gait2392.grf)
    ground = np.column_stack([np.interp(t, grf.index, grf[f"ground_force_v{a}"]) for a in "xyz"])
    stance = ground[:, 1] > 200.0
    assert stance.sum() > 50
    # 1: no muscles, the inverse dynamics on the reserves
    bare = tmp_path / "no_muscles"
    shutil.copytree(folder, bare)
    forces = read_storage(bare / "forces.sto")
    reserves = [c for c in forces.columns if c.startswith("reserve_")]
    id_at = inverse_dynamics_at(folder / "inverse_dynamics.sto", [c[len("reserve_"):] for c in reserves], t)
    for c in forces.columns:
        forces[c] = id_at[c[len("reserve_"):]] if c in reserves else 0.0
    write_storage(bare / "forces.sto", forces, name="Static Optimization", in_degrees=False)
    f = joint_reaction(bare, ["knee_r"], tmp_path / "jr0", external_loads=gait2392.external_loads,
                       frame="ground")["forces"]["knee_r"]
    root = ET.parse(gait2392.model).getroot()
    mass = {b.get("name"): float(b.find("mass").text) for b in root.iter("Body")}
    shank_foot_N = 9.80665 * sum(mass[b] for b in ("tibia_r", "talus_r", "calcn_r", "toes_r"))
    residual = np.linalg.norm(f + ground - [0.0, shank_foot_N, 0.0], axis=1)[stance] / weight
    assert residual.max() < 0.15 and np.sqrt(np.mean(residual**2)) < 0.06, residual.max()
    # 2: the solution's forces
    res = joint_reaction(folder, ["knee_r"], tmp_path / "jr", external_loads=gait2392.external_loads)
    np.testing.assert_allclose(res["time_s"], t, atol=1e-9)
    f = res["forces"]["knee_r"]  # on the tibia, in the tibia's frame: y along its long axis
    assert np.all(np.isfinite(f))
    axial = -f[:, 1] / weight  # compression positive, body weights
    peak = float(axial.max())
    assert 2.0 < peak < 8.0, peak
    # the peak falls in stance (right heel strike 0.618 s, toe-off 1.410 s: README of the data)
    assert 0.618 < float(res["time_s"][int(np.argmax(axial))]) < 1.410


def test_a_locked_coordinate_the_motion_moves_follows_it_in_the_written_model(example, tmp_path):
    """A model locking knee_angle_l, solved on the right leg: the geometry takes the left knee
    at the IK's angle, so the written model prescribes the left knee along the motion (not at
    its locked 0 deg) and the states hold the IK's angle; OpenSim, given the written model,
    assembles it and puts the knee where the IK does at every node time. The subtalar and mtp joints, which
    the motion holds at their locked value, stay constant."""
    import json
    import subprocess
    import sys

    from musclemetab.io import read_table
    from musclemetab.opensim_bridge import call

    from model_edits import with_locked_coordinate

    model = with_locked_coordinate(example.model, "knee_angle_l", tmp_path / "locked_left_knee.osim")
    ik = read_table(example.ik["normal"])
    times = np.linspace(0.6, 0.8, 21)
    soleus = {"max_isometric_force_N": 3000.0, "optimal_fiber_length_m": 0.05, "tendon_slack_length_m": 0.25,
              "pennation_angle_at_optimal_rad": 0.4, "max_contraction_velocity": 10.0,
              "tendon_strain_at_one_norm_force": 0.049, "passive_fiber_strain_at_one_norm_force": 0.6,
              "activation_time_constant_s": 0.015, "deactivation_time_constant_s": 0.06}
    out = tmp_path / "model.osim"
    info = call("solution_model:solution_model", str(model), str(out), {"soleus_r": soleus},
                np.asarray(ik.index, dtype=float),
                {c: np.ascontiguousarray(ik[c]) for c in ik.columns}, True, times, ["ankle_angle_r"])
    want = np.deg2rad(np.interp(times, np.asarray(ik.index, dtype=float), np.asarray(ik["knee_angle_l"], dtype=float)))
    assert np.ptp(want) > 0.3  # the left knee moves by more than 17 deg over the window
    knee = [k for k in info["values"] if k.endswith("/knee_angle_l/value")][0]
    np.testing.assert_allclose(info["values"][knee], want, atol=2e-3)
    assert "knee_angle_l" in info["prescribed_coordinates"]
    subtalar = [k for k in info["values"] if k.endswith("/subtalar_angle_l/value")][0]
    assert np.ptp(info["values"][subtalar]) == 0
    # OpenSim (in a process of its own: it cannot share one with CasADi) loads the written model,
    # assembles it at time 0 and evaluates the knee's prescribed function
    script = ("import json, sys, opensim as osim\n"
              "osim.Logger.setLevelString('error')\n"
              "m = osim.Model(sys.argv[1]); m.initSystem()\n"
              "f = m.getCoordinateSet().get('knee_angle_l').getPrescribedFunction()\n"
              "print(json.dumps([f.calcValue(osim.Vector(1, float(t))) for t in json.loads(sys.argv[2])]))\n")
    at = [0.0, *times.tolist()]
    r = subprocess.run([sys.executable, "-c", script, str(out), json.dumps(at)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    values = json.loads(r.stdout.strip().splitlines()[-1])
    # the model file keeps 6 significant digits; held at the first node's value before the window
    np.testing.assert_allclose(values[1:], info["values"][knee], rtol=1e-5, atol=1e-9)
    assert values[0] == pytest.approx(info["values"][knee][0], abs=1e-9)


def test_the_joint_reaction_example_of_the_docs_writes_the_file_it_names(gait2392_right, tmp_path):
    """The Python example of docs/opensim_files.md ("knee contact force with OpenSim's
    JointReaction analysis"), run by OpenSim over the first four states of the solution's files
    (without the ground forces, which do not change the file's name): OpenSim writes the file
    the example's last comment names, with the columns it names. The example used to name
    ``jr/<name>_JointReaction_ReactionLoads.sto``, a file OpenSim does not write: without names
    it writes ``_Un-named analysis._ReactionLoads``."""
    import re
    import subprocess
    import sys
    from pathlib import Path

    from musclemetab.io import read_storage

    _, folder = gait2392_right
    text = (Path(__file__).resolve().parents[1] / "docs" / "opensim_files.md").read_text()
    section = text[text.index("## Example: knee contact force with OpenSim's JointReaction analysis"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    named = re.search(r"tool\.run\(\)\s+# (\S+): (knee\S+)_fx, fy, fz", code)
    code = "\n".join(line for line in code.splitlines() if "ExternalLoads(" not in line)
    code = code.replace('folder = "out/r"', f"folder = {str(folder)!r}")
    states = read_storage(folder / "states.sto").index
    code = code.replace("import opensim as osim",
                        f"import opensim as osim\nosim.Logger.setLevelString('error')\n"
                        f"t0, t1 = {float(states[0])!r}, {float(states[3])!r}")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    written = tmp_path / named.group(1)
    assert sorted(p.name for p in written.parent.iterdir()) == [written.name]
    table = read_storage(written)
    assert len(table) == 4 and [f"{named.group(2)}_f{a}" for a in "xyz"] == [c for c in table.columns
                                                                            if c.startswith(named.group(2) + "_f")]

"""Adversarial studies: names that would become paths outside the output folder, folders the
package did not create, two runs on one folder, leftovers of killed runs, Ctrl-C, options
that cannot work and outputs that cannot be written. None of these cases solves anything:
each one must be refused, or handled, before or instead of any solver work."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import InputFileError, OptionError, SolverError
from musclemetab.study import run_study, study_from_dict
from musclemetab.study import units as units_mod
from musclemetab.study.runner import LOCK_FILE, STUDY_JSON, StudyRun, study_lock
from musclemetab.study.units import MARKER_FILE, Unit, remove_stale_partials, unit_folder


def _study(example, *, subject="sub1", trials=("slow", "normal"), workflows=("effort-gen",), **subject_keys):
    return {
        "name": "adversarial",
        "workflows": list(workflows),
        "models": ["UM10"],
        "subjects": [{
            "name": subject,
            "model": str(example.model),
            "body_mass_kg": example.body_mass_kg,
            "height_m": example.height_m,
            "trials": [{"name": t, "ik": str(example.ik[t]), "id": str(example.id[t])} for t in trials],
            **subject_keys,
        }],
    }


# ----------------------------------------------------------------------------- names and paths
@pytest.mark.parametrize("name", ["../../../victim", "../../evil", "/tmp/absolute", ".hidden", "a/b", "a\\b", "..", ""])
@pytest.mark.parametrize("where", ["subject", "trial"])
def test_names_that_are_not_plain_folder_names_are_refused(example, tmp_path, name, where):
    victim = tmp_path / "victim" / "normal" / "effort-gen"
    victim.mkdir(parents=True)
    (victim / "precious.txt").write_text("keep me")
    data = _study(example)
    if where == "subject":
        data["subjects"][0]["name"] = name
    else:
        data["subjects"][0]["trials"][0]["name"] = name
    with pytest.raises(OptionError, match="name"):
        study_from_dict(data, base="/", output=tmp_path / "study" / "out")
    assert (victim / "precious.txt").read_text() == "keep me"
    assert not (tmp_path / "study").exists()


def test_unit_folders_must_stay_inside_the_output_folder(tmp_path):
    out = tmp_path / "out"
    assert unit_folder(out, Unit("sub1", "normal", "effort-gen")) == (out / "units/sub1/normal/effort-gen").resolve()
    for unit in (Unit("../../..", "x", "effort-gen"), Unit("sub1", "x", "../../../../etc")):
        with pytest.raises(OptionError, match="outside the output folder"):
            unit_folder(out, unit)


def test_a_folder_the_package_did_not_create_is_never_replaced(tmp_path):
    folder = tmp_path / "units" / "sub1" / "normal" / "effort-gen"
    folder.mkdir(parents=True)
    (folder / "precious.txt").write_text("keep me")
    new = tmp_path / "units" / "sub1" / "normal" / ".effort-gen.partial-1"
    new.mkdir()
    (new / MARKER_FILE).write_text("")
    (new / "unit.json").write_text("{}")
    with pytest.raises(OptionError, match="not written by musclemetab"):
        units_mod._replace_folder(new, folder)
    assert (folder / "precious.txt").read_text() == "keep me" and new.is_dir()
    # a folder of ours is replaced, and the old one removed
    (folder / "precious.txt").unlink()
    (folder / MARKER_FILE).write_text("")
    units_mod._replace_folder(new, folder)
    assert (folder / "unit.json").is_file() and not new.exists()
    assert [p.name for p in folder.parent.iterdir()] == ["effort-gen"]


def test_stale_partial_folders_are_removed_only_when_marked(tmp_path):
    parent = tmp_path / "units" / "sub1" / "normal"
    ours, theirs = parent / ".effort-gen.partial-abc", parent / ".notes.partial-keep"
    for p in (ours, theirs):
        p.mkdir(parents=True)
        (p / "solution.sto").write_bytes(b"x" * 1000)
    (ours / MARKER_FILE).write_text("")
    assert remove_stale_partials(tmp_path) == [ours]
    assert not ours.exists() and (theirs / "solution.sto").is_file()


# ----------------------------------------------------------------------------- study file values
@pytest.mark.parametrize("edit, words", [
    (lambda d: d.update(workflows=5), "'workflows' must be a list"),
    (lambda d: d.update(models=3), "'models' must be"),
    (lambda d: d.update(output=5), "'output' must be a folder path"),
    (lambda d: d["subjects"][0].update(body_mass_kg=72600), "not a human body mass in kilograms"),
    (lambda d: d["subjects"][0].update(body_mass_kg=7.26), "not a human body mass in kilograms"),
    (lambda d: d["subjects"][0]["trials"][0].update(ik=5), "'ik' must be a file path"),
])
def test_study_values_of_the_wrong_kind_are_one_line_errors(example, edit, words):
    data = _study(example)
    edit(data)
    with pytest.raises(OptionError, match=words) as info:
        study_from_dict(data, base="/")
    assert "\n" not in str(info.value)


def test_a_folder_where_a_file_is_expected_says_so(example, tmp_path):
    data = _study(example)
    data["subjects"][0]["trials"][0]["ik"] = str(tmp_path)
    with pytest.raises(InputFileError, match="is the folder .* not a file"):
        study_from_dict(data, base="/")


def test_a_folder_given_as_the_study_file_names_the_study_files_in_it(tmp_path):
    from musclemetab.study.spec import load_study

    with pytest.raises(InputFileError, match=r"is a folder; give the study file itself, a \.toml file$"):
        load_study(tmp_path)
    (tmp_path / "study.toml").write_text("")
    with pytest.raises(InputFileError, match=rf"{tmp_path} is a folder; give the study file itself \({tmp_path / 'study.toml'}\)$"):
        load_study(tmp_path)


def test_failed_units_are_said_on_standard_error(capsys):
    """What a run did goes to standard output; each failed unit's line, its reason, to standard
    error (with the other errors), an interrupted unit's to neither."""
    from types import SimpleNamespace

    from musclemetab.commands.run import print_run

    run = SimpleNamespace(summary_line=lambda: "3 units: 1 run, 0 up to date; 2 failed", removed_partials=[],
                          failed={"s/walk/effort-gen": "ModelError: m.osim: OpenSim cannot load this model",
                                  "s/walk/effort-ten": "interrupted"}, interrupted={"s/walk/effort-ten"})
    print_run(run, "run")
    out, err = capsys.readouterr()
    assert out == "run: 3 units: 1 run, 0 up to date; 2 failed\n"
    assert err == "run: failed s/walk/effort-gen: ModelError: m.osim: OpenSim cannot load this model\n"


# ----------------------------------------------------------------------------- before anything is written
@pytest.mark.parametrize("kwargs, words", [
    ({"workers": 0}, "--workers must be"),
    ({"workers": -2}, "--workers must be"),
    ({"scheduler": "notanaddress"}, "not an address"),
    ({"scheduler": "http://localhost:8787"}, "dashboard"),
    ({"scheduler": "tls://localhost:8786"}, "TLS settings"),
    ({"scheduler": "tcp://localhost"}, "no host and port"),
    ({"scheduler": "ftp://localhost:21"}, "unknown protocol"),
])
def test_bad_executor_options_fail_at_once_and_write_nothing(example, tmp_path, kwargs, words, monkeypatch):
    import distributed

    def no_connection(*args, **kwargs):  # a connection attempt would wait for a timeout
        raise AssertionError("a scheduler connection was attempted")

    monkeypatch.setattr(distributed, "Client", no_connection)
    study = study_from_dict(_study(example), base="/", output=tmp_path / "out")
    with pytest.raises(OptionError, match=words):
        run_study(study, progress=False, **kwargs)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("kind", ["file", "below a file", "unwritable"])
def test_an_output_that_cannot_be_a_folder_is_refused_before_anything(example, tmp_path, kind):
    existing = tmp_path / "results.txt"
    existing.write_text("not a folder")
    out = {"file": existing, "below a file": existing / "sub", "unwritable": Path("/proc/musclemetab-out")}[kind]
    study = study_from_dict(_study(example), base="/", output=out)
    with pytest.raises(OptionError, match="output folder"):
        run_study(study, workers=1, progress=False)
    assert existing.read_text() == "not a folder" and sorted(p.name for p in tmp_path.iterdir()) == ["results.txt"]


# ----------------------------------------------------------------------------- the lock
def test_a_second_run_on_the_same_folder_refuses(example, tmp_path, capsys):
    from musclemetab.commands import main

    out = tmp_path / "out"
    study = study_from_dict(_study(example), base="/", output=out)
    with study_lock(out) as lock:
        holder = json.loads(lock.path.read_text())
        assert holder["pid"] == os.getpid()
        with pytest.raises(OptionError, match=f"in use by another musclemetab run .*{LOCK_FILE}"):
            run_study(study, workers=1, progress=False)
        toml = tmp_path / "study.toml"
        toml.write_text(
            f'output = "out"\nworkflows = ["effort-gen"]\n[[subjects]]\nname = "s"\nmodel = "{example.model}"\n'
            f'body_mass_kg = 72.6\nheight_m = 1.743\n[[subjects.trials]]\nname = "normal"\n'
            f'ik = "{example.ik["normal"]}"\nid = "{example.id["normal"]}"\n'
        )
        capsys.readouterr()
        assert main(["run", str(toml), "--no-progress"]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "lock file" in err and "wait for that run" in err
    assert not (out / LOCK_FILE).exists() and not (out / "units").exists()


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "out"
    out.mkdir()
    import socket

    (out / LOCK_FILE).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(), "started": "then"}))
    with study_lock(out) as lock:
        assert json.loads(lock.path.read_text())["pid"] == os.getpid()
    assert not (out / LOCK_FILE).exists()


# ----------------------------------------------------------------------------- Ctrl-C and counting
def _count_calls(monkeypatch, behaviour):
    calls = []

    def fake_trial(study, unit, tmp, *dependencies):
        calls.append(unit.label)
        return behaviour(unit, tmp)

    monkeypatch.setattr(units_mod, "_run_trial", fake_trial)
    return calls


@pytest.mark.parametrize("how", ["KeyboardInterrupt", "solver swallows SIGINT"])
def test_ctrl_c_marks_the_running_unit_interrupted_and_starts_nothing_new(example, tmp_path, monkeypatch, how):
    """The unit's work is replaced by one that gets Ctrl-C half-way, as a solve would."""
    def interrupted(unit, tmp):
        (tmp / "solution.sto").write_text("half")
        if how == "KeyboardInterrupt":
            raise KeyboardInterrupt
        try:  # a real SIGINT, caught by the solver, which reports a failed solve
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        raise SolverError("effort-gen solve did not converge (status NonIpopt_Exception_Thrown)")

    calls = _count_calls(monkeypatch, interrupted)
    out = tmp_path / "out"
    (out / "units" / "sub1" / "slow").mkdir(parents=True)
    stale = out / "units" / "sub1" / "slow" / ".effort-gen.partial-old"
    stale.mkdir()
    (stale / MARKER_FILE).write_text("")
    study = study_from_dict(_study(example, trials=("slow", "normal", "fast")), base="/", output=out)
    run = run_study(study, workers=1, progress=False)
    assert calls == ["sub1/slow/effort-gen"]  # the queued units never started
    assert run.interrupted == ["sub1/slow/effort-gen"] and run.removed_partials == [stale]
    assert run.summary_line().startswith("3 units: 1 run, 0 up to date, 2 not started; 0 failed, 1 interrupted")
    # nothing half-written: no unit folder, no temporary folder, no lock
    assert sorted(p.name for p in (out / "units" / "sub1").rglob("*")) == ["slow"]
    assert not (out / LOCK_FILE).exists()
    failures = pd.read_csv(out / "failures.csv")
    assert failures.set_index("trial").loc["slow", "reason"].startswith("interrupted")


def test_ctrl_c_on_the_command_line_exits_130(example, tmp_path, monkeypatch, capsys):
    from musclemetab.commands.run import exit_status as _status

    def interrupted(unit, tmp):
        raise KeyboardInterrupt

    _count_calls(monkeypatch, interrupted)
    study = study_from_dict(_study(example), base="/", output=tmp_path / "out")
    run = run_study(study, workers=1, progress=False)
    assert _status(run) == 130
    assert "interrupted" in capsys.readouterr().err


def test_units_not_run_because_a_unit_they_need_failed_are_counted(example, tmp_path):
    """An EMG-TEN estimation that fails (its EMG file is not a storage file) blocks two units."""
    bad_emg = tmp_path / "emg.mot"
    bad_emg.write_text("not an EMG file\n")
    data = _study(example, workflows=("emg-ten",))
    for t in data["subjects"][0]["trials"]:
        t["emg"] = str(bad_emg)
    study = study_from_dict(data, base="/", output=tmp_path / "out")
    run = run_study(study, workers=1, progress=False)
    assert run.ran == ["sub1/all trials/emg-ten"] and len(run.blocked) == 2
    line = run.summary_line()
    assert line.startswith("3 units: 1 run, 0 up to date, 2 not run (a unit they need failed); 3 failed"), line
    assert "emg.mot" in run.failed["sub1/all trials/emg-ten"]


def test_summary_line_counts_each_unit_once():
    run = StudyRun(output=Path("o"), ran=["a", "b"], skipped=["c"], failed={"b": "x"}, n_planned=3)
    assert run.summary_line().startswith("3 units: 2 run, 1 up to date; 1 failed;")


@pytest.mark.parametrize("workers", [1, 2])
def test_ctrl_c_on_a_real_run(example, tmp_path, workers):
    """``musclemetab run`` in its own process group gets SIGINT (as from a terminal) while its
    first units work: exit status 130, the running units interrupted, nothing queued started,
    no temporary folder, no lock. With ``--workers 2`` (a process pool) both trials start at
    once and both are interrupted; the third, queued, never starts."""
    out = tmp_path / "out"
    toml = tmp_path / "study.toml"
    trials = ("normal", "slow") if workers == 1 else ("normal", "slow", "fast")
    toml.write_text(
        f'output = "out"\nworkflows = ["effort-gen"]\nmodels = ["UM10"]\n[[subjects]]\nname = "s"\n'
        f'model = "{example.model}"\nbody_mass_kg = 72.6\nheight_m = 1.743\n' + "".join(
            f'[[subjects.trials]]\nname = "{t}"\nik = "{example.ik[t]}"\nid = "{example.id[t]}"\n'
            for t in trials)
    )
    proc = subprocess.Popen([sys.executable, "-m", "musclemetab", "run", str(toml), "--workers", str(workers),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while (len(list((out / "units").rglob(".*.partial-*"))) < workers and proc.poll() is None
               and time.monotonic() < deadline):
            time.sleep(0.1)
        time.sleep(1.0)  # the units are computing their geometry or solving (as in the SIGTERM test below)
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, (stdout, stderr)
    assert f"{workers} interrupted" in stdout and "musclemetab: interrupted" in stderr
    assert "Traceback" not in stderr
    reasons = pd.read_csv(out / "failures.csv").set_index("trial")["reason"]
    started = sorted(t for t in reasons.index if reasons[t].startswith("interrupted"))
    assert len(started) == workers, reasons
    assert f"{len(trials)} units: {workers} run, 0 up to date, {len(trials) - workers} not started; 0 failed" in stdout
    assert sorted(p.relative_to(out).as_posix() for p in (out / "units").rglob("*")) == \
        ["units/s"] + [f"units/s/{t}" for t in started]
    assert not (out / LOCK_FILE).exists()


def test_a_call_interrupted_mid_way_does_not_leave_its_reply_to_the_next(example, monkeypatch):
    """Ctrl-C while the OpenSim worker computes: the next call (the next unit of a study in
    the same pool process) gets its own reply, not the interrupted call's."""
    from musclemetab.opensim_bridge import client

    real_recv = client.receive_message
    armed = []

    def interrupted_recv(stream):
        if armed:
            armed.clear()
            raise KeyboardInterrupt  # after the request was sent, before its reply was read
        return real_recv(stream)

    monkeypatch.setattr(client, "receive_message", interrupted_recv)
    client.call("model_ops:read_model_info", str(example.model))  # the worker is up (its "ready" read)
    armed.append(True)
    with pytest.raises(KeyboardInterrupt):
        client.call("model_ops:read_time_series_table", str(example.ik["normal"]))
    slow = client.call("model_ops:read_time_series_table", str(example.ik["slow"]))
    from musclemetab.io.storage import read_storage

    times = {t: read_storage(example.ik[t]).index.to_numpy() for t in ("normal", "slow")}
    assert len(times["slow"]) != len(times["normal"])
    np.testing.assert_allclose(slow["time"], times["slow"], atol=1e-9)


# ----------------------------------------------------------------------------- side = "both"
def _both(example, **subject_keys):
    data = _study(example, trials=("normal",), side="both", **subject_keys)
    data["subjects"][0]["trials"][0]["cycle"] = "auto"
    return data


@pytest.mark.parametrize("edit, words", [
    (lambda d: d["subjects"][0]["trials"][0].pop("cycle"), ["side = \"both\"", "cycle = \"auto\"", "normal"]),
    (lambda d: d["subjects"][0].update(dofs=["knee_angle_r"]), ["'dofs' names one leg's DOFs"]),
    (lambda d: d["subjects"][0]["trials"][0].update(toe_off_s=1.0), ["toe_off_s belongs to one leg", "normal"]),
    (lambda d: d["subjects"][0]["trials"][0].update(grf_column="ground_force_vy"), ["grf_column belongs to one leg"]),
    (lambda d: d.update(workflows=["effort-gen", "emg-ten"]), ["the emg-ten workflow", "own subject"]),
    (lambda d: d["subjects"][0].update(side="left"), ["'side' must be \"r\", \"l\" or \"both\"", "left"]),
])
def test_both_legs_refuses_what_belongs_to_one_leg(example, edit, words):
    data = _both(example)
    edit(data)
    if "emg-ten" in data["workflows"]:
        data["subjects"][0]["trials"][0]["emg"] = str(example.emg["normal"])
    with pytest.raises(OptionError) as info:
        study_from_dict(data, base="/")
    assert all(w in str(info.value) for w in words), str(info.value)


def test_both_legs_make_one_unit_per_leg_with_their_own_keys(example):
    from musclemetab.study import plan_units
    from musclemetab.study.units import unit_key

    both = study_from_dict(_both(example), base="/", output="/tmp/out")
    units = plan_units(both)[1]
    assert [(u.folder.as_posix(), u.label) for u in units] == [
        ("units/sub1/normal/effort-gen/r", "sub1/normal/effort-gen/r"),
        ("units/sub1/normal/effort-gen/l", "sub1/normal/effort-gen/l")]
    assert [u.leg(both) for u in units] == ["r", "l"]
    keys = {unit_key(both, u) for u in units}
    assert len(keys) == 2
    # the unit of a one-sided subject keeps its folder, label and key (no side in them)
    one = study_from_dict(_study(example, trials=("normal",)), base="/", output="/tmp/out")
    (single,) = plan_units(one)[1]
    assert single.side is None and single.folder.as_posix() == "units/sub1/normal/effort-gen"
    assert unit_key(one, single) not in keys


def test_changing_side_replaces_only_our_unit_folders(tmp_path):
    """r -> both: the single-leg unit folder of the earlier run makes way for the legs' folders;
    both -> r: the container of the legs' folders is replaced by the single unit's folder; a
    folder the package did not write is never touched."""
    from musclemetab.study.units import UNIT_FILE, prepare_leg_folder

    out = tmp_path / "out"
    single = out / "units" / "sub1" / "normal" / "effort-gen"
    single.mkdir(parents=True)
    for name in (MARKER_FILE, UNIT_FILE, "solution.sto"):
        (single / name).write_text("{}")
    prepare_leg_folder(out, Unit("sub1", "normal", "effort-gen", "r"))
    assert (single / MARKER_FILE).is_file() and not (single / "solution.sto").exists()
    assert [p.name for p in single.parent.iterdir()] == ["effort-gen"]
    leg = single / "r"
    leg.mkdir()
    (leg / MARKER_FILE).write_text("")
    new = single.parent / ".effort-gen.partial-1"
    new.mkdir()
    (new / UNIT_FILE).write_text("{}")
    units_mod._replace_folder(new, single)  # back to one leg: the container is ours
    assert (single / UNIT_FILE).is_file() and not (single / "r").exists()
    theirs = out / "units" / "sub2" / "normal" / "effort-gen"
    theirs.mkdir(parents=True)
    (theirs / "precious.txt").write_text("keep me")
    with pytest.raises(OptionError, match="not written by musclemetab"):
        prepare_leg_folder(out, Unit("sub2", "normal", "effort-gen", "l"))
    assert (theirs / "precious.txt").read_text() == "keep me"


def test_a_trial_without_events_or_ankle_moment_says_how_to_give_the_cycle(example, tmp_path):
    """No ground forces, no events and an ID file without the side's ankle moment (another model's
    naming): one error naming the trial and the column, and the ways to give the cycle."""
    from musclemetab.errors import MissingColumnError
    from musclemetab.io import read_storage, write_storage
    from musclemetab.study.events import trial_cycle
    from musclemetab.study.spec import Trial

    moments = read_storage(example.id["normal"]).rename(columns={"ankle_angle_r_moment": "ankle_r_moment"})
    id_file = tmp_path / "id.sto"
    write_storage(id_file, moments)
    with pytest.raises(MissingColumnError) as info:
        trial_cycle(Trial(name="walk", ik=example.ik["normal"], id=id_file), "r")
    for words in ("trial 'walk'", "ankle_angle_r_moment", "cycle = \"auto\"", "start_s, toe_off_s and end_s"):
        assert words in str(info.value)


def _descendants(pid: int) -> set[int]:
    """The processes below ``pid`` (children, theirs...), from /proc."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # ended meanwhile
            continue
        ppid = int(text[text.rindex(")") + 2:].split()[1])
        children.setdefault(ppid, []).append(int(stat.parent.name))
    found, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"  # a zombie has ended
    except OSError:
        return False


def test_sigterm_stops_a_run_as_ctrl_c_does_and_leaves_no_process(example, tmp_path):
    """``musclemetab run --workers 2`` gets SIGTERM (what a batch scheduler sends, to the main
    process alone) while its two units work: exit status 143, the running units marked
    interrupted, and no process of its tree (the two pool workers, their OpenSim workers,
    multiprocessing's resource tracker) still running 5 s later (the test waits until they have all
    ended, at most 5 s)."""
    out = tmp_path / "out"
    toml = tmp_path / "study.toml"
    toml.write_text(
        f'output = "out"\nworkflows = ["effort-gen"]\nmodels = ["UM10"]\n[[subjects]]\nname = "s"\n'
        f'model = "{example.model}"\nbody_mass_kg = 72.6\nheight_m = 1.743\n' + "".join(
            f'[[subjects.trials]]\nname = "{t}"\nik = "{example.ik[t]}"\nid = "{example.id[t]}"\n'
            for t in ("normal", "slow", "fast")))
    proc = subprocess.Popen([sys.executable, "-m", "musclemetab", "run", str(toml), "--workers", "2",
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    tree: set[int] = set()
    try:
        deadline = time.monotonic() + 120
        while (len(list((out / "units").rglob(".*.partial-*"))) < 2 and proc.poll() is None
               and time.monotonic() < deadline):
            time.sleep(0.1)
        time.sleep(1.0)  # the units are computing their geometry or solving
        tree = _descendants(proc.pid)
        os.kill(proc.pid, signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=120)
        deadline = time.monotonic() + 5.0  # every process of the tree ended within 5 s (checked every 50 ms)
        while any(_alive(p) for p in tree) and time.monotonic() < deadline:
            time.sleep(0.05)
        left = sorted(p for p in tree if _alive(p))
    finally:
        if proc.poll() is None:
            proc.kill()
        for p in tree:  # what the command left, ended by the test
            if _alive(p):
                os.kill(p, signal.SIGKILL)
    assert len(tree) >= 3, tree  # two workers and the resource tracker at least
    assert left == [], (left, stderr)
    assert proc.returncode == 143, (stdout, stderr)
    assert "musclemetab: terminated" in stderr and "Traceback" not in stderr
    reasons = pd.read_csv(out / "failures.csv").set_index("trial")["reason"]
    assert sum(r.startswith("interrupted") for r in reasons) == 2, reasons

"""The typed record of a solve (``summary.json``) and the one template of shared parameter docs.

A solve's ``summary.json`` is read into :class:`~musclemetab.redundancy.record.SolveRecord`, whose
structured entries are small frozen records (:mod:`musclemetab.redundancy.entries`); written again
it is the same file, byte for byte. The report reads the record through it.
"""

from __future__ import annotations

import dataclasses
import json
import pickle
from pathlib import Path

import pytest

from musclemetab.quality import Flag
from musclemetab.redundancy.diagnosis import Diagnosis, Finding, violation_text
from musclemetab.redundancy.entries import (
    AssistanceRecord, ConvergenceRecord, FiberLengthBounds, ReadOnlyMap, TrialRecord, WindowRecord, WorkflowRecord,
)
from musclemetab.redundancy.record import ProblemRecord, SolveRecord
from musclemetab.redundancy.solution import SUMMARY_FILE, Solution, read_summary


def _text(d) -> str:
    """The JSON text of ``d`` (NaN written as the package writes it): equal text, equal file."""
    return json.dumps(d, indent=2, allow_nan=True)


@pytest.fixture(scope="module")
def effort_gen(example, tmp_path_factory) -> Path:
    """The folder of the example subject's normal trial solved with EFFORT-GEN (the solve the
    suite shares through its memo)."""
    from musclemetab.redundancy.run import solve_files

    out = tmp_path_factory.mktemp("effort_gen") / "solution"
    solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-gen").write(out)
    return out


def test_a_solves_summary_reads_typed_and_writes_back_byte_for_byte(effort_gen, tmp_path):
    text = (effort_gen / SUMMARY_FILE).read_text(encoding="utf-8")
    raw = json.loads(text)
    record = read_summary(effort_gen)
    assert _text(record.to_dict()) == _text(raw) and list(record.to_dict()) == list(raw)
    # typed entries hold the file's values
    assert isinstance(record.workflow, WorkflowRecord) and record.workflow.name == raw["workflow"]["name"] == "effort-gen"
    assert record.workflow.weights == raw["workflow"]["weights"]
    assert record.solver_options.tol == raw["solver_options"]["tol"]
    assert record.problem_size.variables == raw["problem_size"]["variables"] > 0
    assert record.input_preparation.filter == raw["input_preparation"]["filter"]
    assert isinstance(record.convergence, ConvergenceRecord)
    assert record.convergence.max_rate_residue == raw["convergence"]["max_rate_residue"]
    assert dict(record.convergence.rate_residue) == raw["convergence"]["rate_residue"]
    assert isinstance(record.fiber_length_bounds, FiberLengthBounds)
    assert record.fiber_length_bounds.default == tuple(raw["fiber_length_bounds"]["default"])
    assert isinstance(record.diagnosis, Diagnosis)
    assert [f.to_dict() for f in record.diagnosis.findings] == raw["diagnosis"]["findings"]
    assert all(isinstance(f, Flag) for f in record.plausibility)
    assert [f.to_dict() for f in record.plausibility] == raw["plausibility"]
    assert record.time_window_s == tuple(raw["time_window_s"]) and record.muscles == tuple(raw["muscles"])
    assert record.inputs["ik"] == raw["inputs"]["ik"] and isinstance(record.inputs, ReadOnlyMap)
    # the solution loads and writes the same file again
    Solution.load(effort_gen).write(tmp_path / "again")
    assert (tmp_path / "again" / SUMMARY_FILE).read_text(encoding="utf-8") == text


def test_an_effort_solves_record_keeps_its_entries_and_their_order(effort_gen, builder_entries):
    """The entries that the record builder (``redundancy/records_build.py``) writes into a
    single-trial effort solve's ``summary.json`` are those the package wrote before one builder
    made the records of the three kinds of solve, in the same order."""
    raw = json.loads((effort_gen / SUMMARY_FILE).read_text(encoding="utf-8"))
    assert builder_entries(raw) == builder_entries.before["effort"]


def test_the_record_builder_refuses_an_entry_its_kind_does_not_write_and_a_missing_one():
    from musclemetab.redundancy.record import RunRecord
    from musclemetab.redundancy.records_build import trial_record

    run = RunRecord(status="Solve_Succeeded", success=True)
    with pytest.raises(TypeError, match="estimate records no emg_tracking"):
        trial_record("estimate", run, None, None, None, None, fiber_dynamics="forward", emg_tracking={})
    with pytest.raises(TypeError, match="effort record needs its preparation_time_s"):
        trial_record("effort", run, None, None, None, None, fiber_dynamics="forward")


def test_every_summary_of_the_demo_study_round_trips(demo):
    """The units of ``musclemetab demo`` (three trials, two workflows), also after a trip through
    pickle (as a solution travels between processes); each names the workflow of its unit folder."""
    out, _ = demo
    files = sorted(Path(out).rglob(SUMMARY_FILE))
    assert len(files) == 6
    for path in files:
        raw = json.loads(path.read_text(encoding="utf-8"))
        record = SolveRecord.from_dict(raw)
        assert _text(record.to_dict()) == _text(raw), path
        assert _text(pickle.loads(pickle.dumps(record)).to_dict()) == _text(raw), path
        assert record.workflow.name == path.parent.name and record.time_window_s == tuple(raw["time_window_s"])
        assert record.solver_options.stop == record.convergence.stop == raw["convergence"]["stop"]


def test_a_builders_dictionaries_become_typed_read_only_entries():
    device = {"file": "exo.csv", "gain": 0.5, "axis": "flexion", "dofs": ["ankle_angle_r"], "cycle_s": [0.6, 1.7],
              "cycle_source": "ground forces", "positive_work_J": 3.5, "negative_work_J": -1.0, "net_work_J": 2.5,
              "a_newer_entry": {"x": [1, 2]}}
    record = SolveRecord.from_dict({"status": "Solve_Succeeded", "success": True,
                                    "workflow": {"name": "effort-gen", "weights": {"w_activation": 1.0}}})
    record = record.with_(assistance=device)  # a stage adds a dictionary: it becomes the entry's record
    assert isinstance(record.assistance, AssistanceRecord)
    assert record.assistance.dofs == ("ankle_angle_r",) and record.assistance.positive_work_J == 3.5
    assert record.assistance.extra == {"a_newer_entry": {"x": (1, 2)}}  # kept as read, in its place
    assert list(record.to_dict()["assistance"]) == list(device) and record.to_dict()["assistance"] == device
    with pytest.raises(TypeError):
        record.workflow.weights["w_activation"] = 2.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        record.assistance.gain = 1.0
    with pytest.raises(TypeError, match="no entry 'gian'"):
        record.assistance.with_(gian=1.0)
    # the window a trial's solve records, and the gait cycle it pads
    from musclemetab.redundancy.window import TrialWindow

    window = TrialWindow(0.5, 1.8, "ground reaction forces", cycle={"start_s": 0.55, "toe_off_s": 1.2, "end_s": 1.75},
                         padding_s=(0.05, 0.05), warnings=("clipped",))
    windowed = record.with_(window=window.record())
    assert isinstance(windowed.window, WindowRecord) and windowed.window.padding_s == (0.05, 0.05)
    assert windowed.gait_cycle["toe_off_s"] == 1.2 and windowed.to_dict()["window"] == window.record()
    # an entry is also a read-only mapping of the file's entries, equal to the dictionary
    assert record.workflow == {"name": "effort-gen", "weights": {"w_activation": 1.0}}
    assert record.workflow.get("description") is None and "description" not in record.workflow


def test_diagnosis_with_the_last_iterate_round_trips_and_names_the_violations():
    finding = Finding("soleus_r", "hill_violated", "blocking", ((0.6, 0.62),), 0.61, 0.02, 1e-3, "-", "")
    diagnosis = {"thresholds": {"fiber_length_bounds": [0.1, 1.7]}, "findings": [], "last_iterate": [finding.to_dict()]}
    record = SolveRecord.from_dict({"status": "Maximum_Iterations_Exceeded", "success": False, "diagnosis": diagnosis})
    assert record.diagnosis.last_iterate == (finding,) and record.to_dict()["diagnosis"] == diagnosis
    assert "soleus_r (Hill equilibrium off by 0.02 - at 0.61 s" in violation_text(record)
    # a converged solve's diagnosis has no last iterate, and writes none
    converged = SolveRecord.from_dict({"status": "Solve_Succeeded", "success": True,
                                       "diagnosis": {"thresholds": {}, "findings": []}})
    assert converged.diagnosis.last_iterate is None and "last_iterate" not in converged.to_dict()["diagnosis"]
    assert violation_text(converged) == ""


def test_problem_record_types_its_structured_entries():
    section = {"workflow": "emg-ten", "status": "Solve_Succeeded", "success": True,
               "problem_size": {"variables": 100, "equality_constraints": 80, "mesh_intervals": 20},
               "trials": [{"label": "walk", "time_window_s": [0.6, 1.8], "n_intervals": 120, "inputs": {"ik": "w.mot"}}],
               "solver_options": {"w_activation": 1.0, "stop": "optimum", "tol": 1e-8, "ipopt": {}},
               "convergence": {"stop": "optimum", "tolerance": 1e-8, "final_barrier_parameter": None, "note": "n"}}
    record = ProblemRecord.from_dict(section)
    assert record.problem_size.mesh_intervals == 20 and record.solver_options.stop == "optimum"
    assert record.convergence.note == "n" and record.to_dict() == section
    assert isinstance(record.trials[0], TrialRecord) and record.trials[0].time_window_s == (0.6, 1.8)
    assert record.outcome_lines()[1] == "stop optimum (tolerance 1e-08); rates' convergence not checked"


def test_the_report_reads_the_typed_record(tmp_path):
    """The report's solver-run table and flags come through the typed loader: the values it shows are
    those of the units' ``summary.json``, read here as plain JSON."""
    from test_report import make_study

    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.page import solver_runs

    root = make_study(tmp_path / "study", measured=False, trials={"normal": 1.25})
    study = read_study_folder(root)
    rows = solver_runs(study)
    assert rows
    for subject, trial, workflow, side, status, iterations, *_ in rows:
        folder = root / "units" / subject / trial / workflow
        raw = json.loads((folder / SUMMARY_FILE).read_text(encoding="utf-8"))
        record = study.summary(folder)
        assert isinstance(record, SolveRecord) and record.workflow.name == raw["workflow"]["name"]
        assert (status, iterations) == (raw["status"], str(raw["iterations"]))
        assert side == {"r": "right", "l": "left"}[raw.get("side", "r")]


def test_fill_doc_fills_the_shared_text_indented_as_the_docstring():
    from numpydoc.docscrape import FunctionDoc

    from musclemetab._docs import docdict, fill_doc
    from musclemetab.metabolics import umberger2003

    def nested():
        """Something.

            Parameters
            ----------
            %(check_units)s
            """

    fill_doc(nested)
    first, *rest = docdict["check_units"].splitlines()
    assert f"            {first}\n" + "".join(f"            {ln}\n" for ln in rest) in nested.__doc__

    def unknown():
        """%(no_such_parameter)s"""

    with pytest.raises(KeyError, match="no_such_parameter"):
        fill_doc(unknown)
    # the energy models' shared arguments are parameters numpydoc reads; the Umberger family's
    # options stand at the docstring's indentation, their text under them
    params = {p.name: p for p in FunctionDoc(umberger2003)["Parameters"]}
    assert params["excitation"].type == "array_like" and params["check"].type == "bool"
    assert "\n    effort_scaling : float\n        The factor ``S`` of both heats" in umberger2003.__doc__

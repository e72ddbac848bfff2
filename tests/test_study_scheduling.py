"""Study throughput: which units run together, and the thread pools of the worker processes."""

from __future__ import annotations

import os

from musclemetab.study import study_from_dict
from musclemetab.study.runner import THREAD_VARIABLES, _Executor, _pin_threads, unit_batches


def _study(example, workflows, **subject):
    return study_from_dict({
        "name": "s", "workflows": list(workflows), "models": ["UM10"],
        "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": 70.0, "height_m": 1.7, **subject,
                      "trials": [{"name": t, "ik": str(example.ik[t]), "id": str(example.id[t]),
                                  "emg": str(example.emg[t])} for t in ("slow", "normal")]}],
    }, base="/")


def test_units_without_an_estimate_run_with_the_estimations(example):
    study = _study(example, ["effort-gen", "effort-ten", "emg-ten"], tendon_stiffness="emg-ten")
    first, second = unit_batches(study)
    assert [(u.trial, u.workflow) for u in first] == [(None, "emg-ten"), ("slow", "effort-gen"), ("normal", "effort-gen")]
    assert sorted((u.trial, u.workflow) for u in second) == [
        ("normal", "effort-ten"), ("normal", "emg-ten"), ("slow", "effort-ten"), ("slow", "emg-ten")]
    # no estimation: one batch with every unit
    (only,) = unit_batches(_study(example, ["effort-gen", "effort-ten"]))
    assert len(only) == 4


def test_worker_processes_get_their_share_of_the_cores(monkeypatch):
    for v in THREAD_VARIABLES:
        monkeypatch.delenv(v, raising=False)
    monkeypatch.setenv("MKL_NUM_THREADS", "7")  # set by the caller: kept
    executor = _Executor(2, None)
    try:
        seen = {v: executor.submit(os.getenv, v).result(timeout=120) for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                                                      "MKL_NUM_THREADS")}
    finally:
        executor.close()
    share = str(max(1, (os.cpu_count() or 1) // 2))
    assert seen == {"OMP_NUM_THREADS": share, "OPENBLAS_NUM_THREADS": share, "MKL_NUM_THREADS": "7"}
    assert "OMP_NUM_THREADS" not in os.environ  # restored after the pool
    restore = _pin_threads(3)
    assert os.environ["OPENBLAS_NUM_THREADS"] == "3" and os.environ["MKL_NUM_THREADS"] == "7"
    restore()
    assert "OPENBLAS_NUM_THREADS" not in os.environ

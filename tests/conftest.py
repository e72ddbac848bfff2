"""Shared fixtures: the example data sets, the stored reference values, a loopback mirror.

The example data are located by :mod:`musclemetab.datasets` alone: ``MUSCLEMETAB_DATA`` when
set (a folder holding one data set's files, or one sub-folder per data set), otherwise the
files are downloaded with pooch on first use. The tests need the real data: they fail, not
skip, when it cannot be had. Every value a test compares against lives in this repository
(``tests/data/``, sources named in its README) or comes from those data sets.
"""

from __future__ import annotations

import contextlib
import functools
import http.server
import os
import shutil
import threading
from pathlib import Path

import pytest

TEST_DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def example():
    from musclemetab.datasets import example_subject

    return example_subject()


@pytest.fixture(scope="session")
def gait2392():
    """OpenSim's gait2392 walking example (second subject: other model family, both legs, 60 Hz)."""
    from musclemetab.datasets import gait2392_subject01

    return gait2392_subject01()


@pytest.fixture(scope="session")
def passive_csv(example, tmp_path_factory):
    """The study's calibration (``passiveMoments.mat``) converted to the package's
    passive_parameters.csv format: one file per run, so that the solves given it are memoised."""
    import numpy as np
    import scipy.io

    mat = scipy.io.loadmat(str(example.passive_moments_mat), squeeze_me=True, struct_as_record=False)
    only = mat["sim"].Results.onlyParam
    path = tmp_path_factory.mktemp("passive") / "passive_parameters.csv"
    rows = ["muscle,kPE,s0,sM"]
    for n, k, s in zip(only.MuscleNames, only.calParam.kpe, only.calParam.ksf):
        if np.isfinite(k):
            rows.append(f"{n},{float(k)!r},{float(s)!r},0.6")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture(scope="session")
def reference_table():
    """Published per-muscle values of the example subject (``tests/data/muscle_properties_reference.csv``)."""
    import pandas as pd

    return pd.read_csv(TEST_DATA / "muscle_properties_reference.csv").set_index("name")


@pytest.fixture(scope="session")
def builder_entries():
    """``entries(summary) -> list``: the keys of a ``summary.json`` that a solve's record builder
    writes (those before the residuals), to compare with ``tests/data/trial_record_order.json``
    (``entries.before[kind]``: the keys, in order, of each kind of solve before one builder made them)."""
    import json

    def entries(summary: dict) -> list:
        keys = list(summary)
        return keys[:keys.index("max_moment_residual_Nm")]

    entries.before = json.loads((TEST_DATA / "trial_record_order.json").read_text())
    return entries


@pytest.fixture(scope="session")
def demo(tmp_path_factory):
    """``musclemetab demo`` run once per test run: ``(output folder, results table)``.

    The parallel test processes share it: the first to ask runs it, the others wait for it
    (a lock file) and read the same folder.
    """
    import pandas as pd
    import solve_memo

    from musclemetab.commands import main

    out = _run_root(tmp_path_factory) / "demo"
    with solve_memo.locked(out.with_suffix(".lock")):
        if not (out / "results.csv").is_file():
            code = main(["demo", "--out", str(out), "--workers", "2", "--no-progress"])
            assert code == 0
    return out, pd.read_csv(out / "results.csv")


@pytest.fixture(scope="session")
def two_subjects(example, gait2392, tmp_path_factory):
    """The two-subject study of ``test_trials.TWO_SUBJECTS`` (the example subject's right leg and
    gait2392's subject on both legs) run once per test run by ``musclemetab run --report``:
    ``(output folder, what the command printed)``. Shared by the parallel test processes like
    :func:`demo`. What it printed on standard error (its worker processes included: captured at
    the file descriptors) is :func:`two_subjects_stderr`."""
    import solve_memo
    from test_trials import TWO_SUBJECTS

    from musclemetab.commands import main

    root = _run_root(tmp_path_factory) / "two_subjects"
    printed = root / "printed.txt"
    with solve_memo.locked(root.with_suffix(".lock")):
        if not printed.is_file():
            shutil.rmtree(root, ignore_errors=True)
            root.mkdir()
            study = root / "study.toml"
            study.write_text(TWO_SUBJECTS.format(example=example, gait2392=gait2392))
            with _captured_fds(root / "stdout.txt", root / "stderr.txt"):
                code = main(["run", str(study), "--workers", "2", "--report"])
            assert code == 0, (root / "stderr.txt").read_text()
            (root / "stdout.txt").replace(printed)
    return root / "out", printed.read_text()


@pytest.fixture(scope="session")
def two_subjects_stderr(two_subjects) -> str:
    """What ``musclemetab run`` of :func:`two_subjects` printed on standard error (warnings, progress)."""
    return (two_subjects[0].parent / "stderr.txt").read_text()


@contextlib.contextmanager
def _captured_fds(stdout_file: Path, stderr_file: Path):
    """Standard output and error of this process and of the processes it starts, into files."""
    import sys

    with open(stdout_file, "w", buffering=1) as out, open(stderr_file, "w", buffering=1) as err:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
        try:
            os.dup2(out.fileno(), 1)
            os.dup2(err.fileno(), 2)
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                yield
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)




@pytest.fixture(scope="session")
def geometry_cache(_isolated_cache) -> Path:
    """The test session's geometry cache (``$MUSCLEMETAB_CACHE/geometry``), shared by every
    test that computes the example subject's geometry: each trial goes through OpenSim once."""
    from musclemetab.geometry import default_cache_dir

    return default_cache_dir()


@pytest.fixture(scope="session")
def gait2392_prepared(gait2392, tmp_path_factory):
    """``musclemetab prepare`` of OpenSim's gait2392 subject01 with OpenSim's scaling and IK setups,
    run on a copy of the inputs in a folder of their own from another working folder: ``(inputs,
    out)``. Scaling and IK go through OpenSim once per test run (the package's cache, shared by
    the test processes and tests/test_scale_ik.py)."""
    import warnings

    from musclemetab.commands import main
    from musclemetab.errors import MarkerErrorWarning

    root = tmp_path_factory.mktemp("prepare")
    inputs = root / "inputs"
    inputs.mkdir()
    for p in (gait2392.generic_model, gait2392.static, gait2392.markers, gait2392.scale_setup,
              gait2392.scale_marker_set, gait2392.ik_setup):
        shutil.copy(p, inputs)
    cwd = root / "cwd"
    cwd.mkdir()
    out = root / "out"
    old = os.getcwd()
    os.chdir(cwd)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MarkerErrorWarning)  # OpenSim's own setups exceed the limits
            status = main(["prepare", "--model", str(inputs / gait2392.generic_model.name),
                           "--static", str(inputs / gait2392.static.name), "--markers", str(inputs / gait2392.markers.name),
                           "--mass", "72.6", "--scale-setup", str(inputs / gait2392.scale_setup.name),
                           "--ik-setup", str(inputs / gait2392.ik_setup.name), "--out", str(out)])
    finally:
        os.chdir(old)
    assert status == 0
    return inputs, out


def _run_root(tmp_path_factory) -> Path:
    """A folder shared by every process of this test run (the parallel workers of
    pytest-xdist included): the parent of the workers' temporary folders."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(autouse=True, scope="session")
def _each_problem_solved_once(tmp_path_factory):
    """Each muscle redundancy problem is solved once per test run (see ``solve_memo``).

    The memo lives in the run's shared folder, so the parallel test workers, the study pool
    workers and the pools of ``solve --side both`` (their initialiser installs it) and Dask workers (``solve_memo.install_in_worker``)
    all use it.
    """
    import solve_memo

    import musclemetab.processes as processes

    undo = solve_memo.install(_run_root(tmp_path_factory) / "solve-memo")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(processes, "ignore_sigint", solve_memo.start_pool_worker)
        yield
    undo()
    os.environ.pop(solve_memo.MEMO_ENV, None)


@contextlib.contextmanager
def loopback_mirror(files: dict, root: Path):
    """Serve ``{path under the server root: local file}`` over HTTP on 127.0.0.1.

    Yields ``(root, base_url)``; the files are copied under ``root`` so a test may alter them.
    """
    for rel, source in files.items():
        target = root / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(source, target)
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(root))
    handler.log_message = lambda *a, **k: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield root, f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


@pytest.fixture()
def dataset_mirror(tmp_path):
    """``mirror(dataset, local_folder, commit)``: a loopback server laid out like the source
    repository at ``commit`` (files at ``<commit>/<path in the repository>``); returns
    ``(server root, base URL of the commit)``."""
    import musclemetab.datasets as ds

    with contextlib.ExitStack() as stack:
        def mirror(dataset: str, folder: Path, commit: str):
            files = {f"{commit}/{path}": Path(folder) / name for name, (_, path) in ds.manifest(dataset).items()}
            root, url = stack.enter_context(loopback_mirror(files, tmp_path / "www" / dataset))
            return root, f"{url}{commit}/"

        yield mirror


@pytest.fixture(autouse=True, scope="session")
def _isolated_cache(tmp_path_factory):
    """Keep the geometry cache of a test run out of the user's cache."""
    old = os.environ.get("MUSCLEMETAB_CACHE")
    cache = _run_root(tmp_path_factory) / "cache"  # shared by the parallel workers: each trial's geometry once
    cache.mkdir(exist_ok=True)
    os.environ["MUSCLEMETAB_CACHE"] = str(cache)
    yield
    if old is None:
        os.environ.pop("MUSCLEMETAB_CACHE", None)
    else:
        os.environ["MUSCLEMETAB_CACHE"] = old


#: the test modules that take longest (measured with ``--durations``), started first so that
#: the parallel processes of a run (pytest-xdist, ``--dist loadfile`` with
#: ``--no-loadscope-reorder``: modules handed out in this order, not by their number of tests)
#: finish together; ``test_demo.py`` makes the shared ``demo`` fixture at the start, while the
#: other process solves EMG-TEN, so that no module waits for it later; the other modules follow
#: in collection order
_LONGEST_FIRST = ("test_emg_ten.py", "test_demo.py", "test_benchmarks.py", "test_gait2392.py", "test_redundancy.py",
                  "test_estimate.py", "test_study.py", "test_uncertainty.py", "test_calibration.py",
                  "test_robustness_outputs.py", "test_report.py", "test_energy_goal.py", "test_prepare.py",
                  "test_emg_informed.py", "test_weights.py", "test_cli_flow.py", "test_diagnosis.py",
                  "test_opensim_files.py", "test_geometry.py", "test_study_emg_modes.py", "test_robustness_study.py",
                  "test_assistance.py", "test_report_browser.py", "test_trials.py", "test_api_docs.py",
                  "test_cold_start.py", "test_scale_ik.py", "test_robustness_lock.py", "test_metabolics_states.py",
                  "test_study_warm.py", "test_stop.py", "test_robustness_values.py", "test_figure_layout.py",
                  "test_sensitivity.py", "test_stage_paths.py")


def pytest_collection_modifyitems(config, items):
    """The longest test modules first (each module runs whole in one process)."""
    rank = {name: i for i, name in enumerate(_LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))

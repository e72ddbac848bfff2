"""Start-up of a solve: the on-disk cache of model parameters, no OpenSim when every cache
hits, and a command that imports only the stage it runs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from musclemetab import model as model_module
from musclemetab.model import default_dofs
from musclemetab.errors import CacheWarning, OpenSimWorkerError
from musclemetab.opensim_bridge import client


DOFS = default_dofs("r")


def _forbid_opensim(monkeypatch):
    """Make any start of the OpenSim worker fail, and stop a running one."""
    client.shutdown()

    def refuse():
        raise OpenSimWorkerError("the OpenSim worker was started although every cache entry exists")

    monkeypatch.setattr(client, "_start", refuse)


def test_model_parameters_from_disk_cache(example, tmp_path, monkeypatch):
    model_module._CACHE.clear()
    first = model_module.read_model(example.model, cache_dir=tmp_path)  # OpenSim in the worker
    entries = list(tmp_path.glob("model-*.npz"))
    assert len(entries) == 1
    assert not model_module.model_is_cached(example.model, tmp_path)  # the layout is not cached yet
    from musclemetab.layout import read_layout

    read_layout(example.model, cache_dir=tmp_path)
    assert model_module.model_is_cached(example.model, tmp_path)

    model_module._CACHE.clear()  # a new process: nothing in memory
    _forbid_opensim(monkeypatch)
    again = model_module.read_model(example.model, cache_dir=tmp_path)
    assert again.muscles.names == first.muscles.names
    for f in model_module._ARRAY_FIELDS:
        np.testing.assert_array_equal(getattr(again.muscles, f), getattr(first.muscles, f))
    assert again.body_mass_kg == first.body_mass_kg == pytest.approx(72.6, abs=1e-9)
    assert again.coordinates == first.coordinates and again.couplers == first.couplers

    # the key is the content: a copy under another name hits the same entry
    copy = tmp_path / "renamed.osim"
    copy.write_bytes(example.model.read_bytes())
    assert model_module.read_model(copy, cache_dir=tmp_path).muscles.names == first.muscles.names
    model_module._CACHE.clear()


def test_unreadable_model_cache_entry_is_recomputed(example, tmp_path):
    model_module._CACHE.clear()
    first = model_module.read_model(example.model, cache_dir=tmp_path)
    (entry,) = tmp_path.glob("model-*.npz")
    entry.write_bytes(b"not an npz file")
    model_module._CACHE.clear()
    with pytest.warns(CacheWarning, match=f"{entry.name} cannot be read"):
        again = model_module.read_model(example.model, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.muscles.max_isometric_force_N, first.muscles.max_isometric_force_N)
    assert np.load(entry)["result"].size == 1  # rewritten, readable again
    model_module._CACHE.clear()


def test_solve_without_opensim_when_cached(example, tmp_path, monkeypatch):
    """Geometry and model parameters cached: the solve runs with OpenSim unavailable."""
    from musclemetab.geometry import compute_geometry, geometry_is_cached
    from musclemetab.layout import read_layout
    from musclemetab.redundancy import SolverOptions, solve_files

    ik, idf = example.ik["normal"], example.id["normal"]
    assert not geometry_is_cached(example.model, ik, DOFS, cache_dir=tmp_path)
    model_module._CACHE.clear()
    geom = compute_geometry(example.model, ik, cache_dir=tmp_path)
    model_module.read_model(example.model, cache_dir=tmp_path)
    layout = read_layout(example.model, cache_dir=tmp_path)
    assert geometry_is_cached(example.model, ik, DOFS, cache_dir=tmp_path)
    assert model_module.model_is_cached(example.model, tmp_path)

    model_module._CACHE.clear()
    _forbid_opensim(monkeypatch)
    sol = solve_files(example.model, ik, idf, "effort-gen", cache_dir=tmp_path,
                      options=SolverOptions(max_iter=2))
    assert sol.summary["iterations"] == 2
    assert sol.muscles == geom.muscles
    again = read_layout(example.model, cache_dir=tmp_path)  # from the cache, OpenSim refused
    assert again.coordinates == layout.coordinates and again.joints == layout.joints
    model_module._CACHE.clear()


def test_command_imports_only_its_stage():
    code = (
        "import sys; from musclemetab.commands import build_parser; p = build_parser('solve'); "
        "p.parse_args(['solve', '--model', 'm', '--ik', 'i', '--id', 'd', '--out', 'o']); "
        "print(sorted(m for m in ('musclemetab.study', 'musclemetab.report', 'musclemetab.metabolics', "
        "'musclemetab.redundancy.emg_ten', 'scipy.signal', 'scipy.interpolate', 'scipy.optimize', 'scipy.stats', "
        "'pandas', 'casadi', 'opensim') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    # the full parser still offers every command
    from musclemetab.commands import build_parser

    help_text = build_parser().format_help()
    for name in ("geometry", "solve", "metabolics", "calibrate-passive", "run", "demo", "report"):
        assert name in help_text


def test_solve_command_imports_scipy_when_it_filters(example, geometry_cache, tmp_path):
    """Importing the solver imports no SciPy; a whole `musclemetab solve` (caches filled, two
    IPOPT iterations, folder written) in a new process imports SciPy's signal (the low-pass
    filter), interpolate (the mesh splines) and optimize (the static optimisation) when it
    prepares the trial, and no pandas: the files are read and written as NumPy tables
    (musclemetab.io.read_table) and the package's muscle table, which the diagnosis before the
    solve reads, with the csv module."""
    import json

    from musclemetab.geometry import compute_geometry
    from musclemetab.layout import read_layout

    ik, idf = example.ik["normal"], example.id["normal"]
    compute_geometry(example.model, ik, cache_dir=geometry_cache)
    model_module.read_model(example.model, cache_dir=geometry_cache)
    read_layout(example.model, cache_dir=geometry_cache)
    out = tmp_path / "out"
    argv = ["solve", "--model", str(example.model), "--ik", str(ik), "--id", str(idf), "--out", str(out),
            "--cache-dir", str(geometry_cache), "--max-iter", "2"]
    watched = ("scipy.signal", "scipy.interpolate", "scipy.optimize", "pandas", "casadi")
    code = (
        "import sys; import musclemetab.redundancy, musclemetab.redundancy.inputs, musclemetab.redundancy.static_opt; "
        f"print(sorted(m for m in {watched!r} if m in sys.modules)); "
        f"from musclemetab.commands import main; rc = main({argv!r}); "
        f"print(rc); print(sorted(m for m in {watched!r} if m in sys.modules))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    lines = proc.stdout.strip().splitlines()
    assert proc.returncode == 0, proc.stderr
    assert lines[-3] == "[]"  # the solver's modules import SciPy only inside the functions that need it
    # two iterations do not converge: the command reports it (non-zero) after writing the folder
    assert lines[-2] != "0" and "did not converge" in proc.stderr
    assert json.loads((out / "summary.json").read_text())["iterations"] == 2
    assert lines[-1] == "['casadi', 'scipy.interpolate', 'scipy.optimize', 'scipy.signal']"


def test_work_sent_ahead_leaves_each_reply_to_its_caller(tmp_path):
    """``call_in_background`` (the solution's model prepared while IPOPT solves): its failure is
    ignored, and the calls after it get their own replies, in order."""
    from musclemetab.errors import ModelError
    from musclemetab.opensim_bridge import call, call_in_background

    missing = str(tmp_path / "no_model.osim")
    args = ({"soleus_r": {}}, [0.0, 1.0], {"ankle_angle_r": [0.0, 0.0]}, False, [0.0, 1.0], ["ankle_angle_r"])
    call_in_background("solution_model:prepare_solution_model", missing, *args)
    before = call("solution_model:prepared_models")  # the list, not the background call's error
    assert isinstance(before, list)
    with pytest.raises(ModelError, match="no_model.osim: no such model file"):  # the same work, asked for
        call("solution_model:solution_model", missing, str(tmp_path / "m.osim"), *args)
    assert call("solution_model:prepared_models") == before  # nothing kept of the failures


def _small_structure(**goals):
    from musclemetab.redundancy.goals import Goals
    from musclemetab.redundancy.transcription import GroupStructure

    return GroupStructure(n_muscles=3, n_dofs=2, emg_index=(), fiber_index=(),
                          goals=Goals(fiber_dynamics="forward", **goals), optimal_reserve_Nm=150.0, factor_of=(),
                          emg_factor=(), n_full=0, p_index=(), zero_r=())


def _assert_same_functions(a: dict, b: dict):
    """Equal names, and bit-identical outputs at random inputs (the same operations in the same order)."""
    rng = np.random.default_rng(7)
    assert sorted(a) == sorted(b)
    for name in a:
        ins = [rng.uniform(0.2, 1.2, a[name].size_in(i)) for i in range(a[name].n_in())]
        out_a, out_b = a[name].call(ins), b[name].call(ins)
        assert len(out_a) == len(out_b) > 0
        for x, y in zip(out_a, out_b):
            assert x.sparsity() == y.sparsity()
            np.testing.assert_array_equal(np.asarray(x.nonzeros()), np.asarray(y.nonzeros()))


def test_group_functions_are_read_back_from_the_cache_unchanged(tmp_path, monkeypatch):
    """A new process reads a group's functions from the package cache instead of building them:
    the same functions; another structure, CasADi or package code is another entry; a damaged
    entry is deleted with a warning and built again."""
    from musclemetab.redundancy import function_cache
    from musclemetab.redundancy.transcription import _group_functions

    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(tmp_path))
    st = _small_structure()
    builds = []

    def build(structure=st):
        builds.append(structure)
        return _group_functions(structure)

    built = function_cache.cached_functions("group functions", st, build)
    (entry,) = (tmp_path / "functions").glob("functions-*.npz")
    read = function_cache.cached_functions("group functions", st, build)
    assert len(builds) == 1  # the second came from the entry
    _assert_same_functions(built, read)

    other = _small_structure(w_velocity=0.02)  # another structure: built, its own entry
    function_cache.cached_functions("group functions", other, lambda: build(other))
    assert len(builds) == 2 and len(list((tmp_path / "functions").glob("*.npz"))) == 2

    monkeypatch.setattr(function_cache, "code_digest", lambda: "another version of the package")
    function_cache.cached_functions("group functions", st, build)
    assert len(builds) == 3 and len(list((tmp_path / "functions").glob("*.npz"))) == 3
    monkeypatch.undo()
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(tmp_path))

    entry.write_bytes(entry.read_bytes()[:1000])  # cut short
    with pytest.warns(CacheWarning, match=f"{entry.name} cannot be read"):
        again = function_cache.cached_functions("group functions", st, build)
    assert len(builds) == 4
    _assert_same_functions(built, again)
    _assert_same_functions(built, function_cache.cached_functions("group functions", st, build))  # rewritten
    assert len(builds) == 4


def test_code_digest_is_the_package_source():
    """The key's code part: SHA-256 over every module's path and bytes, worked here independently."""
    import hashlib
    from pathlib import Path

    import musclemetab
    from musclemetab.redundancy.function_cache import code_digest

    root = Path(musclemetab.__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    assert code_digest() == h.hexdigest()


def test_shutdown_kills_a_worker_that_does_not_end_when_its_input_closes(monkeypatch):
    """The exit functions stop the OpenSim worker by closing its input (an idle worker ends at
    once); a process that goes on (here one that never reads its input) is killed after
    ``SHUTDOWN_WAIT_S``, so that a command's exit, after Ctrl-C too, is never held up by it."""
    client.shutdown()
    busy = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE)
    monkeypatch.setattr(client, "_PROC", busy)
    try:
        client.shutdown()
        assert busy.poll() == -9  # SIGKILL, not the end of its 60 s
        assert client._PROC is None
    finally:
        if busy.poll() is None:
            busy.kill()


def test_shutdown_lets_an_idle_worker_end_by_itself(monkeypatch):
    """A process that ends when its input closes (as the idle worker does) is not killed."""
    client.shutdown()
    idle = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE)
    monkeypatch.setattr(client, "_PROC", idle)
    client.shutdown()
    assert idle.returncode == 0

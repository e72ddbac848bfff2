"""Reliability of the command line and its outputs: numeric settings declared once (the study
file's table) for ``solve`` and ``estimate``, options that override each other, couplings,
run-time libraries never named by a study file and loaded only after their symbols are read,
resource bounds, outputs (a user's folder never deleted, a lock on ``solve --out``, write
errors as one line), and Ctrl-C.

Each refusal is one line naming the option, key, path or muscle; a decoy file beside the
output folder shows that nothing is written outside it."""

from __future__ import annotations

import errno
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from musclemetab.commands import build_parser, main
from musclemetab.errors import OptionError, OutputError
from musclemetab.io.atomic import FILES_MANIFEST, FolderLock, atomic_directory, written_files
from musclemetab.study.spec import NUMBER_KEYS, study_from_dict

TESTS = Path(__file__).resolve().parent
DECOY_TEXT = "a file of the user beside the output folder\n"


@pytest.fixture()
def decoy(tmp_path):
    """A file beside the output folders of a test; it must stay as it is."""
    path = tmp_path / "decoy.txt"
    path.write_text(DECOY_TEXT)
    yield path
    assert path.read_text() == DECOY_TEXT
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # no temporary left beside


def _files(example, trial="normal"):
    return ["--model", str(example.model), "--ik", str(example.ik[trial]), "--id", str(example.id[trial])]


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("musclemetab: error: "), err
    return err


def _previous_output(folder: Path, files: dict[str, str]) -> dict[Path, str]:
    """``files`` (name -> text) written into ``folder`` as the package writes its outputs (listed
    in ``.musclemetab-files``), as a previous run would have left them; ``{path: text}``."""
    with atomic_directory(folder, mark=True) as tmp:
        for name, text in files.items():
            (tmp / name).write_text(text)
    return {folder / name: text for name, text in files.items()}


# ----------------------------------------------------------------------------------------------
# 1. numeric settings: one table for the study file and the command line

#: (command, option, key, a value the table refuses)
REFUSED = [
    ("solve", "--mesh-frequency", "mesh_frequency_hz", "0"),
    ("solve", "--mesh-frequency", "mesh_frequency_hz", "5000"),
    ("solve", "--max-iter", "max_iter", "0"),
    ("solve", "--max-iter", "max_iter", "1000000"),
    ("solve", "--print-level", "print_level", "13"),
    ("solve", "--grf-threshold", "grf_threshold_N", "-5"),
    ("solve", "--emg-tolerance", "emg_tolerance", "2"),
    ("solve", "--emg-weight", "emg_weight", "-1"),
    ("solve", "--energy-weight", "weight", "nan"),
    ("solve", "--effort-weight", "effort_weight", "-1"),
    ("solve", "--energy-smoothing", "smoothing", "0"),
    ("solve", "--mass", "body_mass_kg", "72600"),
    ("solve", "--height", "height_m", "174.3"),
    ("solve", "--workers", "workers", "0"),
    ("estimate", "--max-iter", "max_iter", "0"),
    ("estimate", "--emg-tolerance", "emg_tolerance", "-0.5"),
]


@pytest.mark.parametrize("command, option, key, value", REFUSED)
def test_command_line_numbers_are_checked_by_the_study_files_table(tmp_path, capsys, decoy, command, option, key,
                                                                   value):
    out = tmp_path / "out"
    args = [command, "--model", str(tmp_path / "no_model.osim"), "--ik", "ik.mot", "--id", "id.sto", option, value,
            "--out", str(out)]
    if command == "estimate":
        args += ["--estimate", "tendon_stiffness=soleus_r"]
    assert main(args) == 1
    err = _one_line_error(capsys)
    assert f"{option} = " in err and NUMBER_KEYS[key].range_text() in err, err
    assert "no_model.osim" not in err  # refused before any file is read
    assert not out.exists()


@pytest.mark.parametrize("option, key, where, value", [
    ("--grf-threshold", "grf_threshold_N", "trial", -5.0),
    ("--emg-tolerance", "emg_tolerance", "subject", 2.0),
    ("--max-iter", "max_iter", "solver", 0),
])
def test_study_file_and_command_line_refuse_the_same_value_with_the_same_range(example, tmp_path, capsys, option, key,
                                                                               where, value):
    data = {"workflows": ["effort-gen"], "models": ["UM10"],
            "subjects": [{"name": "s", "model": str(example.model), "body_mass_kg": 72.6, "height_m": 1.743,
                          "trials": [{"name": "normal", "ik": str(example.ik["normal"]),
                                      "id": str(example.id["normal"])}]}]}
    if where == "trial":
        data["subjects"][0]["trials"][0][key] = value
    elif where == "subject":
        data["subjects"][0].update(emg_mode="constrained", emg_tolerance=value)
        data["subjects"][0]["trials"][0]["emg"] = str(example.emg["normal"])
    else:
        data["solver"] = {key: value}
    with pytest.raises(OptionError) as info:
        study_from_dict(data, base="/", output=tmp_path / "study")
    assert main(["solve", *_files(example), option, str(value), "--out", str(tmp_path / "out")]) == 1
    err = _one_line_error(capsys)
    expected = NUMBER_KEYS[key].range_text()
    assert expected in str(info.value) and expected in err
    assert f"'{key}' = " in str(info.value) and f"{option} = " in err


@pytest.mark.parametrize("command", ["solve", "estimate"])
def test_every_numeric_option_is_declared_in_the_table(command):
    """Every option of ``solve`` and ``estimate`` that takes a number goes through the table
    (:func:`musclemetab.commands.options.number_option`), and its help shows the range."""
    parser = build_parser(command)
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    declared = sub.get_default("number_options")
    numeric = {a.dest: a for a in sub._actions if a.type in (int, float)}
    assert numeric and set(numeric) == set(declared)
    for dest, (option, key) in declared.items():
        assert option in numeric[dest].option_strings
        assert NUMBER_KEYS[key].range_text() in numeric[dest].help


@pytest.mark.parametrize("extra, named", [
    (["--grf", "GRF.mot", "--external-loads", "GRF.xml"], ("--grf", "--external-loads")),
    (["--tendon-stiffness", "soleus_r=10", "--parameters", "p.json"], ("--tendon-stiffness", "--parameters")),
    (["--window", "0.5:1.0", "--cycle", "auto"], ("--window", "--cycle")),
])
def test_options_that_override_each_other_are_refused_together(tmp_path, capsys, decoy, extra, named):
    out = tmp_path / "out"
    assert main(["solve", "--model", "m.osim", "--ik", "ik.mot", "--id", "id.sto", *extra, "--out", str(out)]) == 1
    err = _one_line_error(capsys)
    assert f"{named[0]} and {named[1]} cannot be used together" in err
    assert not out.exists()


@pytest.mark.parametrize("extra, words", [
    (["--dofs", "knee_angle_x"], ["--dofs", "knee_angle_x", "knee_angle_r"]),
    (["--exclude-muscles", "soleus_x"], ["--exclude-muscles", "soleus_x"]),
])
def test_names_that_match_nothing_are_errors(example, tmp_path, capsys, decoy, extra, words):
    out = tmp_path / "out"
    assert main(["solve", *_files(example), *extra, "--out", str(out)]) == 1
    err = _one_line_error(capsys)
    assert all(w in err for w in words), err
    assert not out.exists()


def test_a_force_column_that_is_not_in_the_file_is_an_error(gait2392, tmp_path, capsys, decoy):
    out = tmp_path / "out"
    assert main(["solve", "--model", str(gait2392.model), "--ik", str(gait2392.ik), "--id", str(gait2392.id),
                 "--grf", str(gait2392.grf), "--grf-column", "ground_force_vz_typo", "--cycle", "auto",
                 "--out", str(out)]) == 1
    err = _one_line_error(capsys)
    assert "missing vertical force column ground_force_vz_typo" in err and "near names: " in err, err
    assert str(gait2392.grf) in err and not out.exists()


# ----------------------------------------------------------------------------------------------
# 6. couplings

@pytest.mark.parametrize("estimate, couple, words", [
    (["tendon_stiffness=soleus_r"], ["soleus_r,gasmed_x"], ["gasmed_x is estimated for no kind", "--estimate"]),
    (["tendon_stiffness=soleus_r,gasmed_r", "optimal_fiber_length=soleus_r"], ["soleus_r,gasmed_r"],
     ["estimated for the same kinds", "soleus_r: optimal_fiber_length, tendon_stiffness", "gasmed_r: tendon_stiffness"]),
    (["tendon_stiffness=soleus_r"], ["soleus_r"], ["two or more muscles"]),
])
def test_couplings_must_name_muscles_estimated_alike(example, tmp_path, capsys, decoy, estimate, couple, words):
    out = tmp_path / "out"
    code = main(["estimate", *_files(example), "--ultrasound", str(tmp_path / "us.mot"), "--estimate", *estimate,
                 "--couple", *couple, "--out", str(out)])
    err = _one_line_error(capsys)
    assert code == 1 and f"--couple {couple[0]}" in err and all(w in err for w in words), err
    assert not out.exists()


# ----------------------------------------------------------------------------------------------
# 2. no native code from data

DECOY_SOURCE = textwrap.dedent("""\
    #include <stdio.h>
    #include <stdlib.h>
    __attribute__((constructor)) static void loaded(void) {
        const char *path = getenv("MUSCLEMETAB_TEST_DECOY");
        FILE *f = path ? fopen(path, "w") : NULL;
        if (f) { fputs("the decoy library was loaded", f); fclose(f); }
    }
    int ma27_lookalike(void) { return 0; }
    """)


@pytest.fixture()
def decoy_library(tmp_path, monkeypatch):
    """``(library, witness)``: a shared library whose constructor writes ``witness`` when it is
    loaded (built with ``cc``; without a compiler, a file named like one), and ``ctypes.CDLL``
    watched: the test fails if anything loads it."""
    import ctypes

    lib, witness = tmp_path / "libdecoy.so", tmp_path / "decoy_was_loaded"
    source = tmp_path / "decoy.c"
    source.write_text(DECOY_SOURCE)
    if shutil.which("cc"):
        subprocess.run(["cc", "-shared", "-fPIC", "-o", str(lib), str(source)], check=True)
    else:
        lib.write_bytes(b"\x7fELF not a library")
    monkeypatch.setenv("MUSCLEMETAB_TEST_DECOY", str(witness))
    loads = []
    real = ctypes.CDLL

    def watched(name, *args, **kwargs):
        if Path(str(name)).name == lib.name:
            loads.append(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(ctypes, "CDLL", watched)
    yield lib, witness
    assert loads == [] and not witness.exists()


def test_a_study_file_naming_a_library_is_refused_before_anything_is_loaded(example, tmp_path, capsys,
                                                                            decoy_library):
    lib, _ = decoy_library
    toml = tmp_path / "study.toml"
    toml.write_text(f'output = "out"\nworkflows = ["effort-gen"]\nmodels = ["UM10"]\n'
                    f'[solver]\nlinear_solver = "ma27"\nlinear_solver_library = "{lib}"\n'
                    f'[[subjects]]\nname = "s"\nmodel = "{tmp_path / "not_read.osim"}"\nbody_mass_kg = 72.6\n'
                    f'height_m = 1.743\n[[subjects.trials]]\nname = "t"\nik = "ik.mot"\nid = "id.sto"\n')
    assert main(["run", str(toml), "--no-progress"]) == 1
    err = _one_line_error(capsys)
    assert "[solver] linear_solver_library" in err and "not a library" in err
    assert "MUSCLEMETAB_LINEAR_SOLVER_LIBRARY" in err and "not_read.osim" not in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("given", ["option", "environment"])
def test_a_library_without_the_solvers_symbols_is_not_loaded(tmp_path, capsys, monkeypatch, decoy_library, given):
    lib, _ = decoy_library
    extra = ["--linear-solver-library", str(lib)] if given == "option" else []
    if given == "environment":
        monkeypatch.setenv("MUSCLEMETAB_LINEAR_SOLVER_LIBRARY", str(lib))
    out = tmp_path / "out"
    assert main(["solve", "--model", "m.osim", "--ik", "ik.mot", "--id", "id.sto", "--linear-solver", "ma27", *extra,
                 "--out", str(out)]) == 1
    err = _one_line_error(capsys)
    assert str(lib) in err and "ma27" in err
    if shutil.which("cc"):
        assert "does not export ma27ad_, ma27bd_, ma27cd_" in err and "was not loaded" in err
    assert not out.exists()


def test_the_symbol_reader_reads_a_real_library():
    """The dynamic symbols of the C library as Python's ctypes finds them: functions every
    libc exports, and no undefined import among them."""
    import ctypes.util

    from musclemetab.redundancy.linear_solvers import _find_library, exported_symbols

    libc = _find_library(ctypes.util.find_library("c"))
    symbols = exported_symbols(libc)
    assert {"malloc", "free", "printf", "fopen"} <= symbols
    assert all(hasattr(ctypes.CDLL(libc), name) for name in ("malloc", "fopen"))
    with pytest.raises(ValueError, match="not an ELF file"):
        exported_symbols(__file__)


def test_an_ipopt_status_of_a_failed_library_load_is_reported_as_such():
    """IPOPT ends with ``Invalid_Option`` when it cannot load the linear solver's library (CasADi 3.6,
    ``linear_solver=ma27, hsllib=/nonexistent``): the advice says so, not 'check the inputs'."""
    from musclemetab.redundancy.ipopt import failure_advice

    advice = failure_advice("Invalid_Option")
    assert "could not load the linear solver's library" in advice and "MUSCLEMETAB_LINEAR_SOLVER_LIBRARY" in advice


# ----------------------------------------------------------------------------------------------
# 3. resource bounds

def test_problem_memory_estimate_and_limit():
    from musclemetab.redundancy.ipopt import MAX_PROBLEM_MEMORY_MB, check_problem_memory, problem_memory_mb

    assert problem_memory_mb([(40, 5, 118)]) == pytest.approx(73 + 0.47 * 118, rel=1e-12)  # the measured problem
    assert problem_memory_mb([(20, 5, 100), (20, 5, 100)]) == pytest.approx(73 + 0.47 * 200 * 105 / 205, rel=1e-12)
    check_problem_memory([(40, 5, 1200)])  # a 1.2 s cycle at the finest mesh (1000 per s) is built
    n = int((MAX_PROBLEM_MEMORY_MB - 73) / 0.47) + 1
    with pytest.raises(OptionError, match=rf"{n} mesh intervals and need about 8000 MB .* limit of 8000 MB; .*--mesh-frequency"):
        check_problem_memory([(40, 5, n)])


def test_a_problem_past_the_memory_limit_is_refused_before_it_is_built(example, tmp_path, capsys, monkeypatch,
                                                                       decoy):
    """0.3 s of the normal trial at 1000 intervals per second (N = 300, 73 + 0.47 x 300 = 214 MB
    by the estimate) against a limit lowered to 200 MB: refused with the estimate before the
    problem is built, nothing written."""
    import musclemetab.redundancy.ipopt as ipopt
    import musclemetab.redundancy.resources as resources

    monkeypatch.setattr(resources, "MAX_PROBLEM_MEMORY_MB", 200.0)
    built = []
    monkeypatch.setattr(ipopt, "build_problem", lambda *a, **k: built.append(1))
    out = tmp_path / "out"
    assert main(["solve", *_files(example), "--window", "0.6:0.9", "--mesh-frequency", "1000", "--out",
                 str(out)]) == 1
    err = _one_line_error(capsys)
    assert "300 mesh intervals and need about 214 MB of memory, more than the limit of 200 MB" in err, err
    assert built == [] and not out.exists()


# ----------------------------------------------------------------------------------------------
# 4. outputs

@pytest.mark.parametrize("name", ["summary.json", "solution.sto"])
def test_a_user_folder_where_solve_writes_a_file_is_never_deleted(example, tmp_path, capsys, decoy, name):
    out = tmp_path / "out"
    (out / name).mkdir(parents=True)
    (out / name / "notes.txt").write_text("mine")
    assert main(["solve", *_files(example), "--out", str(out)]) == 1
    err = _one_line_error(capsys)
    assert f"{out / name} is a folder" in err and "not removed" in err
    assert (out / name / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir()) == [name]  # no lock, no temporary folder left


def test_atomic_directory_refuses_to_replace_a_folder_before_moving_anything(tmp_path, decoy):
    out = tmp_path / "out"
    (out / "b.txt").mkdir(parents=True)
    (out / "b.txt" / "keep").write_text("mine")
    (out / "a.txt").write_text("old")
    with pytest.raises(OptionError, match=r"b\.txt is a folder.*not removed"):
        with atomic_directory(out) as tmp:
            (tmp / "a.txt").write_text("new")
            (tmp / "b.txt").write_text("new")
    assert (out / "a.txt").read_text() == "old" and (out / "b.txt" / "keep").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir()) == ["a.txt", "b.txt"]


@pytest.mark.parametrize("code, words", [
    (errno.ENOSPC, "the disk is full"),
    (errno.EROFS, "the file system is read-only"),
    (errno.EACCES, "permission denied"),
    (errno.EFBIG, "a file would exceed the file-size limit (ulimit -f)"),
])
@pytest.mark.parametrize("when", ["writing", "moving"])
def test_write_errors_are_one_line_naming_the_folder(tmp_path, monkeypatch, decoy, code, words, when):
    """A full disk, a folder made read-only mid-run, a file-size limit: raised while the files
    are written (into the temporary folder) or moved into place; the old files stay."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.txt").write_text("old")
    if when == "moving":
        def failing_replace(src, dst):
            raise OSError(code, os.strerror(code), str(dst))

        monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OutputError) as info:
        with atomic_directory(out) as tmp:
            (tmp / "a.txt").write_text("new")
            if when == "writing":
                raise OSError(code, os.strerror(code), str(tmp / "b.txt"))
    message = str(info.value)
    assert f"cannot write the output folder {out} ({words});" in message and "\n" not in message
    assert (out / "a.txt").read_text() == "old" and sorted(p.name for p in out.iterdir()) == ["a.txt"]


_CHILD = textwrap.dedent("""\
    import resource, sys
    sys.path.insert(0, {tests!r})
    import solve_memo
    import musclemetab.redundancy.run as run
    solve_memo.install({memo!r})  # the solve of the test run (stored with no limit)
    write = run.write_solution_folder

    def limited(*args, **kwargs):  # the limit from the writing of the output on
        resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
        return write(*args, **kwargs)

    run.write_solution_folder = limited
    from musclemetab.commands import main
    sys.exit(main({args!r}))
    """)


def test_a_file_size_limit_is_one_line_with_the_previous_output_kept(example, tmp_path, decoy):
    """``solve`` under ``ulimit -f`` (RLIMIT_FSIZE, 64 kB; solution.sto is about 650 kB) in its
    own process: exit 1 with one line naming the folder (before: a traceback ending in
    ``OSError: [Errno 27] File too large``), the previous output as it was, no lock, no
    temporary folder."""
    out = tmp_path / "out"
    previous = {"solution.sto": "previous solution\n", "summary.json": '{"previous": true}\n'}
    _previous_output(out, previous)
    listed = (out / FILES_MANIFEST).read_text()
    memo = os.environ.get("MUSCLEMETAB_TEST_SOLVE_MEMO", str(tmp_path / "memo"))
    code = _CHILD.format(tests=str(TESTS), memo=memo, limit=64 * 1024,
                         args=["solve", *_files(example), "--out", str(out)])
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 1, proc.stderr
    assert err[-1] == (f"musclemetab: error: cannot write the output folder {out} (a file would exceed the file-size "
                       "limit (ulimit -f)); the files of this step were not written (the folder keeps what it held): "
                       "free space or choose a folder you can write to, and run again")
    assert {p.name: p.read_text() for p in out.iterdir()} == {**previous, FILES_MANIFEST: listed}


@pytest.mark.parametrize("command", ["solve", "estimate"])
def test_a_second_run_on_the_same_output_folder_refuses(example, tmp_path, capsys, decoy, command):
    """Another process holds ``--out`` (as a running ``solve`` or ``estimate`` does): the command
    refuses, naming the lock and the process, before it reads any input, and leaves the lock and
    the folder as they were."""
    out = tmp_path / "out"
    extra = ["--estimate", "tendon_stiffness=soleus_r", "--ultrasound", str(tmp_path / "not_read.mot")] \
        if command == "estimate" else []
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom musclemetab.io.atomic import FolderLock\n"
         f"with FolderLock({str(out)!r}, 'output folder'):\n    print('held', flush=True)\n    sys.stdin.read()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        lock = json.loads((out / ".musclemetab.lock").read_text())
        assert main([command, *_files(example), *extra, "--out", str(out)]) == 1
        err = _one_line_error(capsys)
        assert f"the output folder {out} is in use by another musclemetab run (process {holder.pid}" in err
        assert f"lock file {out / '.musclemetab.lock'}" in err and "not_read.mot" not in err
        assert json.loads((out / ".musclemetab.lock").read_text()) == lock
    finally:
        holder.communicate("", timeout=30)
    assert holder.returncode == 0 and not out.exists()  # the holder made the folder and left it empty


def test_the_lock_of_solve_is_released_and_an_empty_folder_removed_on_an_error(tmp_path, capsys, decoy):
    out = tmp_path / "new" / "out"
    assert main(["solve", "--model", str(tmp_path / "no_model.osim"), "--ik", "ik.mot", "--id", "id.sto",
                 "--out", str(out)]) == 1
    assert "no_model.osim" in _one_line_error(capsys)
    assert not (tmp_path / "new").exists()
    (tmp_path / "kept").mkdir()
    with FolderLock(tmp_path / "kept") as lock:  # a folder that existed stays, empty
        assert lock.path.is_file()
    assert list((tmp_path / "kept").iterdir()) == []


def test_the_list_of_written_files_is_what_sha256sum_checks_and_survives_a_failed_move(tmp_path, monkeypatch):
    """``.musclemetab-files`` lists each file the package placed with its SHA-256 in the format of
    ``sha256sum`` (checked by that program, or by hashlib without it). A move that fails half-way
    leaves the old file, which the list still knows (old and new SHA-256 both listed), so the next
    run replaces it."""
    import hashlib

    out = tmp_path / "out"
    _previous_output(out, {"a.txt": "old a\n", "b.txt": "old b\n"})
    with atomic_directory(out, mark=True) as tmp:  # the package's own files: replaced, listed anew
        (tmp / "a.txt").write_text("new a\n")
    if shutil.which("sha256sum"):
        check = subprocess.run(["sha256sum", "--check", "--strict", FILES_MANIFEST], cwd=out, capture_output=True,
                               text=True)
        assert check.returncode == 0 and check.stdout.splitlines() == ["a.txt: OK", "b.txt: OK"], check
    listed = written_files(out)
    assert listed == {n: {hashlib.sha256((out / n).read_bytes()).hexdigest()} for n in ("a.txt", "b.txt")}
    real = os.replace

    def failing(src, dst):
        if Path(dst).name == "a.txt":
            raise OSError(errno.EIO, os.strerror(errno.EIO), str(dst))
        return real(src, dst)

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(OutputError):
        with atomic_directory(out, mark=True) as tmp:
            (tmp / "a.txt").write_text("newer a\n")
    monkeypatch.setattr(os, "replace", real)
    assert (out / "a.txt").read_text() == "new a\n" and len(written_files(out)["a.txt"]) == 2
    with atomic_directory(out, mark=True) as tmp:
        (tmp / "a.txt").write_text("newest a\n")
    assert written_files(out)["a.txt"] == {hashlib.sha256(b"newest a\n").hexdigest()}


def _demo_unit(demo) -> Path:
    """A solved unit folder of the demo study (solution, metabolics and analysis files)."""
    return next(p.parent for p in sorted((demo[0] / "units").rglob("summary.json")))


DEMO_STUDY_FILE = "study.toml"  # what ``musclemetab demo`` writes into its folder (``output = "."``)


def _demo_copy(demo, tmp_path) -> Path:
    """A copy of the demo's study folder (its units complete: run again, none is solved)."""
    study = tmp_path / "study"
    shutil.copytree(demo[0], study)
    return study


def _user_file_case(case, example, demo, tmp_path):
    """``(command line, the file in the way, the words of the refusal)`` of one command of
    :func:`test_a_file_the_package_did_not_write_is_never_replaced`."""
    out = tmp_path / "out"
    not_ours = "was not written by musclemetab ({} has no .musclemetab-files"
    if case == "solve":
        return ["solve", *_files(example), "--out", str(out)], out / "solution.sto", not_ours.format(out)
    if case == "solve --side both":
        _previous_output(out / "l", {"summary.json": "{}\n"})  # a folder of the package, listed
        return (["solve", *_files(example), "--side", "both", "--cycle", "auto", "--out", str(out)],
                out / "l" / "states.sto", f"was not written by musclemetab (not listed in {out / 'l' / FILES_MANIFEST})")
    if case == "solve --workflow emg-ten":
        return (["solve", "--workflow", "emg-ten", *_files(example), "--emg", str(example.emg["normal"]),
                 "--labels", "normal", "--out", str(out)], out / "normal" / "summary.json",
                not_ours.format(out / "normal"))
    if case == "estimate":
        _previous_output(out, {"parameters.json": "{}\n"})
        return (["estimate", *_files(example), "--ultrasound", str(tmp_path / "not_read.mot"), "--estimate",
                 "tendon_stiffness=soleus_r", "--out", str(out)], out / "parameters.json",
                "was changed since musclemetab wrote it")
    if case == "geometry":
        return (["geometry", "--model", str(tmp_path / "not_read.osim"), "--ik", str(tmp_path / "not_read.mot"),
                 "--out", str(out)], out / "muscle_tendon_lengths.sto", not_ours.format(out))
    if case == "calibrate-passive --side both":
        _previous_output(out, {"fit.json": "{}\n"})  # a folder of the package, listed
        return (["calibrate-passive", "--model", str(tmp_path / "not_read.osim"), "--trials",
                 str(tmp_path / "not_read"), "--side", "both", "--out", str(out)], out / "passive_parameters.csv",
                f"was not written by musclemetab (not listed in {out / FILES_MANIFEST})")
    if case == "calibrate-passive":
        return (["calibrate-passive", "--model", str(tmp_path / "not_read.osim"), "--trials",
                 str(tmp_path / "not_read"), "--out", str(out)], out / "fit.json", not_ours.format(out))
    if case == "run (the study's root)":
        study = _demo_copy(demo, tmp_path)
        return (["run", str(study / DEMO_STUDY_FILE), "--no-progress"], study / "failures.csv",
                "was changed since musclemetab wrote it")
    unit = _demo_unit(demo)
    if case == "metabolics --sensitivity":
        return (["metabolics", "--solution", str(unit), "--model", str(example.model), "--mass", "72.6",
                 "--sensitivity", "--out", str(out)], out / "sensitivity.csv", not_ours.format(out))
    if case == "analyse (analyse.json)":
        return ["analyse", "--solution", str(unit), "--out", str(out)], out / "analyse.json", not_ours.format(out)
    if case == "metabolics":
        return (["metabolics", "--solution", str(unit), "--model", str(example.model), "--mass", "72.6",
                 "--out", str(out)], out / "per_muscle.csv", not_ours.format(out))
    if case == "analyse":
        return ["analyse", "--solution", str(unit), "--out", str(out)], out / "analysis.csv", not_ours.format(out)
    study = tmp_path / "study"  # report: the page of the demo's study, changed by the user
    shutil.copytree(demo[0], study)
    return (["report", str(study), "--force"], study / "report.html", "was changed since musclemetab wrote it")


@pytest.mark.parametrize("case", ["solve", "solve --side both", "solve --workflow emg-ten", "estimate", "metabolics",
                                  "metabolics --sensitivity", "analyse", "analyse (analyse.json)", "report",
                                  "geometry", "calibrate-passive", "calibrate-passive --side both",
                                  "run (the study's root)"])
def test_a_file_the_package_did_not_write_is_never_replaced(example, demo, tmp_path, capsys, decoy, case):
    """A file of the user under one of the package's output names (or the package's file, changed
    since): the command refuses in one line naming the file and the remedy, before its work,
    and the file and its folder stay as they were (no lock, no temporary, no list added)."""
    args, path, words = _user_file_case(case, example, demo, tmp_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("the user's own file\n")
    before = {p: p.read_bytes() for p in path.parent.iterdir() if p.is_file()}
    started = time.monotonic()
    assert main(args) == 1
    err = _one_line_error(capsys)
    assert f"{path} {words}" in err, err
    assert err.endswith("it is not replaced: move the file away, or choose another output folder (--out)"), err
    assert {p: p.read_bytes() for p in path.parent.iterdir() if p.is_file()} == before
    assert time.monotonic() - started < 10.0  # refused before the solve, the metabolic models or the figures


def test_the_files_the_package_wrote_are_replaced_and_listed_anew(example, demo, tmp_path, capsys):
    """``metabolics`` into a copy of a demo unit folder (its files listed by the study): the
    package's files are replaced, the list holds their new SHA-256 (hashlib), the others stay."""
    import hashlib

    unit = tmp_path / "unit"
    shutil.copytree(_demo_unit(demo), unit)
    solution = (unit / "solution.sto").read_bytes()
    (unit / "per_muscle.csv").write_text("")  # not the file the study listed: refused ...
    assert main(["metabolics", "--solution", str(unit), "--model", str(example.model), "--mass", "72.6",
                 "--out", str(unit)]) == 1
    assert f"{unit / 'per_muscle.csv'} was changed since musclemetab wrote it" in _one_line_error(capsys)
    shutil.copy(_demo_unit(demo) / "per_muscle.csv", unit / "per_muscle.csv")  # ... the listed one is replaced
    assert main(["metabolics", "--solution", str(unit), "--model", str(example.model), "--mass", "72.6",
                 "--out", str(unit)]) == 0
    listed = written_files(unit)
    for name in ("metabolics.sto", "per_muscle.csv", "whole_body.csv", "plausibility.json", "solution.sto"):
        assert listed[name] == {hashlib.sha256((unit / name).read_bytes()).hexdigest()}, name
    assert (unit / "solution.sto").read_bytes() == solution


def _tiny_outputs(case, out: Path) -> list[str]:
    """Write ``case``'s outputs into ``out`` with the package's writer, from small made-up numbers
    (no solve, no OpenSim); the names written."""
    import numpy as np

    if case == "geometry":
        from musclemetab.geometry import Geometry, write_geometry

        t = np.linspace(0.0, 0.1, 3)
        geom = Geometry(time=t, muscles=("soleus_r", "tibant_r"), dofs=("ankle_angle_r",),
                        lmt_m=np.array([[0.30, 0.35], [0.31, 0.34], [0.32, 0.33]]),
                        moment_arms_m=np.full((3, 1, 2), 0.04), source={})
        return [p.name for p in write_geometry(geom, out)]
    if case == "calibrate-passive":
        from musclemetab.calibration import PassiveCalibration, write_passive_parameters

        written = PassiveCalibration({"soleus_r": (2.0, 0.1, 0.6)}, {"rms_Nm": {"ankle": 0.5}}).write(out)
        both = write_passive_parameters(out.parent / "passive_parameters.csv", {"soleus_r": (2.0, 0.1, 0.6),
                                                                                "soleus_l": (2.1, 0.1, 0.6)})
        return [*written, f"../{both.name}"]
    from musclemetab.redundancy.sensitivity import Sensitivity, write_sensitivity

    sens = Sensitivity(trial="t", muscles=("soleus_r",), models=("UM10",), parameters=[("lMo", "soleus_r")],
                       values=np.array([0.05]), nominal_whole_body={"UM10": 3.0},
                       nominal_per_muscle={"UM10": np.array([12.0])}, whole_body={"UM10": np.array([0.7])},
                       per_muscle={"UM10": np.array([[9.0]])})
    return [write_sensitivity([sens], out).name]


@pytest.mark.parametrize("case", ["geometry", "calibrate-passive", "metabolics --sensitivity"])
def test_the_writers_replace_their_own_files_and_refuse_the_users(tmp_path, case):
    """Written twice into one folder: the second replaces the first without complaint (the list
    holds each file with its present SHA-256, hashlib); a file the user changed since is then
    refused by the next write, naming it, and stays."""
    import hashlib

    out = tmp_path / "out"
    names = _tiny_outputs(case, out)
    first = {n: (out / n).read_bytes() for n in names}
    assert _tiny_outputs(case, out) == names
    for n in names:
        folder = (out / n).parent
        assert (out / n).read_bytes() == first[n]
        assert written_files(folder)[Path(n).name] == {hashlib.sha256(first[n]).hexdigest()}, n
    mine = out / names[0]
    mine.write_text("the user's own file\n")
    with pytest.raises(OptionError, match=f"{mine} was changed since musclemetab wrote it.*move the file away"):
        _tiny_outputs(case, out)
    assert mine.read_text() == "the user's own file\n"


def test_a_study_run_again_replaces_the_files_of_its_root(demo, tmp_path, capsys):
    """The demo's study run again on a copy (its units complete, none solved): the root's files
    are replaced without complaint, the same bytes (what the units hold did not change), listed
    with their SHA-256 (hashlib); the units' folders are untouched."""
    import hashlib

    from musclemetab.study.runner import study_root_files

    study = _demo_copy(demo, tmp_path)
    before = {p.relative_to(study): p.read_bytes() for p in study.rglob("*") if p.is_file()}
    assert main(["run", str(study / DEMO_STUDY_FILE), "--no-progress"]) == 0
    listed = written_files(study)
    for name in study_root_files():
        if (study / name).is_file():
            assert listed[name] == {hashlib.sha256((study / name).read_bytes()).hexdigest()}, name
    assert {"results.csv", "failures.csv", "study.json", "muscle_groups.csv", "data_dictionary.csv"} <= set(listed)
    for name in ("results.csv", "per_muscle.csv", "failures.csv", "muscle_groups.csv", "data_dictionary.csv"):
        assert (study / name).read_bytes() == before[Path(name)], name
    units = {p: b for p, b in before.items() if p.parts[0] == "units"}
    assert {p.relative_to(study): p.read_bytes() for p in (study / "units").rglob("*") if p.is_file()} == units


@pytest.mark.parametrize("put, replaced", [("notes.txt", False), ("solution.sto", True)])
def test_a_unit_folder_holding_a_file_the_package_did_not_write_is_not_replaced(example, tmp_path, monkeypatch, put,
                                                                                 replaced):
    """A unit's folder lists its files; run again, the unit's folder is replaced only when every
    file in it is listed: a file of the user (notes) makes the unit fail naming it, and stays; a
    listed output the user changed is redone, as resuming does (docs/study.md)."""
    from musclemetab.errors import InputFileError
    from musclemetab.study import run_study
    from musclemetab.study import units as units_mod

    def failing(study, unit, tmp, *dependencies):  # a unit that writes a file, then fails on its input
        (tmp / "solution.sto").write_text("half")
        raise InputFileError("a broken input of the test")

    monkeypatch.setattr(units_mod, "_run_trial", failing)
    data = {"workflows": ["effort-gen"], "models": ["UM10"],
            "subjects": [{"name": "s", "model": str(example.model), "body_mass_kg": 72.6, "height_m": 1.743,
                          "trials": [{"name": "normal", "ik": str(example.ik["normal"]),
                                      "id": str(example.id["normal"])}]}]}
    study = study_from_dict(data, base="/", output=tmp_path / "study")
    run_study(study, workers=1, progress=False)
    folder = tmp_path / "study" / "units" / "s" / "normal" / "effort-gen"
    assert set(written_files(folder)) == {"solution.sto", "unit.json", units_mod.MARKER_FILE}
    (folder / put).write_text("the user's")
    run = run_study(study, workers=1, progress=False)
    reason = run.failed["s/normal/effort-gen"]
    if replaced:
        assert reason == "InputFileError: a broken input of the test" and (folder / put).read_text() == "half"
    else:
        assert f"{folder / put} was not written by musclemetab" in reason and "move the file away" in reason
        assert (folder / put).read_text() == "the user's" and (folder / "solution.sto").read_text() == "half"


# ----------------------------------------------------------------------------------------------
# 5. Ctrl-C

def _sigint_as_in_a_terminal():
    """SIGINT's default disposition, as a command started from a terminal has it (a test run
    started in the background of a non-interactive shell inherits SIGINT ignored, and Python
    then installs no KeyboardInterrupt handler)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _interrupt(args, ready, timeout=120.0):
    """Start ``python -m musclemetab ARGS`` in its own process group, wait until ``ready()`` (or
    the process ends), send SIGINT to the group as a terminal would; ``(status, stderr, seconds
    from the signal to the exit)``."""
    proc = subprocess.Popen([sys.executable, "-m", "musclemetab", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=_sigint_as_in_a_terminal)
    try:
        deadline = time.monotonic() + timeout
        while not ready() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        return proc.returncode, err, time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()


def _interrupt_holding_the_lock(args, out: Path, previous: dict) -> None:
    """:func:`_interrupt` 1.5 s after the command took the lock of ``out`` (past its option
    checks, at work): status 130 within 2 s with ``musclemetab: interrupted`` and no traceback,
    the ``previous`` files (``{path: text}``) as they were, no lock, no temporary folder."""
    lock = out / ".musclemetab.lock"
    code, err, seconds = _interrupt(args, lambda: lock.exists() and time.sleep(1.5) is None)
    assert code == 130, err
    assert err.strip().splitlines()[-1] == "musclemetab: interrupted" and "Traceback" not in err
    assert seconds < 2.0, f"{seconds:.2f} s from the signal to the exit; standard error:\n{err}"
    assert {p: p.read_text() for p in previous} == previous
    assert not lock.exists() and not list(out.rglob(".partial-*"))


@pytest.mark.parametrize("side", ["r", "both"])
def test_ctrl_c_during_solve_exits_130_at_once_and_keeps_the_previous_output(example, tmp_path, decoy, side):
    """A finer mesh (300 per s) than any other test solves, so the solve is still running when the
    signal comes (after the lock is taken, i.e. past the option checks)."""
    out = tmp_path / "out"
    legs = [out / "r", out / "l"] if side == "both" else [out]
    previous = {}
    for leg in legs:
        previous.update(_previous_output(leg, {name: f"previous {leg.name} {name}\n"
                                               for name in ("solution.sto", "summary.json")}))
    args = ["solve", *_files(example), "--mesh-frequency", "300", "--side", side, "--out", str(out)]
    if side == "both":
        args[1:7] = _files(example)
        args += ["--cycle", "auto", "--workers", "2"]
    _interrupt_holding_the_lock(args, out, previous)


def test_ctrl_c_while_ipopt_iterates_exits_130_not_as_a_failed_solve(example, tmp_path, decoy):
    """CasADi stops IPOPT on Ctrl-C and returns a failure status; the command must take it for
    the interrupt it is (status 130, previous output kept), not for a solve that did not
    converge (status 1, the unconverged iterate written over the output). The signal is sent
    once IPOPT's first progress line (one at every iterate) shows that it iterates: the whole
    trial's solve has far to go."""
    out = tmp_path / "out"
    _previous_output(out, {"summary.json": "previous\n"})
    args = ["solve", *_files(example), "--out", str(out)]
    proc = subprocess.Popen([sys.executable, "-c", _EVERY_ITERATE, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=_sigint_as_in_a_terminal)
    lines, iterating = [], threading.Event()

    def read():
        for line in proc.stderr:
            lines.append(line)
            if "solving: iteration" in line:
                iterating.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert iterating.wait(120), "".join(lines)
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=60)
        reader.join(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    err = "".join(lines)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "musclemetab: interrupted" and "did not converge" not in err
    assert (out / "summary.json").read_text() == "previous\n" and not (out / "solution.sto").exists()


@pytest.mark.opensim
def test_ctrl_c_while_ipopt_iterates_prints_one_line_and_none_of_casadi(example, tmp_path, capfd, monkeypatch):
    """SIGINT delivered while IPOPT computes (10 ms after its third iterate; a window no other
    test solves, so IPOPT runs): CasADi catches the interrupt in a function evaluation or the
    iteration callback and writes its own warning line about it (``CasADi - ... WARNING(
    "KeyboardInterruptException") [...]``); the command's standard error holds its one line,
    ``musclemetab: interrupted``, after the progress lines and nothing of CasADi's."""
    import musclemetab.redundancy.ipopt as ipopt
    import musclemetab.redundancy.progress as progress

    monkeypatch.setattr(progress, "PROGRESS_INTERVAL_S", 0.0)
    real = ipopt.ProgressLines.iteration

    def iteration(self, f, g):
        real(self, f, g)
        if self.count == 3:  # the signal comes while IPOPT computes the next iterate
            threading.Timer(0.01, os.kill, (os.getpid(), signal.SIGINT)).start()

    monkeypatch.setattr(ipopt.ProgressLines, "iteration", iteration)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (see above)
    try:
        status = main(["solve", *_files(example), "--window", "0.64:0.86", "--out", str(tmp_path / "s")])
    finally:
        signal.signal(signal.SIGINT, previous)
    err = capfd.readouterr().err.splitlines()
    assert status == 130, err
    assert err[-1] == "musclemetab: interrupted", err
    assert all(line.startswith("musclemetab: solving: iteration ") for line in err[:-1]), err


def test_ctrl_c_during_report_exits_130_and_keeps_the_previous_report(demo, tmp_path, decoy):
    """``report --force`` redraws the figures of a copy of the demo's study folder; SIGINT 2.5 s
    after its start (reading the study, or drawing): status 130 within 2 s, the previous page as
    it was."""
    folder = tmp_path / "study"
    shutil.copytree(demo[0], folder)
    page = (folder / "report.html").read_bytes()
    start = time.monotonic()
    code, err, seconds = _interrupt(["report", str(folder), "--force"], lambda: time.monotonic() - start > 2.5)
    assert code == 130 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == "musclemetab: interrupted"
    assert seconds < 2.0
    assert (folder / "report.html").read_bytes() == page


def test_ctrl_c_while_outputs_are_moved_into_place_waits_for_the_last_one(tmp_path):
    """SIGINT while the legs' folders are written (``solve --side both``) comes after the last
    one: both folders new, then KeyboardInterrupt."""
    from musclemetab.processes import sigint_deferred

    legs = [tmp_path / "r", tmp_path / "l"]
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (see above)
    try:
        with pytest.raises(KeyboardInterrupt):
            with sigint_deferred():
                for i, leg in enumerate(legs):
                    with atomic_directory(leg) as tmp:
                        (tmp / "summary.json").write_text("new")
                    if i == 0:
                        os.kill(os.getpid(), signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert [(leg / "summary.json").read_text() for leg in legs] == ["new", "new"]


@pytest.mark.parametrize("workflow", ["emg-ten", "effort-gen"])
def test_ctrl_c_during_an_emg_solve_exits_130_and_keeps_the_previous_output(example, tmp_path, decoy, workflow):
    """EMG-TEN, and the EMG-informed solve of an effort workflow: SIGINT 1.5 s after the lock is
    taken (the solve running) gives status 130 within 2 s and the previous output as it was."""
    out = tmp_path / "out"
    previous = _previous_output(out, {"parameters.json": "previous\n", "summary.json": "previous\n"})
    args = ["solve", "--workflow", workflow, *_files(example), "--emg", str(example.emg["normal"]), "--labels",
            "normal", "--out", str(out)]
    _interrupt_holding_the_lock(args, out, previous)
    assert sorted(p.name for p in out.iterdir()) == [FILES_MANIFEST, "parameters.json", "summary.json"]


def test_ctrl_c_during_estimate_exits_130_at_once_and_keeps_the_previous_output(example, tmp_path, decoy):
    """``estimate`` (the soleus' tendon stiffness from constant fiber lengths): SIGINT 1.5 s after
    it holds the lock gives status 130 within 2 s, the previous parameters and personalised model
    as they were."""
    from musclemetab.io import read_storage, write_storage

    import pandas as pd

    inputs = tmp_path / "inputs"
    inputs.mkdir()
    t = read_storage(example.ik["normal"]).index
    write_storage(inputs / "us.mot", pd.DataFrame({"soleus_r": [40.0] * len(t)}, index=t), in_degrees=False)
    out = tmp_path / "out"
    previous = _previous_output(out, {"parameters.json": "previous\n",
                                      f"{example.model.stem}_personalised.osim": "previous\n"})
    args = ["estimate", *_files(example), "--ultrasound", str(inputs / "us.mot"), "--estimate",
            "tendon_stiffness=soleus_r", "--labels", "normal", "--out", str(out)]
    _interrupt_holding_the_lock(args, out, previous)
    assert not (out / "normal").exists()


@pytest.mark.parametrize("view", ["failures.csv", "report", "data dictionary"])
def test_an_interrupted_unit_is_labelled_interrupted_apart_from_the_failures(example, tmp_path, monkeypatch, view):
    """A study of three trials whose first unit fails on its input and whose second gets Ctrl-C
    (as in tests/test_robustness_study.py): the third is never reached. ``failures.csv`` says
    ``failed`` for the first and ``interrupted`` for the others; the report lists the first under
    "Failures" and the others under their own heading "Interrupted"; the data dictionary
    documents the column."""
    import re

    import pandas as pd

    from musclemetab.errors import InputFileError
    from musclemetab.study import run_study
    from musclemetab.study import units as units_mod

    if view == "data dictionary":
        from musclemetab.datadict import DATA_DICTIONARY

        (entry,) = [e for e in DATA_DICTIONARY if e[1] == "status"]
        assert "failures.csv" in entry[0] and "failed" in entry[3] and "interrupted" in entry[3]
        return
    calls = []

    def trial(study, unit, tmp, *dependencies):
        calls.append(unit.label)
        if len(calls) == 1:
            raise InputFileError("a broken input of the test")
        raise KeyboardInterrupt

    monkeypatch.setattr(units_mod, "_run_trial", trial)
    data = {"workflows": ["effort-gen"], "models": ["UM10"],
            "subjects": [{"name": "s", "model": str(example.model), "body_mass_kg": 72.6, "height_m": 1.743,
                          "trials": [{"name": t, "ik": str(example.ik[t]), "id": str(example.id[t])}
                                     for t in ("slow", "normal", "fast")]}]}
    out = tmp_path / "study"
    run = run_study(study_from_dict(data, base="/", output=out), workers=1, progress=False)
    assert calls == ["s/slow/effort-gen", "s/normal/effort-gen"] and run.interrupted == ["s/normal/effort-gen"]
    failures = pd.read_csv(out / "failures.csv", keep_default_na=False).set_index("trial")
    assert list(failures.columns) == ["subject", "workflow", "status", "reason"]
    assert failures["status"].to_dict() == {"slow": "failed", "normal": "interrupted", "fast": "interrupted"}
    if view == "report":
        from musclemetab.report.folder import read_study_folder
        from musclemetab.report.page import render_page

        html = render_page(read_study_folder(out), [])
        failed = html.split('<h2 id="failures">')[1].split("<h2")[0]
        stopped = html.split('<h2 id="interrupted">Interrupted</h2>')[1].split("<h2")[0]
        rows = lambda part: re.findall(r"<td[^>]*>(slow|normal|fast)</td>", part)  # noqa: E731
        assert rows(failed) == ["slow"] and "a broken input of the test" in failed
        assert rows(stopped) == ["normal", "fast"] and "2 units did not finish" in stopped
        assert 'href="#interrupted"' in html


def test_a_ctrl_c_swallowed_on_its_way_is_raised_before_anything_is_written():
    """Ctrl-C that Python code swallows on its way (an interrupt running through an import guarded
    by ``except ImportError``) inside ``solve``'s or ``estimate``'s :func:`sigint_noted` block is
    raised before the outputs are written: the writing block does not run; the next one does."""
    from musclemetab.processes import sigint_deferred, sigint_noted

    written = []
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (see above)
    try:
        with pytest.raises(KeyboardInterrupt):
            with sigint_noted():
                try:
                    os.kill(os.getpid(), signal.SIGINT)
                    time.sleep(1.0)
                except KeyboardInterrupt:
                    pass  # swallowed
                with sigint_deferred():
                    written.append("new outputs")
        with sigint_deferred():
            written.append("the next command's outputs")
    finally:
        signal.signal(signal.SIGINT, previous)
    assert written == ["the next command's outputs"]


def _interrupted_small_solve(handle):
    """IPOPT on a small problem with progress lines that send SIGINT at the third iterate, the
    KeyboardInterrupt then given to ``handle`` (it raises what CasADi would see, or nothing: the
    interrupt lost), inside :func:`~musclemetab.processes.sigint_noted` and with SIGINT as in a
    terminal: ``(solver, iterates seen)`` once the block has raised KeyboardInterrupt (the test
    fails otherwise)."""
    import casadi as ca

    from musclemetab.processes import sigint_noted
    from musclemetab.redundancy import progress

    iterations = []

    class Lines(progress.ProgressLines):
        def iteration(self, f, g):
            iterations.append(f)
            if len(iterations) == 3:
                try:
                    os.kill(os.getpid(), signal.SIGINT)
                    time.sleep(0.5)  # the handler runs here, inside the callback
                except KeyboardInterrupt as exc:
                    handle(exc)
            super().iteration(f, g)

    x = ca.SX.sym("x", 2)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (see above)
    original = progress.ProgressLines
    progress.ProgressLines = Lines
    try:
        with progress.solve_progress(interval_s=60.0, stream=io.StringIO()):
            callback = progress._progress_callback(2, 0, [], [])
        solver = ca.nlpsol("s", "ipopt", {"x": x, "f": (x[0] - 1) ** 4 + (x[1] - 2) ** 4},
                           {"iteration_callback": callback, "ipopt": {"print_level": 0, "sb": "yes"},
                            "print_time": False})
        with pytest.raises(KeyboardInterrupt):
            with sigint_noted():
                solver(x0=[0, 0])
    finally:
        progress.ProgressLines = original
        signal.signal(signal.SIGINT, previous)
    return solver, iterations


def test_ctrl_c_inside_the_progress_callback_stops_ipopt_without_a_traceback(capfd):
    """Ctrl-C that comes while IPOPT's progress callback runs, at its third iteration, inside
    CasADi's conversion of the callback's arguments, where it surfaces as a ``SystemError`` chaining
    the interrupt (CasADi printed that traceback and its warning, seen in a run): the callback asks
    IPOPT to stop, IPOPT returns, and the interrupt is raised once, with nothing on standard error."""
    def as_in_casadi(exc):  # as it surfaces from inside CasADi's argument conversion
        raise SystemError("<method 'get' of 'dict' objects> returned a result with an exception set") from exc

    solver, iterations = _interrupted_small_solve(as_in_casadi)
    assert len(iterations) == 3 and solver.stats()["return_status"] == "User_Requested_Stop"
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err and "KeyboardInterrupt" not in out + err, err


def test_ctrl_c_whose_interrupt_is_lost_still_stops_ipopt_at_the_next_iterate():
    """Ctrl-C noted by the command's handler whose KeyboardInterrupt Python then loses (raised where it
    drops it, e.g. a weakref callback: here swallowed inside the progress callback's work): IPOPT is
    asked to stop at its next iterate, and the interrupt is raised once it returns (it ran to its
    end before)."""
    solver, iterations = _interrupted_small_solve(lambda exc: None)  # lost
    assert len(iterations) == 3 and solver.stats()["return_status"] == "User_Requested_Stop"


def test_an_interrupt_python_cannot_raise_is_not_printed_by_the_command_line(capsys):
    """Ctrl-C or SIGTERM that lands in a weakref callback (seen in a run: that of an import's module
    lock) is an "unraisable" error Python prints with its traceback; the command line's hook drops
    it (the handlers in place have noted the interrupt, which the command says once) and passes
    every other unraisable error on."""
    import weakref

    from musclemetab.commands import _interrupt_not_raisable

    passed = []
    previous, sys.unraisablehook = sys.unraisablehook, _interrupt_not_raisable(passed.append)
    try:
        class Thing:
            pass

        def interrupted(_):
            raise KeyboardInterrupt

        def broken(_):
            raise ValueError("a callback's own error")

        for callback in (interrupted, broken):
            thing = Thing()
            ref = weakref.ref(thing, callback)
            del thing  # the callback runs here; its error is unraisable
            assert ref() is None
    finally:
        sys.unraisablehook = previous
    assert [type(u.exc_value) for u in passed] == [ValueError]
    assert capsys.readouterr().err == ""


def test_progress_labels_an_interrupted_unit_interrupted_not_failed():
    import io

    from musclemetab.study.runner import _Progress

    stream = io.StringIO()
    bar = _Progress(3, True, stream)
    bar.update("s/a/effort-gen", {"status": "ok"})
    bar.update("s/b/effort-gen", {"status": "interrupted"})
    bar.update("s/c/effort-gen", {"status": "failed"})
    lines = stream.getvalue().splitlines()
    assert lines[1].endswith("s/b/effort-gen interrupted") and "0 failed, 1 interrupted" in lines[1]
    assert lines[2].endswith("s/c/effort-gen FAILED") and "1 failed, 1 interrupted" in lines[2]


def test_run_refuses_the_workers_the_table_refuses(tmp_path, capsys):
    assert main(["run", str(tmp_path / "study.toml"), "--workers", "0"]) == 1
    err = _one_line_error(capsys)
    assert "--workers = 0" in err and NUMBER_KEYS["workers"].range_text() in err and "study.toml" not in err


def test_an_error_that_ctrl_c_caused_is_reported_as_the_interrupt(monkeypatch, capsys, tmp_path, decoy):
    """Ctrl-C during the import of a compiled module can come back as that import's ImportError
    (the interrupt its context): the command says it was interrupted and exits 130, without a
    traceback; an ImportError of its own (no interrupt behind it) is not taken for one."""
    import musclemetab.commands.geometry as geometry
    from musclemetab.commands import main

    def interrupted_import(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ImportError("numpy.core.multiarray failed to import")

    monkeypatch.setattr(geometry, "run", interrupted_import)
    argv = ["geometry", "--model", "m.osim", "--ik", "ik.mot", "--out", str(tmp_path / "g")]
    assert main(argv) == 130
    assert capsys.readouterr().err == "musclemetab: interrupted\n"

    def broken_import(args):
        raise ImportError("no module named foo")

    monkeypatch.setattr(geometry, "run", broken_import)
    with pytest.raises(ImportError, match="foo"):
        main(argv)
    assert not (tmp_path / "g").exists()


def test_demo_never_writes_over_a_study_file_of_the_user(tmp_path, decoy):
    """``demo`` writes ``OUT/study.toml``: over its own earlier one (listed in the folder's
    file list) without complaint, over a file of the user of that name never (one line naming it)."""
    from musclemetab.errors import MusclemetabError
    from musclemetab.study.demo import demo_study

    out = tmp_path / "demo"
    demo_study(out, speeds=["normal"])
    first = (out / "study.toml").read_text()
    demo_study(out, speeds=["normal", "fast"])  # its own file: replaced
    assert (out / "study.toml").read_text() != first and "fast" in (out / "study.toml").read_text()
    (out / "study.toml").write_text("# my own study\n")
    with pytest.raises(MusclemetabError, match=r"study\.toml"):
        demo_study(out, speeds=["normal"])
    assert (out / "study.toml").read_text() == "# my own study\n"


# ----------------------------------------------------------------------------------------------
# 6. output streams that fail

#: ``python -c`` running the command line with a progress line for every IPOPT iterate (throttle 0 s)
_EVERY_ITERATE = ("import sys; import musclemetab.redundancy.progress as progress; progress.PROGRESS_INTERVAL_S = 0.0; "
                  "from musclemetab.commands import main; sys.argv[0] = 'musclemetab'; sys.exit(main())")


def _closing(fd: int):
    """A ``preexec_fn`` starting the command with descriptor ``fd`` closed (``2>&-``)."""
    return lambda: os.close(fd)


@pytest.mark.opensim
def test_a_closed_standard_error_never_stops_a_solve(example, tmp_path):
    """``solve ... 2>&-`` with a progress line due at every iterate (a new process: it solves for
    itself, the test run's memo of solves is not installed there): the lines are lost, the solve
    converges and the command exits 0
    (the progress callback failing on the write used to stop IPOPT at its first line with
    User_Requested_Stop, and the command blamed the constraints)."""
    out = tmp_path / "s"
    proc = subprocess.run([sys.executable, "-c", _EVERY_ITERATE, "solve", *_files(example), "--window",
                           "0.62:0.84", "--out", str(out)], stdout=subprocess.PIPE, text=True,
                          preexec_fn=_closing(2), timeout=300)
    summary = json.loads((out / "summary.json").read_text())
    assert proc.returncode == 0 and summary["status"] == "Solve_Succeeded", proc.stdout
    assert summary["iterations"] > 1 and "Solve_Succeeded" in proc.stdout


@pytest.mark.opensim
@pytest.mark.parametrize("stdout", ["full", "closed"])
def test_a_standard_output_that_cannot_be_written_is_exit_1_without_a_traceback(example, tmp_path, stdout):
    """``geometry ... >/dev/full`` and ``>&-``: the geometry is computed and written, the report
    line is lost; status 1 with one line on standard error saying why, no traceback."""
    out = tmp_path / "g"
    with open(os.devnull if stdout == "closed" else "/dev/full", "w") as sink:
        proc = subprocess.run([sys.executable, "-m", "musclemetab", "geometry", "--model", str(example.model),
                               "--ik", str(example.ik["normal"]), "--out", str(out)], stdout=sink,
                              stderr=subprocess.PIPE, text=True, timeout=300,
                              preexec_fn=_closing(1) if stdout == "closed" else None)
    reason = "it is closed" if stdout == "closed" else "No space left on device"
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.splitlines() == [
        f"musclemetab: error: standard output could not be written ({reason}), so the command's messages are "
        "lost; run it again with standard output to a terminal or a file that can be written"]
    assert (out / "muscle_tendon_lengths.sto").is_file()


def test_progress_lines_to_a_full_or_closed_stream_are_lost_without_an_exception():
    """The progress writers of a solve and of a study, given a full stream (``/dev/full``), a
    closed one and none (``sys.stderr`` of ``2>&-``; a solve's lines then go to the package's
    logger, whose handler loses them): no exception, no line counted on a stream."""
    from musclemetab.redundancy.ipopt import ProgressLines
    from musclemetab.study.runner import _Progress

    closed = open(os.devnull, "w")
    closed.close()
    full = open("/dev/full", "w")
    for stream in (full, closed, None):
        lines = ProgressLines([0.0], [0.0], 0.0, stream=stream)
        lines.stream = stream
        lines.iteration(1.0, [0.0])
        assert lines.count == 1 and lines.lines == (0 if stream is not None else 1)
        _Progress(1, True, stream).update("s/a/effort-gen", {"status": "ok"})
    with pytest.raises(OSError):  # what the writers could not write is still in its buffer
        full.close()

"""Choice of IPOPT's linear solver: option checks before any work, options passed to IPOPT."""

from __future__ import annotations

import ctypes.util

import pytest

from musclemetab.commands import main
from musclemetab.errors import OptionError
from musclemetab.redundancy.ipopt import (
    MUMPS_OPTIONS,
    SolverOptions,
    check_linear_solver,
    ipopt_options,
)


def test_missing_runtime_library_is_an_option_error(tmp_path):
    missing = tmp_path / "libhsl_missing.so"
    with pytest.raises(OptionError, match=r"ma57.*libhsl_missing\.so.*cannot be loaded"):
        SolverOptions(linear_solver="ma57", linear_solver_library=str(missing))
    with pytest.raises(OptionError, match=r"pardiso.*libpardiso_missing\.so"):
        check_linear_solver("pardiso", str(tmp_path / "libpardiso_missing.so"))
    with pytest.raises(OptionError, match=r"'superlu' is unknown.*mumps, spral, ma27"):
        SolverOptions(linear_solver="superlu")
    with pytest.raises(OptionError, match="built into IPOPT"):
        SolverOptions(linear_solver="spral", linear_solver_library="libhsl.so")


def test_runtime_library_passed_to_ipopt(monkeypatch):
    # a library that does not export the solver's functions is refused (libm is no HSL library);
    # one that does (libm, its symbol table read as if it did) is passed to IPOPT under the option
    # of the solver family
    import musclemetab.redundancy.ipopt as ipopt
    import musclemetab.redundancy.linear_solvers as linear_solvers

    libm = ctypes.util.find_library("m")
    assert libm
    with pytest.raises(OptionError, match=r"ma86: .*does not export ma86_analyse_d.*not loaded"):
        SolverOptions(linear_solver="ma86", linear_solver_library=libm)
    every = {s for names in ipopt.LINEAR_SOLVER_SYMBOLS.values() for s in names}
    monkeypatch.setattr(linear_solvers, "exported_symbols", lambda path: every)
    hsl = ipopt_options(SolverOptions(linear_solver="ma86", linear_solver_library=libm), MUMPS_OPTIONS)
    assert hsl["linear_solver"] == "ma86" and hsl["hsllib"] == libm
    assert "min_refinement_steps" not in hsl  # the MUMPS settings stay with MUMPS
    par = ipopt_options(SolverOptions(linear_solver="pardiso", linear_solver_library=libm))
    assert par["pardisolib"] == libm and "hsllib" not in par
    default = ipopt_options(SolverOptions(), MUMPS_OPTIONS)
    assert default["linear_solver"] == "mumps" and default["min_refinement_steps"] == 0
    assert "hsllib" not in default and "pardisolib" not in default


def test_command_line_reports_the_library_before_reading_files(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["solve", "--model", str(tmp_path / "no_model.osim"), "--ik", "ik.mot", "--id", "id.sto",
                 "--linear-solver", "ma27", "--linear-solver-library", str(tmp_path / "nolib.so"),
                 "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1
    assert "--linear-solver" in err and "nolib.so" in err and "no_model.osim" not in err
    assert not out.exists()


def test_emg_informed_solve_uses_the_linear_solver(tmp_path, capsys, monkeypatch, example):
    """An effort workflow's EMG-informed solve (``solve --emg``) hands the command line's linear
    solver to the solve, and refuses a missing library before reading any file, as the other
    solves do."""
    import musclemetab.redundancy.emg_run as run

    seen = {}

    class Stop(Exception):
        pass

    def capture(*args, options=None, **kwargs):
        seen["options"] = options
        raise Stop

    monkeypatch.setattr(run, "solve_emg_ten", capture)
    files = ["--model", str(example.model), "--ik", str(example.ik["normal"]), "--id", str(example.id["normal"]),
             "--emg", str(example.emg["normal"])]
    with pytest.raises(Stop):
        main(["solve", "--workflow", "effort-cal", *files, "--linear-solver", "spral", "--out", str(tmp_path / "a")])
    assert seen["options"].linear_solver == "spral"
    code = main(["solve", "--workflow", "effort-cal", "--model", str(tmp_path / "no_model.osim"), "--ik", "ik.mot",
                 "--id", "id.sto", "--emg", "emg.mot", "--linear-solver", "ma27", "--linear-solver-library",
                 str(tmp_path / "nolib.so"), "--out", str(tmp_path / "b")])
    err = capsys.readouterr().err.strip()
    assert code == 1 and "--linear-solver" in err and "nolib.so" in err and "no_model.osim" not in err


def test_study_key(example):
    from musclemetab.study import study_from_dict
    from musclemetab.study.units import plan_units, unit_key

    def study(**extra):
        data = {
            "name": "s", "workflows": ["effort-gen"], "models": ["UM10"],
            "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": 70.0, "height_m": 1.7,
                          "trials": [{"name": "normal", "ik": str(example.ik["normal"]),
                                      "id": str(example.id["normal"])}]}],
        }
        return study_from_dict(data | extra, base="/")

    # a study file may name a solver, not a library (native code) to load
    with pytest.raises(OptionError, match=r"\[solver\] linear_solver_library: a study file names a linear solver, "
                                          r"not a library.*MUSCLEMETAB_LINEAR_SOLVER_LIBRARY"):
        study(solver={"linear_solver": "ma97", "linear_solver_library": "/nowhere/libhsl_nowhere.so"})
    with pytest.raises(OptionError, match=r"\[solver\].*ma97.*libhsl\.so"):  # not installed here
        study(solver={"linear_solver": "ma97"})
    default, spral = study(), study(solver={"linear_solver": "spral"})
    assert spral.settings["solver"]["linear_solver"] == "spral"
    unit = plan_units(default)[1][0]
    assert unit_key(spral, unit) != unit_key(default, unit)  # another solver may find another optimum

"""The command line: version, help on every subcommand, one-line errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

import musclemetab
from musclemetab.commands import build_parser, main


def _subcommands():
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return sorted(action.choices)


def test_version():
    r = subprocess.run([sys.executable, "-m", "musclemetab", "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == f"musclemetab {musclemetab.__version__}"


def test_geometry_is_a_subcommand():
    assert "geometry" in _subcommands()


@pytest.mark.parametrize("command", _subcommands())
def test_help_on_every_subcommand(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    # every command writing files names where (--out; export's --mat), the cache command writes none
    main_option = {"export": "--mat", "cache": "--clear"}.get(command, "--out")
    assert out.startswith(f"usage: musclemetab {command}") and main_option in out
    assert "-q, --quiet" in out and "-v, --verbose" in out


def test_usage_error_is_one_line_and_status_1(capsys):
    with pytest.raises(SystemExit) as info:
        main(["geometry"])
    assert info.value.code == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("musclemetab: error: ") and "--out" in err


@pytest.mark.parametrize("argv, line", [
    (["geometry", "--modle", "m.osim", "--ik", "ik.mot", "--out", "o"],
     "unrecognized option --modle (did you mean --model?); see 'musclemetab geometry --help'"),
    (["solve", "--model", "m.osim", "--ik", "ik.mot", "--out", "o", "--sdie", "l"],
     "unrecognized option --sdie (did you mean --side?); see 'musclemetab solve --help'"),
    (["report", "DIR", "--xyzzy"], "unrecognized option --xyzzy; see 'musclemetab report --help'"),
    (["-q", "metabolics", "--solution", "S", "--mass", "70", "--out", "o", "--modle", "m.osim"],
     "unrecognized option --modle (did you mean --model?); see 'musclemetab metabolics --help'"),
    (["analyse", "--solutoin", "S", "--metabolcs", "M", "--out", "o"],
     "unrecognized options --solutoin (did you mean --solution?), --metabolcs (did you mean --metabolics?); "
     "see 'musclemetab analyse --help'"),
])
def test_an_unknown_option_names_the_closest_known_one_and_the_commands_help(argv, line, capsys):
    """A misspelt option is named as unknown with the command's closest option (it used to say only
    "the following arguments are required: --model", hiding the cause), and the line points to
    the command's own help (an unknown option after the command's required ones pointed to the
    top-level help)."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 1
    assert capsys.readouterr().err.splitlines() == [f"musclemetab: error: {line}"]


@pytest.mark.parametrize("argv, line", [
    (["solv", "--model", "m.osim"], "unknown command 'solv' (did you mean solve?); see 'musclemetab solve --help'"),
    (["-q", "metabolcs", "--out", "o"],
     "unknown command 'metabolcs' (did you mean metabolics?); see 'musclemetab metabolics --help'"),
    (["frobnicate"], "unknown command 'frobnicate' (the commands: c3d, emg, prepare, geometry, solve, estimate, metabolics, "
     "analyse, export, calibrate-passive, run, demo, report, cache); see 'musclemetab --help'"),
])
def test_a_misspelt_command_names_the_closest_and_its_help(argv, line, capsys):
    """A misspelt command (it used to be taken for a missing one, its options for unknown ones:
    "unrecognized option --model (did you mean --help?)") is named with the closest command and
    that command's ``--help``."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 1
    assert capsys.readouterr().err.splitlines() == [f"musclemetab: error: {line}"]


@pytest.mark.parametrize("flag, debug", [("-q", False), ("--quiet", False), (None, False), ("-v", True),
                                         ("--verbose", True)])
@pytest.mark.parametrize("where", ["before", "after"])
def test_quiet_and_verbose_before_or_after_the_command(flag, debug, where, tmp_path, capsys):
    """``-q`` and ``-v`` on either side of the command's name: the error of a missing solution
    folder is said in every case, the debug line of the command only with ``-v``."""
    argv = ["metabolics", "--solution", str(tmp_path / "none"), "--mass", "70", "--out", str(tmp_path / "m")]
    if flag:
        argv = [flag, *argv] if where == "before" else [argv[0], flag, *argv[1:]]
    assert main(argv) == 1
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert out == "" and lines[-1].startswith("musclemetab: error: ") and "none" in lines[-1]
    assert lines[:-1] == ([f"musclemetab: debug: musclemetab {' '.join(argv)} (Python {sys.version.split()[0]})"]
                          if debug else [])


@pytest.mark.parametrize("argv", [["-q", "-v", "report", "A"], ["report", "-q", "-v", "A"], ["-q", "report", "-v", "A"],
                                  ["--verbose", "report", "A", "--quiet"]])
def test_quiet_and_verbose_together_are_refused(argv, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 1
    assert capsys.readouterr().err.splitlines() == [
        "musclemetab: error: argument -v/--verbose: not allowed with argument -q/--quiet; see 'musclemetab report --help'"]


def test_a_warning_is_said_once_per_run(capsys):
    """The same warning raised twice in a run (from two places, so that Python's own registry
    would show both) is printed once; the next run says it again; ``-q``'s level says nothing."""
    import logging
    import warnings

    from musclemetab.errors import PlausibilityWarning
    from musclemetab.messages import configure

    def run(level):
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            restore = configure(level)
            try:
                warnings.warn("S/r: reserve above 5%", PlausibilityWarning)
                warnings.warn("S/r:   reserve above 5%", PlausibilityWarning)  # the same line once collapsed
                warnings.warn("S/l: reserve above 5%", PlausibilityWarning)
            finally:
                restore()
        return capsys.readouterr().err.splitlines()

    once = ["musclemetab: warning: S/r: reserve above 5%", "musclemetab: warning: S/l: reserve above 5%"]
    assert run(logging.INFO) == once
    assert run(logging.INFO) == once
    assert run(logging.ERROR) == []


def test_importing_the_package_loads_neither_opensim_nor_casadi():
    code = "import sys, musclemetab, musclemetab.commands; print('opensim' in sys.modules, 'casadi' in sys.modules)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.stdout.split() == ["False", "False"], r.stderr


def test_console_script_is_the_commands_main():
    """pyproject.toml's console script names ``musclemetab.commands:main`` (what ``python -m
    musclemetab`` runs): the installed ``musclemetab`` program and the tests run the same code."""
    import importlib
    import tomllib
    from pathlib import Path

    import musclemetab.commands

    pyproject = Path(__file__).resolve().parents[1] / "pyproject.toml"
    target = tomllib.loads(pyproject.read_text())["project"]["scripts"]["musclemetab"]
    module, _, attr = target.partition(":")
    assert getattr(importlib.import_module(module), attr) is musclemetab.commands.main
    main_file = Path(musclemetab.__file__).with_name("__main__.py").read_text()
    assert "from .commands import main" in main_file


def test_no_library_module_imports_a_command_module():
    """The command modules sit on top of the library: no module outside ``musclemetab.commands``
    imports one (the package's own ``__main__`` aside)."""
    import ast
    from pathlib import Path

    root = Path(musclemetab.__file__).parent
    offending = []
    for path in root.rglob("*.py"):
        rel = path.relative_to(root)
        if rel.parts[0] == "commands" or rel.name == "__main__.py":
            continue
        package = ["musclemetab", *rel.parts[:-1]]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.ImportFrom):
                base = package[: len(package) - node.level + 1] if node.level else []
                names = [".".join([*base, node.module or ""]).strip(".")]
                names += [f"{names[0]}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            if any(n == "musclemetab.commands" or n.startswith("musclemetab.commands.") for n in names):
                offending.append(str(rel))
    assert offending == []


def test_export_refuses_a_name_without_mat_and_a_file_it_did_not_write(tmp_path, capsys):
    """``export --mat`` checks the file before reading the folder: a name not ending in ``.mat``
    and a file of the user's under the name are refused in one line, the file left as it was."""
    mine = tmp_path / "mine.mat"
    mine.write_text("my own notes")
    assert main(["export", str(tmp_path / "S"), "--mat", str(tmp_path / "out.txt")]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"musclemetab: error: --mat {tmp_path / 'out.txt'}: a MATLAB file's name ends in .mat; give e.g. "
        f"{tmp_path / 'out.mat'}"]
    assert main(["export", str(tmp_path / "S"), "--mat", str(mine)]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"musclemetab: error: {mine} was not written by musclemetab")
    assert mine.read_text() == "my own notes" and sorted(p.name for p in tmp_path.iterdir()) == ["mine.mat"]

"""The command line: version, help on every subcommand, one-line errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

import musclemetab
from musclemetab.cli import build_parser, main


def _subcommands():
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return sorted(action.choices)


def test_version():
    r = subprocess.run([sys.executable, "-m", "musclemetab.cli", "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == f"musclemetab {musclemetab.__version__}"


def test_geometry_is_a_subcommand():
    assert "geometry" in _subcommands()


@pytest.mark.parametrize("command", _subcommands())
def test_help_on_every_subcommand(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: musclemetab {command}") and "--out" in out


def test_usage_error_is_one_line_and_status_1(capsys):
    with pytest.raises(SystemExit) as info:
        main(["geometry"])
    assert info.value.code == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("musclemetab: error: ") and "--out" in err


def test_importing_the_package_loads_neither_opensim_nor_casadi():
    code = "import sys, musclemetab, musclemetab.cli; print('opensim' in sys.modules, 'casadi' in sys.modules)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.stdout.split() == ["False", "False"], r.stderr

"""The package's layers (docs/architecture.md, "Which package may import which"): every import of
the package's own modules, at the top of a module or inside a function, goes to its own
package or to a layer below; none runs back up."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parent.parent / "src" / "musclemetab"

#: the layers from the bottom up, as docs/architecture.md lists them
LAYERS = [
    {"errors", "muscle", "colours", "_docs"},
    {"settings", "messages", "quality", "__init__"},
    {"io", "properties", "processes", "opensim_bridge"},
    {"cache", "datasets", "datadict", "passive"},
    {"model"},
    {"layout"},
    {"geometry", "mocap"},
    {"external_loads", "emg"},
    {"events"},
    {"metabolics"},
    {"redundancy", "study_layout"},
    {"analysis", "uncertainty"},
    {"report", "uncertainty_coverage"},
    {"study", "calibration"},
    {"commands"},
    {"__main__"},
]
LAYER = {name: i for i, names in enumerate(LAYERS) for name in names}


def _unit(path: Path) -> str:
    """The top-level module or package of the package a file belongs to."""
    return path.relative_to(SRC).parts[0].removesuffix(".py")


def _is_unit(name: str) -> bool:
    return (SRC / f"{name}.py").is_file() or (SRC / name / "__init__.py").is_file()


def _imports(path: Path):
    """(line, top-level unit of the package) of every import of the package's own modules."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = path.relative_to(SRC).parent.parts  # the file's package inside musclemetab
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
                parts = [*base, *(node.module.split(".") if node.module else [])]
                if not parts:  # "from .. import x" to the top: x itself, or a name of __init__
                    for alias in node.names:
                        yield node.lineno, alias.name if _is_unit(alias.name) else "__init__"
                    continue
                yield node.lineno, parts[0]
            elif node.module and node.module.split(".")[0] == "musclemetab":
                parts = node.module.split(".")[1:]
                if parts:
                    yield node.lineno, parts[0]
                else:
                    for alias in node.names:
                        yield node.lineno, alias.name if _is_unit(alias.name) else "__init__"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "musclemetab" and len(parts) > 1:
                    yield node.lineno, parts[1]


def test_every_module_is_in_a_layer():
    units = {_unit(p) for p in SRC.rglob("*.py")}
    assert units <= set(LAYER), f"modules without a layer: {sorted(units - set(LAYER))} (docs/architecture.md)"


def test_no_import_runs_back_up():
    up = []
    for path in sorted(SRC.rglob("*.py")):
        here = _unit(path)
        for line, target in _imports(path):
            if target == here:
                continue
            if target not in LAYER:  # a module of the package that is not there (moved, misspelt)
                up.append(f"{path.relative_to(SRC)}:{line} imports {target}, which is no module of the package")
            elif LAYER[target] > LAYER[here]:
                up.append(f"{path.relative_to(SRC)}:{line} imports {target}")
    assert not up, "imports that run back up: " + "; ".join(up)


#: the solver's entry points, from the top down (docs/architecture.md, "Stages and the objects
#: between them"): the file-level functions call problem.py (load_problem, solve), which calls
#: the array-level modules below it; no module below imports one above it
REDUNDANCY_TOP = [{"run", "emg_run", "estimate_run"}, {"problem"}]


def test_the_solver_modules_below_the_problem_do_not_import_it():
    """``redundancy/problem.py`` (Problem, load_problem, solve) stands above every other module of
    ``redundancy`` but the file-level entry points, which stand above it."""
    level = {name: i for i, names in enumerate(REDUNDANCY_TOP) for name in names}
    up = []
    for path in sorted((SRC / "redundancy").glob("*.py")):
        here = level.get(path.stem, len(REDUNDANCY_TOP))
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
                target = node.module.split(".")[0]
                if level.get(target, len(REDUNDANCY_TOP)) < here:
                    up.append(f"redundancy/{path.name}:{node.lineno} imports {target}")
    assert not up, "imports that run back up inside redundancy: " + "; ".join(up)

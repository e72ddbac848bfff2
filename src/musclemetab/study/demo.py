"""The example study: the example subject's three speeds, EFFORT-TEN and EFFORT-GEN.

:func:`demo_study` writes a study file for the example subject (fetched with
:func:`musclemetab.datasets.example_subject`) into the output folder and returns it;
:func:`run_demo` runs it and writes the report. ``musclemetab demo`` calls
:func:`run_demo`.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..io.atomic import atomic_write_text
from .spec import Study, load_study

__all__ = ["demo_study", "run_demo", "DEMO_WORKFLOWS"]

DEMO_WORKFLOWS = ("effort-gen", "effort-ten")


def _toml_string(value) -> str:
    return '"' + str(value).replace("\\", "\\\\").replace('"', '\\"') + '"'


def demo_study(out: str | os.PathLike = "musclemetab-demo", *, speeds=None,
               workflows=DEMO_WORKFLOWS, models: str | list[str] = "all") -> Study:
    """Write ``OUT/study.toml`` for the example subject and return the study."""
    path, text = _demo_file(out, speeds, workflows, models)
    atomic_write_text(path, text, mark=True)  # never over a study.toml of the user
    return load_study(path)


def _demo_file(out, speeds, workflows, models) -> tuple[Path, str]:
    """``OUT/study.toml`` of the example subject and its text."""
    from ..datasets import SPEEDS, example_subject

    ex = example_subject()
    speeds = list(speeds or SPEEDS)
    out = Path(out)
    models_toml = _toml_string(models) if isinstance(models, str) else "[" + ", ".join(map(_toml_string, models)) + "]"
    lines = [
        "# The example subject of musclemetab walking at three speeds (55, 100, 145 % of the",
        "# preferred speed). Written by `musclemetab demo`; run it again with `musclemetab run`.",
        'name = "example subject"',
        'output = "."',
        "workflows = [" + ", ".join(map(_toml_string, workflows)) + "]",
        f"models = {models_toml}",
        'basal = "body"',
        "",
        "[[subjects]]",
        'name = "sub1"',
        f"model = {_toml_string(ex.model)}",
        f"body_mass_kg = {ex.body_mass_kg}",
        f"height_m = {ex.height_m}",
        f"passive = {_toml_string(ex.passive_moments_mat)}",
        '# the study\'s EMG-informed tendon stiffness of this subject (triceps surae, vasti)',
        'tendon_stiffness = "example"',
    ]
    for s in speeds:
        lines += [
            "",
            "[[subjects.trials]]",
            f"name = {_toml_string(s)}",
            f"ik = {_toml_string(ex.ik[s])}",
            f"id = {_toml_string(ex.id[s])}",
            f"emg = {_toml_string(ex.emg[s])}",
        ]
    return out / "study.toml", "\n".join(lines) + "\n"


def run_demo(out: str | os.PathLike = "musclemetab-demo", *, workers: int | None = None, speeds=None,
             report: bool = True, progress: bool = True, force: bool = False, strict: bool = False,
             warm_start: bool = False, adjust=None):
    """Run the example study and write its report; returns the :class:`StudyRun` (``strict``: a
    unit with a plausibility flag fails, :func:`~.spec.strict_study`; ``warm_start``: EFFORT-TEN
    starts from the trial's EFFORT-GEN solution, :func:`~.spec.warm_start_study`; ``adjust``: a
    function of the study giving the study run, e.g. with uncertainty samples, :mod:`.uncertainty`)."""
    import threading
    import tomllib

    from .runner import run_study
    from .spec import study_from_dict

    # the study of the file, which is written once the options are applied: one refused leaves nothing
    path, text = _demo_file(out, speeds, DEMO_WORKFLOWS, "all")
    study = study_from_dict(tomllib.loads(text), base=path.parent, source=path)
    if strict:
        from .spec import strict_study

        study = strict_study(study)
    if warm_start:
        from .spec import warm_start_study

        study = warm_start_study(study, True)
    if adjust is not None:
        study = adjust(study)
    atomic_write_text(path, text, mark=True)  # never over a study.toml of the user
    figures = None
    if report:  # the plot that depends only on the package, drawn while the units run (once per machine)
        from ..report.draw import draw_package_figures

        figures = threading.Thread(target=_quietly, args=(draw_package_figures,), daemon=True)
        figures.start()
    run = run_study(study, workers=workers, progress=progress, force=force)
    if figures is not None:
        figures.join()
    if report and not run.interrupted:
        from ..report import write_report

        run.report = write_report(study.output)
    return run


def _quietly(function) -> None:
    """Run ``function``; a failure is left to the report, which then draws the figure itself."""
    try:
        function()
    except Exception:  # noqa: BLE001 - the report draws the figure and says what went wrong
        pass

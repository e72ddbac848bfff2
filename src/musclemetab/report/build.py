"""Writing the report of a study folder, and its rebuild key.

:func:`write_report` reads the folder (:mod:`.folder`), draws the figures the data support
(:mod:`.plan`, :mod:`.draw`) while it makes the page's tables, and writes the page
(:mod:`.page`) and ``figures/report.json``. The report is rebuilt only when its inputs
changed: :func:`report_key` is the SHA-256 of everything the report is drawn from, recorded in
the page and in ``figures/report.json``; the same key, the page and every figure file present
mean nothing to do. Every file is written atomically.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

from ..errors import MusclemetabError, OptionError
from .draw import FigureEntry, make_figures
from .cli_folder import read_report_input
from .folder import StudyFolder
from .page import page_tables, render_page

__all__ = ["write_report", "generate_report", "report_key", "REPORT_FILE", "FIGURES_FOLDER", "REPORT_RECORD"]

REPORT_FILE = "report.html"
FIGURES_FOLDER = "figures"
#: The record of the last report written beside its figures: key, page and figure entries.
REPORT_RECORD = "report.json"


def report_key(study, formats: Sequence[str] = ("png",), models: Sequence[str] | None = None) -> str:
    """SHA-256 of everything the report is drawn from.

    ``study``: a study folder (its path) or what :func:`~.cli_folder.read_report_input` read.
    The files of its :meth:`~.folder.StudyFolder.report_inputs` (of a study, :func:`~.folder.input_files`:
    the study's tables, every unit's ``unit.json``,
    which records the hash of each of the unit's files, ``summary.json`` among them, and the
    study file ``study.json`` names as its source; of ``analyse`` folders, their tables and
    records and the legs' solution and metabolics files), the figure formats, the models the figures
    show when asked for (``models``, the option ``--models``; the default and ``[report] models``
    follow from the source and ``study.json``), the package version
    and the report's own source (its modules and its page template).
    """
    import hashlib

    from .. import __version__
    from ..io.atomic import file_sha256

    if not isinstance(study, StudyFolder):
        study = StudyFolder(path=Path(study), settings={}, results=None, failures=None)
    h = hashlib.sha256()
    h.update(f"musclemetab {__version__}; formats {','.join(formats)}\n".encode())
    if models is not None:
        h.update(f"models {','.join(models)}\n".encode())
    here = Path(__file__).parent
    for src in sorted(here.glob("*.py")) + sorted((here / "templates").glob("*")):
        h.update(src.name.encode() + b"\0" + src.read_bytes())
    for name, f in study.report_inputs():  # with a study's, the study file its settings came from
        h.update(f"{name} {file_sha256(f) if f.is_file() else 'absent'}\n".encode())
    return h.hexdigest()


def _write_record(fig_dir: Path, key: str, page: Path, entries: Sequence[FigureEntry]) -> None:
    from ..io.atomic import atomic_write_text

    record = {"key": key, "page": page.name, "entries": [
        {"name": e.name, "title": e.title, "caption": e.caption, "note": e.note,
         "paths": None if e.paths is None else {k: str(v) for k, v in e.paths.items()},
         "layout_problems": list(e.problems)} for e in entries]}
    atomic_write_text(fig_dir / REPORT_RECORD, json.dumps(record, indent=1) + "\n", mark=True)


def _recorded_entries(out: Path, key: str) -> list[FigureEntry] | None:
    """The figure entries of the report at ``out`` if it was written from inputs with ``key``
    and its figure files are all there."""
    from ..io.jsonfile import read_json_object

    record = out.parent / FIGURES_FOLDER / REPORT_RECORD
    if not (out.is_file() and record.is_file()):
        return None
    try:
        rec = read_json_object(record, remedy="the report is rebuilt")
    except MusclemetabError:
        return None
    if rec.get("key") != key or rec.get("page") != out.name:
        return None
    try:
        entries = [FigureEntry(e["name"], e["title"], e.get("caption", ""),
                               None if e.get("paths") is None else {k: Path(v) for k, v in e["paths"].items()},
                               e.get("note"), problems=list(e.get("layout_problems") or []))
                   for e in rec.get("entries") or []]
    except (KeyError, TypeError, AttributeError):
        return None
    if any(e.paths is not None and not all(p.is_file() for p in e.paths.values()) for e in entries):
        return None
    if f'content="{key}"' not in out.read_text(encoding="utf-8", errors="replace"):
        return None
    return entries


def figures_folder(out: Path) -> Path:
    """The folder of the figures beside the page ``out``: ``figures``, a real folder inside the
    page's folder. Raises :class:`OptionError` when it is a symbolic link or leads out of the
    page's folder (the report never writes or removes files outside its output folder)."""
    base = out.parent
    fig_dir = base / FIGURES_FOLDER
    if fig_dir.is_symlink() or (fig_dir.exists() and not fig_dir.is_dir()):
        what = f"a symbolic link to {os.readlink(fig_dir)}" if fig_dir.is_symlink() else "not a folder"
        raise OptionError(
            f"{fig_dir}: {what}; the report writes its figures only into a folder '{FIGURES_FOLDER}' of its own "
            f"beside the page: remove {fig_dir} or write the page elsewhere (--out)")
    if fig_dir.exists():
        try:
            fig_dir.resolve().relative_to(base.resolve())
        except ValueError:
            raise OptionError(f"{fig_dir}: leads out of {base} (to {fig_dir.resolve()}); the report writes only "
                              "inside its output folder: write the page elsewhere (--out)") from None
    return fig_dir


def _recorded_files(fig_dir: Path) -> set[str]:
    """The file names of the figures the last report wrote into ``fig_dir`` (its record,
    ``report.json``); none when there is no readable record."""
    from ..io.jsonfile import read_json_object

    record = fig_dir / REPORT_RECORD
    if not record.is_file():
        return set()
    try:
        rec = read_json_object(record, remedy="the report is rebuilt")
        return {Path(str(p)).name for e in rec.get("entries") or [] for p in (e.get("paths") or {}).values()}
    except (MusclemetabError, AttributeError, TypeError):
        return set()


def generate_report(study_dir, out: str | os.PathLike | None = None, *,
                    formats: Sequence[str] = ("png",), force: bool = False,
                    workers: int | None = None, models=None) -> tuple[Path, list[FigureEntry]]:
    """:func:`write_report`, also returning the figure entries (files written or notes)."""
    from ..io.atomic import atomic_write_text

    study = read_report_input(study_dir, models=models)
    if out is None and len(study.sources) > 1:
        raise OptionError(f"the report of {len(study.sources)} analyse folders goes to one page: give --out DIR "
                          "(the page DIR/report.html, its figures in DIR/figures) or --out FILE.html")
    out = page_path(out) if out is not None else study.path / REPORT_FILE
    formats = tuple(dict.fromkeys(("png", *formats)))  # the page embeds the PNG
    key = report_key(study, formats, models=study.figure_models)
    fig_dir = figures_folder(out)
    if not force:
        recorded = _recorded_entries(out, key)
        if recorded is not None:
            return out, recorded
    _check_report_files(out, fig_dir)
    tables: dict = {}
    entries = make_figures(study, fig_dir, formats, workers, meanwhile=lambda: tables.update(page_tables(study)),
                           written_before=_recorded_files(fig_dir))
    atomic_write_text(out, render_page(study, entries, figures_rel=FIGURES_FOLDER, key=key, tables=tables),
                      mark=True)
    _write_record(fig_dir, key, out, entries)
    return out, entries


#: the names of an HTML page; any other ``out`` names a folder
PAGE_SUFFIXES = (".html", ".htm")


def page_path(out: str | os.PathLike) -> Path:
    """The page that ``out`` names: ``out`` itself when it ends in ``.html`` (or ``.htm``) and is
    not a folder, else ``out/report.html`` in the folder ``out`` (made when the page is
    written), so that nothing is written beside a folder the user named."""
    out = Path(out)
    if out.suffix.lower() in PAGE_SUFFIXES and not out.is_dir():
        return out
    if out.exists() and not out.is_dir():
        raise OptionError(f"--out {out}: a file that is not an HTML page (.html); name a folder (the page goes to "
                          f"FOLDER/{REPORT_FILE}, its figures to FOLDER/{FIGURES_FOLDER}) or a file ending in .html")
    return out / REPORT_FILE


def _check_report_files(out: Path, fig_dir: Path) -> None:
    """Refuse (:class:`OptionError` naming the file), before any figure is drawn, a page or record
    file in the report's place that the package did not write or that was changed since
    (:func:`musclemetab.io.atomic.check_replaceable`; a figure's file is checked when the figure
    is saved, :func:`~.draw.make_figures`)."""
    from ..io.atomic import check_output_folder, check_replaceable

    check_output_folder(out.parent, "the page's folder")  # below a file, or not writable: one line
    check_replaceable(out.parent, [out.name])
    check_replaceable(fig_dir, [REPORT_RECORD])


def write_report(study_dir, out: str | os.PathLike | None = None, *,
                 formats: Sequence[str] = ("png",), force: bool = False, workers: int | None = None,
                 models=None) -> Path:
    """Write the figures and the HTML report of a study folder; return the report's path.

    ``study_dir`` is a study folder, or one or more output folders of ``musclemetab analyse``
    (a list; :func:`~.cli_folder.read_report_input`), reported as a study of their trials.
    ``out`` is the HTML file (a name ending in ``.html``) or a folder for it (``out/report.html``,
    :func:`page_path`); default ``study_dir/report.html``; required for several analyse
    folders. The figures are written to the folder ``figures`` beside the page (PNG;
    ``formats=("png", "svg")`` adds SVG). Everything is written atomically. The report is
    rebuilt only when its inputs changed (their content hash, :func:`report_key`, is recorded
    in the page and in ``figures/report.json``) or when ``force`` is true. ``workers`` processes draw the figures (see
    :func:`~.draw.make_figures`). ``models``: the metabolic models the figures show (names or
    ``"all"``; default the paper's six, UM03, BH04, HO06, LW07, UM10, UC16, or ``[report]
    models`` of the study file; LW05 and MA68 only when named); the tables list every model
    of the study. Raises :class:`InputFileError` when the folder or its
    ``results.csv`` is missing.
    """
    return generate_report(study_dir, out, formats=formats, force=force, workers=workers, models=models)[0]

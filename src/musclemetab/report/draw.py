"""Drawing the report's figures: side by side in forked copies of the process, largest first.

:func:`make_figures` draws every :class:`~.plan.FigurePlan` of a study into a folder and
returns one :class:`FigureEntry` per figure: its files, or the note saying why it is not
drawn. The report's process and ``workers - 1`` copies of it (the ``fork`` start method) take
the next figure when they are free, the largest first so that they end together. The size of
a figure is the processor time its last drawing took on this machine (measured in the process
that drew it and kept in the package's cache, :func:`draw_costs`); a figure never drawn here
counts as the largest. A copy that dies leaves its figure to the report's process; Ctrl-C ends
the copies quietly.

The figures that depend only on the package (the Figure-2 plot) are drawn once per version of
the code drawing them and kept in the package's cache (:func:`figure_cache`), with the
SHA-256 of their content beside them.
"""

from __future__ import annotations

import math
import os
import signal
import time
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import MusclemetabError, OptionError
from .folder import StudyFolder
from .plan import FIGURE2_CAPTION, FigurePlan, plan_figures

__all__ = ["FigureEntry", "make_figures", "draw_figure", "default_workers", "draw_costs", "figure_cache",
           "draw_package_figures"]

#: The figure that depends only on the package (drawn once, then copied from the cache).
PACKAGE_FIGURE = "figure2_soleus"
#: The cache file of the measured drawing times, in the cache's folder of figures.
COSTS_FILE = "draw_costs.json"


@dataclass
class FigureEntry:
    """One figure of the report: its files, or the note saying why it is not drawn;
    ``draw_s``: the processor time (s) of drawing it (or of copying it from the cache);
    ``problems``: its texts cut by its edge or drawn over one another
    (:func:`~.layout_check.figure_problems` of the figure as saved; none expected)."""

    name: str
    title: str
    caption: str = ""
    paths: dict | None = None
    note: str | None = None
    draw_s: float | None = None
    problems: list = field(default_factory=list)


# ------------------------------------------------------------------ one figure
def draw_figure(study: StudyFolder, fig_dir: Path, formats: Sequence[str], name: str,
                plan: FigurePlan | None = None) -> FigureEntry:
    """Draw and save one figure of the report (``plan``: its entry of
    :func:`~.plan.plan_figures`, made here when not given)."""
    from .figures import save_figure
    from .layout_check import figure_problems

    if plan is None:
        plan = plan_figures(study)[name]
    if plan.draw is None:
        return FigureEntry(name, plan.title, note=plan.note)
    start = time.process_time()
    cache = figure_cache(name)
    if cache is not None:
        formats = tuple(cache)  # PNG only: the figure is the package's (save_figure2 writes SVG or PDF)
        cached = _read_cache(cache)
        if cached is not None:
            from ..io.atomic import atomic_write_bytes

            paths = {fmt: atomic_write_bytes(Path(fig_dir) / f"{name}.{fmt}", data, mark=True)
                     for fmt, data in cached.items()}
            return FigureEntry(name, plan.title, caption=FIGURE2_CAPTION, paths=paths,
                               draw_s=time.process_time() - start)
    try:
        fig, caption = plan.draw()
    except MusclemetabError as exc:  # the data cannot make it: its note (the time spent finding out kept)
        return FigureEntry(name, plan.title, note=study.short(exc), draw_s=time.process_time() - start)
    paths = save_figure(fig, fig_dir, name, formats=formats)
    problems = figure_problems(fig, drawn=True)  # as saved: every text inside the figure, none over another
    if cache is not None:
        _store_in_cache(paths, cache)
    return FigureEntry(name, plan.title, caption=caption, paths=paths, draw_s=time.process_time() - start,
                       problems=problems)


# ------------------------------------------------------------------ the cache of the package's figures
def _cache_folder() -> Path:
    from ..cache import cache_folder

    return cache_folder("figures")


def figure_cache(name: str) -> dict[str, Path] | None:
    """The cache file of a figure that depends only on the package (Figure 2, as PNG),
    keyed by the source of the modules drawing it and the matplotlib version; ``None`` for
    other figures."""
    if name != PACKAGE_FIGURE:
        return None
    import hashlib
    from importlib.metadata import version

    from .. import colours, metabolics, muscle
    from . import figures, plan

    h = hashlib.sha256(f"{name} matplotlib {version('matplotlib')}\n".encode())
    here = Path(figures.__file__).parent  # the figure modules (figures.py gathers fig_*.py)
    sources = [Path(colours.__file__), *sorted(here.glob("fig*.py")), Path(plan.__file__)]
    for package in (metabolics, muscle):
        sources += sorted(Path(package.__file__).parent.glob("*.py"))
    for src in sources:
        h.update(src.name.encode() + b"\0" + src.read_bytes())
    return {"png": _cache_folder() / f"{name}-{h.hexdigest()[:32]}.png"}


def draw_package_figures() -> None:
    """Draw the figures that depend only on the package (the Figure-2 plot) into the cache,
    unless it holds them already; a report then copies them instead of drawing them.
    ``musclemetab demo`` calls it while the study's units run, so that its report does not
    wait for the plot the first time."""
    import tempfile

    from .figures import save_figure
    from .plan import figure2_figure

    cache = figure_cache(PACKAGE_FIGURE)
    if _read_cache(cache) is not None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        fig, _ = figure2_figure()
        _store_in_cache(save_figure(fig, tmp, PACKAGE_FIGURE, formats=tuple(cache)), cache)


def _checksum_file(path: Path) -> Path:
    """The file beside a cached figure holding the SHA-256 of its content."""
    return path.with_name(path.name + ".sha256")


def _read_cache(cache: dict) -> dict[str, bytes] | None:
    """The content of a figure's cache files (format -> bytes), or ``None`` when one is
    missing or does not match the SHA-256 stored beside it (truncated, corrupted, or written
    by a version without the checksum): the figure is then drawn again and the cache rewritten."""
    import hashlib

    out = {}
    for fmt, path in cache.items():
        try:
            data = path.read_bytes()
            expected = _checksum_file(path).read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError):
            return None
        if hashlib.sha256(data).hexdigest() != expected:
            return None
        out[fmt] = data
    return out


def _store_in_cache(paths: dict, cache: dict) -> None:
    """Copy a drawn figure's files into the cache, each with the SHA-256 of its content
    beside it (see :func:`_read_cache`); a cache that cannot be written is skipped."""
    import hashlib
    import warnings

    from ..errors import CacheWarning
    from ..io.atomic import atomic_write_bytes, atomic_write_text

    try:
        for fmt, target in cache.items():
            target.parent.mkdir(parents=True, exist_ok=True)
            data = Path(paths[fmt]).read_bytes()
            atomic_write_bytes(target, data)
            atomic_write_text(_checksum_file(target), hashlib.sha256(data).hexdigest() + "\n")
    except OSError as exc:
        warnings.warn(f"figure cache {target.parent}: not written ({exc}); the figure is drawn again next time",
                      CacheWarning, stacklevel=3)


# ------------------------------------------------------------------ the drawing costs
def _cost_key(name: str) -> str:
    """The name a drawing time is kept under: the package's figure copied from the cache
    (when it is there) costs another time than drawn."""
    cache = figure_cache(name)
    if cache is not None and all(f.is_file() for f in cache.values()):
        return f"{name} (cached)"
    return name


def draw_costs() -> dict[str, float]:
    """The processor time (s) of the last drawing of each figure on this machine (the
    package's cache, :data:`COSTS_FILE`), by :func:`_cost_key`; ``{}`` when none is kept."""
    import json

    try:
        costs = json.loads((_cache_folder() / COSTS_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(costs, dict):
        return {}
    return {str(k): float(v) for k, v in costs.items() if isinstance(v, (int, float))}


def _keep_costs(entries: Sequence[FigureEntry], keys: dict[str, str]) -> None:
    """Keep the drawing times of ``entries`` (``keys``: each figure's :func:`_cost_key`
    before it was drawn) with the others in the cache; a cache that cannot be written is
    skipped (the figures are then ordered as before)."""
    import json

    from ..io.atomic import atomic_write_text

    measured = {keys[e.name]: round(e.draw_s, 4) for e in entries if e.draw_s is not None}
    if not measured:
        return
    costs = {**draw_costs(), **measured}
    try:
        _cache_folder().mkdir(parents=True, exist_ok=True)
        atomic_write_text(_cache_folder() / COSTS_FILE, json.dumps(costs, indent=1, sort_keys=True) + "\n")
    except OSError:
        pass


# ------------------------------------------------------------------ the processes
def default_workers(figures: int | None = None) -> int:
    """Processes drawing the figures by default: the cores this process may use, at most one
    per figure (``figures``), at least 1.

    The machine's load is not read: a snapshot of it changes from one moment to the next,
    and the load average counts the last minute's work (a report drawn just before among
    it). Another process costs little (it starts as a copy of this one and draws its share;
    this process draws too), so on a busy machine two processes take turns with the others
    no slower than one.
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, figures if figures is not None else cores))


def _prepare_fork() -> None:
    """Load, once before forking, what every drawing process needs: the PNG writer, the font
    and its metrics (the drawing modules are loaded by :func:`make_figures`)."""
    import matplotlib
    from PIL import PngImagePlugin  # noqa: F401

    from .figures import _new_figure

    fig = _new_figure(1.0, 1.0)
    fig.text(0.5, 0.5, "0123456789.-% (W/kg)", fontsize=9)
    with matplotlib.rc_context({"text.hinting": "no_hinting"}):  # as save_figure draws
        fig.canvas.draw()


def _draw_share(study: StudyFolder, fig_dir: Path, formats: Sequence[str], order: Sequence[str], plans: dict,
                counter, send: Callable[[str, FigureEntry | None], None]) -> None:
    """Draw the figures of ``order`` claimed one at a time through the shared ``counter``
    (so that every process takes the next figure when it is free); ``send`` each entry, or
    ``None`` for a figure that raised (the report's process then draws it and raises)."""
    while True:
        with counter.get_lock():
            i = counter.value
            counter.value += 1
        if i >= len(order):
            return
        try:
            entry = draw_figure(study, fig_dir, formats, order[i], plans[order[i]])
        except Exception:  # noqa: BLE001 - drawn again where the error reaches the caller
            entry = None
        send(order[i], entry)


def _child_share(conn, *args) -> None:
    """A forked process's part of :func:`_draw_share`: entries sent through ``conn``. Ctrl-C
    (which reaches every process of the command) or the report's process gone end it quietly:
    the report's process says what happened. SIGTERM (the report's process ending its copies)
    ends it as the operating system does: the forked copy does not keep the report's process's
    handler, which would stop it with a traceback."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        _draw_share(*args, send=lambda name, entry: conn.send((name, entry)))
    except (KeyboardInterrupt, BrokenPipeError):
        pass
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C arriving now has nothing left to stop
        conn.close()


def make_figures(study: StudyFolder, fig_dir: str | os.PathLike, formats: Sequence[str] = ("png",),
                 workers: int | None = None, meanwhile: Callable[[], object] | None = None,
                 written_before: Collection[str] = ()) -> list[FigureEntry]:
    """Draw the figures the study's data support and save them in ``fig_dir`` (``formats``:
    PNG, and SVG when asked for).

    ``workers`` processes draw the figures side by side (default :func:`default_workers`):
    this process and ``workers - 1`` copies of it (the ``fork`` start method; where it is not
    available, this process draws every figure). Each takes the next figure, largest first
    (:func:`draw_costs`), when it is free; this process first runs ``meanwhile`` (the page's
    tables). Returns one :class:`FigureEntry` per figure of :func:`~.plan.plan_figures`, with
    the file paths or the note saying why the figure is not drawn. The files of a figure not
    drawn are removed from ``fig_dir`` when an earlier report wrote them (``written_before``:
    their file names, as its record lists them, and ``fig_dir``'s list of the package's files
    holds them unchanged), so that no figure of an earlier report remains; no other file is
    removed. A file in the place of a drawn figure that the package did not write, or that was
    changed since, is not replaced (:class:`OptionError` naming it, when the figure is saved).
    """
    import gc
    import multiprocessing

    fig_dir = Path(fig_dir)
    plans = plan_figures(study)
    drawn = [n for n in plans if plans[n].draw is not None]
    workers = default_workers(len(drawn)) if workers is None else int(workers)
    if workers < 1:
        raise OptionError(f"workers (--workers) must be at least 1, not {workers}")
    workers = min(workers, len(drawn))
    keys = {n: _cost_key(n) for n in drawn}
    costs = draw_costs()
    order = sorted(drawn, key=lambda n: -costs.get(keys[n], math.inf))  # stable: never drawn first, in page order
    formats = tuple(formats)
    entries: dict[str, FigureEntry] = {}
    children = []
    # The objects made so far (modules, the study's tables) live until the end: frozen, the
    # garbage collector does not go through them at every full collection while the figures'
    # objects come and go (half a second in one process), and the forked copies do not
    # touch (and so copy) their memory pages. Unfrozen at the end.
    if drawn:
        import matplotlib.backends.backend_agg  # noqa: F401  - the drawing modules among them
        import matplotlib.figure  # noqa: F401
        import matplotlib.legend  # noqa: F401
    gc.freeze()
    try:
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            ctx = multiprocessing.get_context("fork")
            counter = ctx.Value("i", 0)
            _prepare_fork()
            for _ in range(workers - 1):
                receive, send = ctx.Pipe(duplex=False)
                child = ctx.Process(target=_child_share, args=(send, study, fig_dir, formats, order, plans,
                                                               counter), daemon=True)
                child.start()
                send.close()
                children.append((child, receive))
        if meanwhile is not None:
            meanwhile()
        if children:
            _draw_share(study, fig_dir, formats, order, plans, counter,
                        send=lambda name, entry: entries.__setitem__(name, entry))
            for child, receive in children:
                while True:
                    try:
                        name, entry = receive.recv()
                    except EOFError:  # the process is done (or died: its figures are drawn below)
                        break
                    entries[name] = entry
                receive.close()
                child.join()
        for n in plans:
            if entries.get(n) is None:
                entries[n] = draw_figure(study, fig_dir, formats, n, plans[n])
    finally:
        for child, _ in children:
            if child.is_alive():
                child.terminate()
                child.join()
        gc.unfreeze()
    _keep_costs(list(entries.values()), keys)
    from ..io.atomic import is_written

    written_before = set(written_before)
    for e in entries.values():
        for ext in ("png", "svg"):
            stale = fig_dir / f"{e.name}.{ext}"
            if (e.paths is None or ext not in e.paths) and stale.name in written_before and is_written(fig_dir,
                                                                                                      stale.name):
                stale.unlink()  # the package's file, unchanged (a file put in its place stays)
    return [entries[n] for n in plans]

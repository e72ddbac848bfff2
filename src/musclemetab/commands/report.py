"""``musclemetab report``: the figures and the HTML report of a study folder, or of the
command line's ``analyse`` output folders.

    musclemetab report DIR [--out OUT] [--svg] [--force] [--workers N] [--models M1,M2|all]
    musclemetab report A [A2 ...] [--out OUT] ...

Writes ``DIR/figures/<name>.png`` (and ``.svg`` with ``--svg``) for every figure the data support, and
``DIR/report.html`` (or ``OUT/report.html`` in a folder ``OUT``, or ``OUT`` itself when it ends in
``.html``, with its figures in ``figures/`` beside it): one
self-contained page (see :mod:`musclemetab.report.build`). Output folders of ``musclemetab
analyse`` (with the solution and metabolics folders they record) give the page a study of
their trials would give (:mod:`musclemetab.report.cli_folder`); several of them need ``--out``.
"""

from __future__ import annotations

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add the ``report`` subcommand to an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "report",
        help="figures and a self-contained HTML report of a study folder or of analyse output folders",
        description=(
            "Read a study folder written by 'musclemetab run' (study.json, results.csv, failures.csv, "
            "units/) and write its figures (DIR/figures/<name>.png, and .svg with --svg: excitations and fiber lengths, "
            "estimated vs measured rate, group rates over the cycle, every muscle over the cycle (heat map), "
            "whole-body rate across speeds, stance and swing shares, group shares, per-muscle ranking; the paper's "
            "six metabolic models unless --models names others) and one HTML page, DIR/report.html, with the settings, the "
            "method, the result tables (W/kg, J/(kg m), %), the figures embedded, the failures and the "
            "software versions. A figure the data do not support is replaced by a note. The report is rebuilt only "
            "when its inputs changed (content hash). Instead of a study folder, give one or more output folders of "
            "'musclemetab analyse' (of one leg, or the parent of r/ and l/): the solution and metabolics folders "
            "each records are read with it, and the page shows what a study of those trials shows (subject: the "
            "model file's name; trial: the IK file's name); several folders need --out."
        ),
    )
    p.add_argument("study_dir", metavar="DIR", nargs="+",
                   help="study folder (holding results.csv and study.json), or one or more output folders of "
                   "'musclemetab analyse' (holding analyse.json)")
    p.add_argument(
        "--out", metavar="OUT",
        help="folder of the page (OUT/report.html, its figures in OUT/figures), or the HTML file to write (a name "
        "ending in .html; the figures go to a folder 'figures' beside it); default DIR/report.html",
    )
    p.add_argument("--svg", action="store_true", help="also write every figure as SVG (slower)")
    p.add_argument("--force", action="store_true",
                   help="redraw even when the inputs did not change (default: the report is rebuilt only when "
                   "the study's results, units or the package changed)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="processes drawing the figures side by side (default: the cores this process may use, at "
                   "most one per figure; 1 draws them one after the other in this process)")
    p.add_argument("--models", metavar="M1,M2",
                   help="metabolic models the figures show, e.g. 'all,LW05,MA68' ('all': the paper's six, "
                   "UM03, BH04, HO06, LW07, UM10, UC16; default: those six, or [report] models of the study "
                   "file); the tables list every model of the study")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab report`` (``args`` from :func:`add_parser`)."""
    from ..report.build import FIGURES_FOLDER, generate_report

    formats = ("png", "svg") if args.svg else ("png",)
    out, entries = generate_report(args.study_dir, args.out, formats=formats, force=args.force,
                                  workers=args.workers, models=args.models)
    drawn = [e.name for e in entries if e.paths is not None]
    print(f"report: {len(drawn)} of {len(entries)} figures -> {out.parent / FIGURES_FOLDER}; page -> {out}")
    notes = {e.note for e in entries if e.paths is None}
    if not drawn and len(notes) == 1:  # one reason for every figure (no unit succeeded): said once
        print(f"  no figure drawn: {notes.pop()}")
    else:
        for e in entries:
            if e.paths is None:
                print(f"  not drawn: {e.name}: {e.note}")
    import warnings

    from ..errors import FigureLayoutWarning

    for e in entries:  # a text cut by the figure's edge or drawn over another (figures/report.json too)
        for problem in e.problems:
            warnings.warn(f"figure {e.name}: {problem}", FigureLayoutWarning, stacklevel=1)
    return 0

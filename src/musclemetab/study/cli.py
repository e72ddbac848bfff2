"""``musclemetab run`` (a study file) and ``musclemetab demo`` (the example study)."""

from __future__ import annotations

__all__ = ["add_run_parser", "add_demo_parser", "run_command", "demo_command"]


def _common(p) -> None:
    p.add_argument("--workers", type=int, metavar="N",
                   help="parallel processes (default: the number of CPUs); 1 runs in this process")
    p.add_argument("--force", action="store_true", help="run every unit again, even those up to date")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def add_run_parser(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run a study: subjects x trials x workflows x metabolic models",
        description=(
            "Run every unit (subject x trial x workflow) of a TOML study file: solve, metabolic models, gait "
            "phases and muscle groups. Resumable: units whose inputs and settings are unchanged and whose "
            "outputs are complete are skipped; failed units are run again. Writes units/<subject>/<trial>/"
            "<workflow>/, results.csv and results.parquet (one row per subject x trial x workflow x model), "
            "failures.csv and study.json in the study's output folder."
        ),
    )
    p.add_argument("study", metavar="STUDY.toml", help="study file")
    p.add_argument("--out", metavar="DIR", help="output folder (default: the study file's 'output')")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask cluster (tcp://host:port); needs pip install 'musclemetab[dask]'")
    p.add_argument("--report", action="store_true", help="also write the figures and report.html")
    _common(p)
    p.set_defaults(func=run_command)


def add_demo_parser(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="the example subject at three speeds: results, figures and report",
        description=(
            "Run the example subject's three walking speeds with EFFORT-TEN and EFFORT-GEN and all six study "
            "metabolic models, then write the results table, the figures and report.html. The example data "
            "are downloaded on first use (or read from $MUSCLEMETAB_DATA)."
        ),
    )
    p.add_argument("--out", default="musclemetab-demo", metavar="DIR", help="output folder (default musclemetab-demo)")
    p.add_argument("--speeds", nargs="+", choices=("slow", "normal", "fast"), help="a subset of the speeds")
    _common(p)
    p.set_defaults(func=demo_command)


def _print_run(run, command: str) -> None:
    print(f"{command}: {run.summary_line()}")
    for label, reason in run.failed.items():
        if label not in run.interrupted:
            print(f"{command}: failed {label}: {reason}")
    if run.removed_partials:
        print(f"{command}: removed {len(run.removed_partials)} unfinished unit folder(s) left by an earlier run")
    report = getattr(run, "report", None)
    if report:
        print(f"{command}: report -> {report}")


def _status(run) -> int:
    """Exit status: 130 after Ctrl-C, 1 when a unit failed, 0 otherwise."""
    if run.interrupted:
        import sys

        print(f"musclemetab: interrupted; {len(run.interrupted)} unit(s) marked interrupted, no new unit started. "
              "Run the same command again to finish the study", file=sys.stderr)
        return 130
    return 1 if run.failed else 0


def run_command(args) -> int:
    from .runner import run_study
    from .spec import load_study

    study = load_study(args.study, output=args.out)
    run = run_study(study, workers=args.workers, scheduler=args.scheduler, force=args.force,
                    progress=not args.no_progress)
    if args.report and not run.interrupted:
        from ..report import write_report

        run.report = write_report(study.output)
    _print_run(run, "run")
    return _status(run)


def demo_command(args) -> int:
    from .demo import run_demo

    run = run_demo(args.out, workers=args.workers, speeds=args.speeds, progress=not args.no_progress,
                   force=args.force)
    _print_run(run, "demo")
    if run.interrupted:
        return _status(run)
    if not run.failed and run.results is not None and len(run.results):
        table = run.results.pivot_table(index="model", columns=["workflow", "trial"], values="mean_W_per_kg")
        trials = list(dict.fromkeys(run.results.sort_values("speed_m_per_s")["trial"]))  # by speed
        table = table.reindex(columns=sorted(table.columns, key=lambda c: (c[0], trials.index(c[1]))))
        print("\nwhole-body metabolic rate, W/kg (two legs + 1.2 W/kg basal):")
        print(table.round(2).to_string())
    return _status(run)

"""``musclemetab demo``: the example study (:func:`musclemetab.study.demo.run_demo`)."""

from __future__ import annotations

from .options import add_study_arguments
from .run import (add_uncertainty_arguments, add_warm_start_arguments, apply_start_arguments,
                  apply_uncertainty_arguments, exit_status, print_run, print_whole_body)

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
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
    add_warm_start_arguments(p)
    add_study_arguments(p)
    add_uncertainty_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab demo`` (``args`` from :func:`add_parser`)."""
    from ..io.atomic import check_output_folder
    from ..study.demo import run_demo

    check_output_folder(args.out)  # a file, or a folder that cannot be written: one line before any work
    result = run_demo(args.out, workers=args.workers, speeds=args.speeds, progress=not (args.no_progress or args.quiet),
                      force=args.force, strict=args.strict, warm_start=bool(args.warm_start),
                      adjust=lambda study: apply_uncertainty_arguments(apply_start_arguments(study, args), args))
    print_run(result, "demo")
    if result.interrupted:
        return exit_status(result)
    if not result.failed and result.results is not None and len(result.results):
        by_speed = result.results.sort_values(["workflow", "speed_m_per_s"], kind="stable")
        print_whole_body(by_speed, keys=("workflow", "trial"))
    return exit_status(result)

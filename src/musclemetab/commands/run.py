"""``musclemetab run``: every unit of a study file (:func:`musclemetab.study.runner.run_study`)."""

from __future__ import annotations

from .options import add_study_arguments

__all__ = ["add_parser", "run", "print_run", "print_whole_body", "exit_status", "add_warm_start_arguments",
           "apply_start_arguments", "add_uncertainty_arguments", "apply_uncertainty_arguments"]


def add_parser(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run a study: subjects x trials x workflows x metabolic models",
        description=(
            "Run every unit (subject x trial x workflow) of a TOML study file: solve, metabolic models, gait "
            "phases and muscle groups. Resumable: units whose inputs and settings are unchanged and whose "
            "outputs are complete are skipped; failed units are run again. Writes units/<subject>/<trial>/"
            "<workflow>/, results.csv (and results.parquet with the parquet extra; one row per subject x trial x workflow x model), "
            "failures.csv and study.json in the study's output folder."
        ),
    )
    p.add_argument("study", metavar="STUDY.toml", help="study file")
    p.add_argument("--out", metavar="DIR", help="output folder (default: the study file's 'output')")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask cluster (tcp://host:port); needs pip install 'musclemetab[dask]'")
    p.add_argument("--report", action="store_true", help="also write the figures and report.html")
    add_warm_start_arguments(p)
    add_study_arguments(p)
    add_uncertainty_arguments(p)
    p.set_defaults(func=run)


def add_warm_start_arguments(p) -> None:
    """``--warm-start``/``--cold-start`` and ``--best-start``: the study file's ``[solver] warm_start``
    and ``best_start`` (``run`` and ``demo``)."""
    from ..settings import SWITCH_KEYS

    key = SWITCH_KEYS["warm_start"]
    group = p.add_mutually_exclusive_group()
    group.add_argument(key.on_option, dest="warm_start", action="store_const", const=True, default=None,
                       help="start a trial's EFFORT-CAL and EFFORT-TEN solves from the solution of the workflow "
                            "before them, as the study file's [solver] warm_start = true: with the study's "
                            "stop ([solver] stop = \"authors\") about half the solver time of those units, with the "
                            "default stop no faster (docs/solver.md); the results may differ (another local optimum, "
                            "docs/study.md)")
    group.add_argument(key.off_option, dest="warm_start", action="store_const", const=False,
                       help="start every solve from static optimisation (the default), as [solver] warm_start = false")
    p.add_argument(SWITCH_KEYS["best_start"].on_option, action="store_true",
                   help="solve a trial's EFFORT-CAL and EFFORT-TEN twice, from static optimisation and from the "
                        "solution of the workflow before them, and keep the lower objective, as the study file's "
                        "[solver] best_start = true: unit.json 'starts' records both starts' objectives and how far "
                        "their whole-body rates differ (a problem with several optima, docs/study.md)")


def apply_start_arguments(study, args):
    """``study`` with ``--best-start`` applied (:func:`add_warm_start_arguments`; ``--warm-start`` and
    ``--cold-start`` are applied by the caller)."""
    if getattr(args, "best_start", False):
        from ..study.spec import best_start_study

        study = best_start_study(study, True)
    return study


def add_uncertainty_arguments(parser) -> None:
    """``--uncertainty N``, ``--uncertainty-seed SEED``, ``--uncertainty-priors FILE`` and ``--sensitivity`` of the
    commands that run a study (``run``, ``demo``); :func:`apply_uncertainty_arguments` applies them."""
    from .options import number_option

    number_option(parser, "--uncertainty", "samples", metavar="N",
                  help="uncertainty bands: N samples of the muscle properties for every trial (the study file's "
                  "[uncertainty] samples; 0: none; docs/uncertainty.md)")
    number_option(parser, "--uncertainty-seed", "seed", metavar="SEED",
                  help="seed of the uncertainty samples (default: the study file's, else 1)")
    parser.add_argument("--uncertainty-priors", metavar="FILE",
                        help="CSV of priors (parameter,distribution,spread,muscle,source) replacing the package's rows")
    from ..settings import SWITCH_KEYS

    parser.add_argument(SWITCH_KEYS["sensitivity"].on_option, dest="sensitivity", action="store_true",
                        help="each effort trial unit also writes sensitivity.csv, the derivative of each rate per "
                        "log of each muscle parameter at the optimum, and the report ranks them (the study file's "
                        "[uncertainty] sensitivity = true; one leg, forward fiber dynamics; about a minute per unit of 40 muscles; "
                        "docs/uncertainty.md)")
    parser.add_argument(SWITCH_KEYS["keep_flagged"].on_option, dest="keep_flagged", action="store_true",
                        help="the uncertainty bands also take the samples with a plausibility flag (huge reserves, "
                        "saturated muscles...); by default they are left out and listed (the study file's "
                        "[uncertainty] keep_flagged = true; docs/uncertainty.md)")


def apply_uncertainty_arguments(study, args):
    """``study`` with the ``--uncertainty...`` and ``--sensitivity`` options of ``args`` (checked) applied."""
    from ..study.uncertainty import with_uncertainty
    from .options import check_number_options

    check_number_options(args)
    if getattr(args, "sensitivity", False):
        from ..study.spec import sensitivity_study

        study = sensitivity_study(study, True)
    samples, seed, priors = (getattr(args, k, None) for k in ("uncertainty", "uncertainty_seed", "uncertainty_priors"))
    keep = True if getattr(args, "keep_flagged", False) else None
    if samples is None and seed is None and priors is None and keep is None:
        return study
    return with_uncertainty(study, samples, seed, priors, keep_flagged=keep)


def print_run(run, command: str) -> None:
    """Print what a study run did (``command``: the command's name, first on every line; each
    failed unit's line, with its reason, on standard error)."""
    import sys

    print(f"{command}: {run.summary_line()}")
    for label, reason in run.failed.items():
        if label not in run.interrupted:
            print(f"{command}: failed {label}: {reason}", file=sys.stderr)
    if run.removed_partials:
        print(f"{command}: removed {len(run.removed_partials)} unfinished unit folder(s) left by an earlier run")
    report = getattr(run, "report", None)
    if report:
        print(f"{command}: report -> {report}")


def exit_status(run) -> int:
    """Exit status: 130 after Ctrl-C (143 after SIGTERM), 1 when a unit failed, 0 otherwise."""
    if run.interrupted:
        import sys

        from . import INTERRUPTED_STATUS, TERMINATED_STATUS
        from ..processes import terminated

        print(f"musclemetab: {'terminated' if terminated() else 'interrupted'}; {len(run.interrupted)} unit(s) "
              "marked interrupted, no new unit started. Run the same command again to finish the study", file=sys.stderr)
        return TERMINATED_STATUS if terminated() else INTERRUPTED_STATUS
    return 1 if run.failed else 0


def run(args) -> int:
    """Run ``musclemetab run`` (``args`` from :func:`add_parser`)."""
    from ..study.runner import run_study
    from ..study.spec import load_study

    study = load_study(args.study, output=args.out)
    if args.strict:
        from ..study.spec import strict_study

        study = strict_study(study)
    if args.warm_start is not None:
        from ..study.spec import warm_start_study

        study = warm_start_study(study, args.warm_start)
    study = apply_uncertainty_arguments(apply_start_arguments(study, args), args)
    result = run_study(study, workers=args.workers, scheduler=args.scheduler, force=args.force,
                       progress=not (args.no_progress or args.quiet))
    if args.report and not result.interrupted:
        from ..report import write_report

        result.report = write_report(study.output)
    print_run(result, "run")
    if not result.interrupted:
        print_whole_body(result.results)
    return exit_status(result)


#: the results a run prints as a table at most (more: the table's file is named instead)
PRINTED_UNITS = 12


def print_whole_body(results, limit: int = PRINTED_UNITS, keys=("subject", "trial", "workflow")) -> None:
    """Print each unit's whole-body rate of each model (W/kg, the results table's rows; the legs
    added for a subject solved on both), units as columns (``keys``, in the table's order), when
    there are at most ``limit`` of them; with uncertainty samples, each rate with its band
    (``[p05-p95]``) and, below, the samples behind the bands and those left out."""
    if results is None or not len(results):
        return
    keys = [k for k in keys if k in results.columns]
    units = results.drop_duplicates(keys)
    if len(units) > limit:
        print(f"whole-body rates of {len(units)} units: the study folder's results.csv")
        return
    band = "whole_body_W_per_kg_p05" in results.columns and results["whole_body_W_per_kg_p05"].notna().any()
    cells = results.assign(cell=[
        f"{r.whole_body_W_per_kg:.2f}" + (f" [{r.whole_body_W_per_kg_p05:.2f}-{r.whole_body_W_per_kg_p95:.2f}]"
                                           if band and r.whole_body_W_per_kg_p05 == r.whole_body_W_per_kg_p05 else "")
        for r in results.itertuples()])
    table = cells.pivot_table(index="model", columns=keys, values="cell", aggfunc="first", sort=False)
    print("\nwhole-body metabolic rate, W/kg (two legs + basal heat)"
          + (", [5-95 % band of the uncertainty samples]:" if band else ":"))
    print(table.to_string())
    if band:
        used = int(units["uncertainty_samples"].fillna(0).sum())
        left = int(units["uncertainty_rejected"].fillna(0).sum())
        print(f"uncertainty: {used} samples behind the bands, {left} left out (a plausibility flag or no "
              "convergence; results.csv uncertainty_band and uncertainty_note say how each band was taken)")

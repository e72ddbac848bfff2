"""``musclemetab calibrate-passive``: passive force-length calibration from passive moments
(:func:`musclemetab.calibration.passive.calibrate_passive`)."""

from __future__ import annotations

__all__ = ["add_parser", "run"]


def _kt_item(text: str) -> tuple[str, float]:
    import argparse

    name, sep, value = text.partition("=")
    try:
        if not sep:
            raise ValueError
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not MUSCLE=VALUE (e.g. soleus_r=20)") from None


def add_parser(sub) -> None:
    p = sub.add_parser(
        "calibrate-passive",
        help="calibrate passive force-length parameters (kPE, s0) from passive joint moments",
        description=(
            "Fit per-muscle passive force-length parameters kPE and s0 (sM = 0.6) so that the passive "
            "moments of the model's muscles match target passive moment-angle data at the ankle, knee "
            "and hip (CasADi + IPOPT). Writes DIR/passive_parameters.csv (muscle,kPE,s0,sM), "
            "DIR/fit.json (RMS moment error per joint, generic and calibrated, solver statistics) and "
            "DIR/passive_fit.png."
        ),
    )
    p.add_argument("--model", required=True, metavar="M.osim", help="OpenSim model (generic, unscaled)")
    p.add_argument(
        "--trials", required=True, metavar="DIR",
        help="folder of in-vivo passive-moment trials: per trial a .sto of target passive moments (N m) and a .mot "
        "of joint angles (deg) with the same name; each trial is recognised by its only non-zero "
        "'<coordinate>_moment' column (ankle, knee or hip flexion of the side), whatever the file names",
    )
    p.add_argument("--side", choices=("r", "l", "both"), default="r",
                   help="leg (default r): its hip, knee and ankle flexion coordinates are found from the model's "
                   "joint tree; both: each leg calibrated from its own trials (the folder holds both legs' "
                   "trials), written to DIR/r and DIR/l, and both legs' parameters in DIR/passive_parameters.csv")
    p.add_argument(
        "--tendon-stiffness", nargs="+", type=_kt_item, metavar="MUSCLE=KT",
        help="override the normalised tendon stiffness of some muscles (default 20 for soleus and "
        "gastrocnemii, 35 for the others)",
    )
    p.add_argument("--no-cache", action="store_true", help="do not read or write the geometry cache")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab calibrate-passive`` (``args`` from :func:`add_parser`)."""
    from pathlib import Path

    from ..calibration.passive import calibrate_passive, write_calibration, write_passive_parameters
    from ..io import check_output_folder

    check_output_folder(args.out)
    kt = dict(args.tendon_stiffness) if getattr(args, "tendon_stiffness", None) else None
    side = getattr(args, "side", "r")
    sides = ("r", "l") if side == "both" else (side,)
    _check_outputs(Path(args.out), side)
    # every leg is calibrated before anything is written: bad trials of one leg leave no output
    results = {s: calibrate_passive(args.model, args.trials, tendon_stiffness=kt, use_cache=not args.no_cache,
                                    side=s) for s in sides}
    out = Path(args.out)
    for s, result in results.items():
        write_calibration(result, out / s if side == "both" else out)
    if side == "both":
        write_passive_parameters(out / "passive_parameters.csv",
                                 {m: p for r in results.values() for m, p in r.calibrated.parameters.items()})
    for s, result in results.items():
        rms_g = result.generic.rms_Nm(result.data)
        rms_c = result.calibrated.rms_Nm(result.data)
        parts = ", ".join(f"{j} {rms_g[j]:.2f} -> {rms_c[j]:.2f}" for j in rms_c)
        st = result.calibrated.stats
        where = f"{out / s} (both legs' parameters: {out / 'passive_parameters.csv'})" if side == "both" else out
        print(
            f"calibrate-passive: {'right' if s == 'r' else 'left'} leg, {len(result.calibrated.parameters)} muscles, "
            f"RMS passive moment error generic -> calibrated (N m): {parts}; IPOPT {st['return_status']} in "
            f"{st['iterations']} iterations -> {where}"
        )
    return 0


def _check_outputs(out, side) -> None:
    """Refuse, before the calibration, an output folder where a file of the user (or one changed
    since the package wrote it) stands under the name of an output (:func:`check_replaceable`)."""
    from ..calibration.result import FIGURE_FILE, FIT_FILE, PARAMETERS_FILE
    from ..io.atomic import check_replaceable

    names = [PARAMETERS_FILE, FIT_FILE, FIGURE_FILE]
    for folder in ([out / "r", out / "l"] if side == "both" else [out]):
        check_replaceable(folder, names)
    if side == "both":
        check_replaceable(out, [PARAMETERS_FILE])

"""``musclemetab calibrate-passive``: passive force-length calibration from passive moments."""

from __future__ import annotations

__all__ = ["add_calibrate_parser", "calibrate_command"]


def _kt_item(text: str) -> tuple[str, float]:
    import argparse

    name, sep, value = text.partition("=")
    try:
        if not sep:
            raise ValueError
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not MUSCLE=VALUE (e.g. soleus_r=20)") from None


def add_calibrate_parser(sub) -> None:
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
    p.add_argument("--side", choices=("r", "l"), default="r",
                   help="leg (default r): its hip, knee and ankle flexion coordinates are found from the model's "
                   "joint tree")
    p.add_argument(
        "--tendon-stiffness", nargs="+", type=_kt_item, metavar="MUSCLE=KT",
        help="override the normalised tendon stiffness of some muscles (default 20 for soleus and "
        "gastrocnemii, 35 for the others)",
    )
    p.add_argument("--no-cache", action="store_true", help="do not read or write the geometry cache")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=calibrate_command)


def calibrate_command(args) -> int:
    from .passive import calibrate_passive, write_calibration

    from ..io import check_output_folder

    check_output_folder(args.out)
    kt = dict(args.tendon_stiffness) if getattr(args, "tendon_stiffness", None) else None
    result = calibrate_passive(args.model, args.trials, tendon_stiffness=kt, use_cache=not args.no_cache,
                               side=getattr(args, "side", "r"))
    write_calibration(result, args.out)
    rms_g = result.generic.rms_Nm(result.data)
    rms_c = result.calibrated.rms_Nm(result.data)
    parts = ", ".join(f"{j} {rms_g[j]:.2f} -> {rms_c[j]:.2f}" for j in rms_c)
    st = result.calibrated.stats
    print(
        f"calibrate-passive: {len(result.calibrated.parameters)} muscles, RMS passive moment error "
        f"generic -> calibrated (N m): {parts}; IPOPT {st['return_status']} in {st['iterations']} "
        f"iterations -> {args.out}"
    )
    return 0

"""``musclemetab geometry``: muscle-tendon lengths and moment arms along an IK motion."""

from __future__ import annotations

__all__ = ["add_parser", "run"]


def _dof_list(text: str) -> list[str]:
    return [d for d in text.replace(",", " ").split() if d]


def add_parser(sub) -> None:
    p = sub.add_parser(
        "geometry",
        help="muscle-tendon lengths and moment arms along an IK motion",
        description=(
            "Compute muscle-tendon lengths and moment arms (m) of the muscles spanning the chosen "
            "DOFs at every frame of an inverse-kinematics motion, with OpenSim. Writes "
            "DIR/muscle_tendon_lengths.sto and DIR/moment_arms_<dof>.sto (one column per muscle). "
            "Results are cached: a second run on the same inputs does no OpenSim work."
        ),
    )
    p.add_argument("--model", required=True, metavar="M.osim", help="OpenSim model")
    p.add_argument("--ik", required=True, metavar="IK.mot", help="inverse kinematics motion")
    p.add_argument(
        "--dofs", nargs="+", metavar="DOF",
        help="coordinates for the moment arms (default: the unlocked coordinates of the --side leg's joints, "
        "from the model)",
    )
    p.add_argument("--side", default="r", choices=("r", "l", "both"),
                   help="leg (default r); both: DIR/r and DIR/l")
    p.add_argument("--muscles", nargs="+", metavar="MUSCLE", help="muscles (default: those spanning the DOFs)")
    p.add_argument(
        "--method", default="velocity", choices=("velocity", "opensim", "finite_difference"),
        help="moment-arm method (default velocity; see the documentation)",
    )
    p.add_argument("--no-cache", action="store_true", help="do not read or write the geometry cache")
    p.add_argument("--cache-dir", metavar="DIR",
                   help="folder of the geometry cache (default $MUSCLEMETAB_CACHE/geometry)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab geometry`` (``args`` from :func:`add_parser`)."""
    from pathlib import Path

    from ..errors import OptionError
    from ..geometry import compute_geometry, write_geometry
    from ..io import check_output_folder

    check_output_folder(args.out)
    dofs = [d for item in args.dofs for d in _dof_list(item)] if args.dofs else None
    if args.side == "both" and (dofs or args.muscles):
        raise OptionError("--dofs and --muscles name one leg's; with --side both leave them out")
    sides = ("r", "l") if args.side == "both" else (args.side,)
    from ..io.atomic import check_replaceable

    for side in sides:  # a file of the user under an output's name is refused before the work
        out = Path(args.out) / side if args.side == "both" else Path(args.out)
        check_replaceable(out, ["muscle_tendon_lengths.sto"] + [f"moment_arms_{d}.sto" for d in dofs or ()])
    geoms = {s: compute_geometry(args.model, args.ik, dofs=dofs, side=s, muscles=args.muscles,
                                 use_cache=not args.no_cache, method=args.method,
                                 cache_dir=args.cache_dir) for s in sides}
    for side, geom in geoms.items():
        out = Path(args.out) / side if args.side == "both" else Path(args.out)
        files = write_geometry(geom, out)
        print(
            f"geometry: side {side}, {len(geom.muscles)} muscles x {len(geom.dofs)} DOFs x {len(geom.time)} frames"
            f"{' (cached)' if geom.source.get('cached') else ''} -> {out} ({len(files)} files)"
        )
    return 0

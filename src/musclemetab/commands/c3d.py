"""``musclemetab c3d``: a C3D file to OpenSim's marker, ground-force and ExternalLoads files."""

from __future__ import annotations

__all__ = ["add_parser", "run", "parse_plate_feet", "parse_foot_markers", "add_lab_options"]


def parse_plate_feet(items) -> dict | None:
    """``["1=r", "2=l"]`` (or ``"1=r,2=l"``) -> ``{1: "r", 2: "l"}``."""
    from ..errors import OptionError

    if not items:
        return None
    out = {}
    for item in ",".join(items).split(","):
        if not item.strip():
            continue
        key, _, side = item.partition("=")
        if not key.strip().isdigit() or side.strip() not in ("r", "l"):
            raise OptionError(f"--plate-feet '{item}' must be PLATE=r or PLATE=l (plates numbered from 1)")
        out[int(key)] = side.strip()
    return out


def parse_foot_markers(items) -> dict | None:
    """``["r=RHEE,RTOE", "l=LHEE,LTOE"]`` -> ``{"r": [...], "l": [...]}`` (heel marker first)."""
    from ..errors import OptionError

    if not items:
        return None
    out = {}
    for item in items:
        side, _, names = item.partition("=")
        names = [n for n in names.split(",") if n.strip()]
        if side.strip() not in ("r", "l") or len(names) < 2:
            raise OptionError(f"--foot-markers '{item}' must be r=HEEL,TOE[,...] or l=HEEL,TOE[,...]")
        out[side.strip()] = [n.strip() for n in names]
    if set(out) != {"r", "l"}:
        raise OptionError("--foot-markers needs both feet: r=HEEL,TOE l=HEEL,TOE")
    return out


def add_lab_options(p) -> None:
    """The options of reading a C3D file (shared with ``musclemetab prepare``)."""
    p.add_argument("--plate-feet", nargs="+", metavar="N=SIDE",
                   help="give whole plates to feet by hand (1=r 2=l); default: from the centre of pressure and "
                   "the foot markers")
    p.add_argument("--foot-markers", nargs="+", metavar="SIDE=HEEL,TOE",
                   help="the foot markers (r=RHEE,RTOE l=LHEE,LTOE); default: recognised by name")
    p.add_argument("--lab-up", default="auto", metavar="AXIS",
                   help="the lab's vertical axis in the C3D file (x, y, z, -x, ...; default from the file)")
    p.add_argument("--lab-forward", default="auto", metavar="AXIS",
                   help="the lab's walking direction (default: the direction the markers move)")


def add_parser(sub) -> None:
    p = sub.add_parser(
        "c3d",
        help="a C3D file to OpenSim's markers (.trc), ground forces (.mot) and ExternalLoads (.xml)",
        description=(
            "Read markers and force plates from a C3D file, turn them into OpenSim's frame (y up) and units "
            "(m, N, N m), and write DIR/<name>.trc, DIR/<name>_grf.mot (force, centre of pressure and free "
            "moment of each plate under each foot), DIR/<name>_grf.xml (ExternalLoads), DIR/<name>_emg.sto (the "
            "analog channels other than the plates': raw EMG, read with --emg-processing raw) and "
            "DIR/<name>_c3d.json (the record: frame, offsets, contacts and their feet). Each plate contact is given "
            "to the foot standing on it, from the centre of pressure and the foot markers; a plate under both feet "
            "at once and a foot partly off its plate are flagged. See docs/lab_data.md."
        ),
    )
    p.add_argument("c3d", metavar="FILE.c3d", help="the C3D file")
    p.add_argument("--model", metavar="M.osim",
                   help="the OpenSim model the forces are for (its heel bodies; default calcn_r and calcn_l)")
    add_lab_options(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab c3d``."""
    from pathlib import Path

    from ..io import check_output_folder
    from ..messages import name_list
    from ..mocap import convert_c3d

    check_output_folder(args.out)
    record = convert_c3d(args.c3d, args.out, model=args.model, up=args.lab_up, forward=args.lab_forward,
                         feet=parse_foot_markers(args.foot_markers), plate_feet=parse_plate_feet(args.plate_feet))
    name = Path(args.c3d).stem
    feet = ", ".join(_contact_text(c) for c in record["contacts"]) or "no force plate"
    emg = f"; EMG channels {name_list(record['emg_channels'])}" if record.get("emg_channels") else ""
    print(f"c3d: {name}: {feet}{emg} -> {args.out}")
    return 0


def _contact_text(c: dict) -> str:
    """One contact of the record as the command prints it, with its flags."""
    flags = (" (both feet!)" if c["two_feet"] else "") + (" (partly off!)" if c.get("partly_off") else "") \
        + "".join(f" (loaded with plate {o['plate']}!)" for o in c.get("overlaps") or [])
    return f"plate {c['plate']} {c['start_s']:.3f}-{c['end_s']:.3f} s: {'right' if c['side'] == 'r' else 'left'}{flags}"

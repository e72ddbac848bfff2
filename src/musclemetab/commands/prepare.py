"""``musclemetab prepare``: from a generic model and the lab's markers to a scaled model and IK."""

from __future__ import annotations

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    from .c3d import add_lab_options

    p = sub.add_parser(
        "prepare",
        help="scale a generic model to a static trial and compute the walking trial's inverse kinematics",
        description=(
            "Scale a generic OpenSim model to the subject from a static trial with OpenSim's ScaleTool (the "
            "setup given, or the measurement set the package ships for gait2392 and Rajagopal models), then "
            "compute the walking trial's inverse kinematics with OpenSim's InverseKinematicsTool. Writes "
            "DIR/model.osim (scaled, markers placed), DIR/static_pose.sto, DIR/static_marker_errors.csv, "
            "DIR/ik.mot, DIR/ik_marker_errors.csv (per frame, flagged above OpenSim's best practice: RMS 2 cm, "
            "maximum 4 cm) and DIR/prepare.json; a C3D walking trial also gives DIR/markers.trc, "
            "DIR/markers_grf.mot and DIR/markers_grf.xml (ExternalLoads). Relative file names in the setups "
            "are read against the setup's folder; nothing is written outside DIR. Then: musclemetab solve "
            "--model DIR/model.osim --ik DIR/ik.mot --external-loads GRF.xml. See docs/lab_data.md."
        ),
    )
    p.add_argument("--model", required=True, metavar="GENERIC.osim", help="the generic (unscaled) model")
    p.add_argument("--static", required=True, metavar="STATIC.trc|.c3d", help="the static standing trial")
    p.add_argument("--markers", required=True, metavar="WALK.trc|.c3d", help="the walking trial's markers")
    p.add_argument("--mass", required=True, type=float, metavar="KG", help="body mass (kg)")
    p.add_argument("--height", type=float, metavar="M",
                   help="body height (m; default: estimated from the static trial's highest marker)")
    p.add_argument("--scale-setup", metavar="S.xml", help="OpenSim ScaleTool setup (its model file is replaced "
                   "by --model, its static trial by --static, its mass by --mass)")
    p.add_argument("--ik-setup", metavar="I.xml", help="OpenSim InverseKinematicsTool setup (its model and marker "
                   "file are replaced by the scaled model and --markers)")
    p.add_argument("--marker-set", metavar="MARKERS.xml",
                   help="marker-set file added to the generic model (default: the scaling setup's, or the model's)")
    p.add_argument("--window", metavar="T0:T1", help="IK time range (s; default: the IK setup's, or the whole trial)")
    add_lab_options(p)
    p.add_argument("--no-cache", action="store_true", help="do not read or write the cache of scaling and IK")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab prepare``."""
    from ..io import check_output_folder
    from ..mocap.prepare import prepare
    from ..redundancy.window import parse_window
    from .c3d import parse_foot_markers, parse_plate_feet
    from .options import check_body

    check_output_folder(args.out)
    window = parse_window(args.window) if args.window else None
    check_body(args.mass, args.height)
    c3d = dict(up=args.lab_up, forward=args.lab_forward, feet=parse_foot_markers(args.foot_markers),
               plate_feet=parse_plate_feet(args.plate_feet))
    rec = prepare(args.model, args.static, args.markers, args.mass, args.out, height_m=args.height,
                  scale_setup=args.scale_setup, ik_setup=args.ik_setup, marker_set=args.marker_set,
                  time_range=window, c3d_options=c3d, use_cache=not args.no_cache)
    s, ik = rec["scaling"]["static_summary"], rec["ik"]["summary"]
    how = "setup" if args.scale_setup else f"{rec['scaling'].get('family')} measurements"
    print(f"prepare: scaled to {rec['mass_kg']:g} kg ({how}), height {rec['height_m']:.3f} m "
          f"({rec['height_from']}); static markers RMS {100 * s['rms_m']:.1f} cm, max {100 * s['max_m']:.1f} cm "
          f"({s['worst_marker']})")
    print(f"prepare: IK {ik['frames']} frames {rec['ik']['time_range'][0]:.3f}-{rec['ik']['time_range'][1]:.3f} s, "
          f"RMS {100 * ik['rms_mean_m']:.1f} cm on average, {ik['flagged_frames']} frames above OpenSim's best "
          f"practice -> {args.out}")
    return 0

"""``musclemetab emg``: raw EMG to normalised envelopes, every processing step an option."""

from __future__ import annotations

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    from .solve import add_raw_emg_arguments

    p = sub.add_parser(
        "emg",
        help="raw EMG (a .sto/.mot table or a C3D file's analog channels) to normalised envelopes",
        description=(
            "Process raw EMG into normalised envelopes and write them: zero-lag band-pass, full-wave rectification, "
            "zero-lag low-pass, normalisation to each channel's peak or to given maxima, optional electromechanical "
            "delay (musclemetab.emg.process_raw_emg; each step an option below). Writes DIR/<name>_envelopes.sto (one "
            "column per channel, OpenSim's format; give it to solve/estimate --emg as processed envelopes) and "
            "DIR/<name>_envelopes.json (the settings and the sampling rate). The same settings on solve and "
            "estimate (--emg-processing raw with these options) give the same envelopes. See docs/lab_data.md."
        ),
    )
    p.add_argument("raw", nargs="+", metavar="RAW", help="raw EMG files (.sto, .mot or .c3d)")
    p.add_argument("--channels", nargs="+", metavar="NAME", help="the channels to process (default all)")
    add_raw_emg_arguments(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run, emg_processing="raw")


def run(args) -> int:
    """Run ``musclemetab emg``."""
    import json
    from pathlib import Path

    from ..emg import EmgProcessing, process_raw_emg
    from ..emg import read_emg_signals
    from ..errors import OptionError
    from ..io import atomic_directory, check_output_folder, write_storage
    from .solve import raw_emg_processing

    check_output_folder(args.out)
    settings = raw_emg_processing(args) or EmgProcessing()
    stems = [Path(p).stem for p in args.raw]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise OptionError(f"two raw EMG files named {dup[0]}: their envelopes would share a file name; rename one")
    done = []
    for path in args.raw:  # everything is read and processed before anything is written
        raw = read_emg_signals(path)
        env = process_raw_emg(raw, channels=args.channels, **settings.settings())
        done.append((Path(path), raw, env))
    with atomic_directory(args.out, mark=True) as tmp:
        for path, raw, env in done:
            write_storage(Path(tmp) / f"{path.stem}_envelopes.sto", env, name=f"{path.stem}_envelopes",
                          comments=[f"normalised EMG envelopes of {path.name} (musclemetab emg)"])
            record = {"source": str(path.resolve()), "channels": list(env.columns),
                      "processing": {k: (list(v) if isinstance(v, tuple) else v) for k, v in settings.settings().items()},
                      "sampling_rate_hz": env.attrs["processing"]["fs_hz"], "units": raw.attrs.get("units")}
            (Path(tmp) / f"{path.stem}_envelopes.json").write_text(json.dumps(record, indent=1) + "\n",
                                                                   encoding="utf-8")
    for path, _, env in done:
        print(f"emg: {path.name}: {len(env.columns)} channel(s), {env.index[0]:.3f}-{env.index[-1]:.3f} s -> "
              f"{Path(args.out) / (path.stem + '_envelopes.sto')}")
    return 0

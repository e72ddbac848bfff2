"""Options several commands share: the whole-body basal heat (``metabolics``, ``analyse``),
the walking speed, and the running of a study (``run``, ``demo``)."""

from __future__ import annotations

from ..errors import OptionError

__all__ = ["BASAL_DEFAULTS", "add_basal_arguments", "check_basal_arguments", "check_speed", "check_body",
           "add_study_arguments", "number_option", "check_number_options", "EXCLUSIVE_OPTIONS", "check_exclusive",
           "add_emg_scale_bounds_argument", "emg_scale_bounds", "add_stop_argument", "add_solve_flags_argument",
           "warn_solve_flags"]

#: the basal options' defaults: the paper's 1.2 W per kg of body mass
BASAL_DEFAULTS = {"basal": "body", "basal_coefficient": 1.2, "basal_exponent": 1.0}


def add_basal_arguments(parser, recorded: str | None = None) -> None:
    """The whole-body basal heat options, ``--basal``, ``--basal-coefficient`` and
    ``--basal-exponent``, of the commands that compute whole-body rates (``metabolics``,
    ``analyse``); :func:`check_basal_arguments` checks their values. With ``recorded`` (where
    the command finds earlier settings, e.g. ``"--metabolics"``) the options default to
    ``None``: the command takes the recorded values, else :data:`BASAL_DEFAULTS`."""
    default = (lambda key: None) if recorded else BASAL_DEFAULTS.get
    also = f" (default: as recorded in {recorded}, else %s)" if recorded else " (default %s)"
    parser.add_argument(
        "--basal", default=default("basal"), choices=("body", "muscle", "none"),
        help="whole-body basal heat: 1.2 W/kg of body mass (body, the paper), 1.2 W/kg of muscle mass in every "
        "muscle (muscle, the study's code) or none" + also % "body",
    )
    parser.add_argument(
        "--basal-coefficient", type=float, default=default("basal_coefficient"), metavar="W_PER_KG",
        help="basal heat coefficient as OpenSim's probes write it (basal_coefficient): under --basal body the "
        "basal heat is COEFFICIENT * mass^EXPONENT W; it is also the per-muscle basal heat, W per kg of muscle "
        "mass" + also % "1.2",
    )
    parser.add_argument(
        "--basal-exponent", type=float, default=default("basal_exponent"), metavar="X",
        help="basal heat exponent of the body mass (OpenSim's basal_exponent; --basal body only)" + also % "1",
    )


def check_basal_arguments(args) -> None:
    """Raise :class:`OptionError` naming the option for a basal coefficient that is not a
    non-negative number, an exponent that is not finite, or an exponent with ``--basal muscle``."""
    from ..settings import check_number

    check_number("basal_coefficient", args.basal_coefficient, option="--basal-coefficient")
    check_number("basal_exponent", args.basal_exponent, option="--basal-exponent")
    if args.basal == "muscle" and args.basal_exponent != 1:
        raise OptionError("--basal-exponent applies to --basal body only (the muscle rule is linear in each "
                          "muscle's mass); drop it or use --basal body")


def check_speed(speed: float | None) -> None:
    """Raise :class:`OptionError` for a ``--speed`` that is not a walking or running speed in m/s
    (the study file's ``speed_m_per_s`` check)."""
    from ..settings import check_number

    if speed is not None:
        check_number("speed_m_per_s", speed, option="--speed")


def check_body(mass_kg: float | None, height_m: float | None) -> None:
    """Raise :class:`OptionError` for a ``--mass`` or ``--height`` that is not a human one
    (the study file's ``body_mass_kg`` and ``height_m`` checks)."""
    from ..settings import check_number

    if mass_kg is not None:
        check_number("body_mass_kg", mass_kg, option="--mass")
    if height_m is not None:
        check_number("height_m", height_m, option="--height")


def add_study_arguments(parser) -> None:
    """``--workers``, ``--force``, ``--no-progress`` and ``--strict`` of the commands that run a study."""
    number_option(parser, "--workers", "workers", metavar="N",
                  help="parallel processes (default: the number of CPUs); 1 runs in this process")
    parser.add_argument("--force", action="store_true", help="run every unit again, even those up to date")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--strict", action="store_true",
                        help="a unit with a plausibility flag fails, with the flags as its reason (the study "
                        "file's strict = true; docs/quality.md)")


def number_option(parser, option: str, key: str, *, help: str, default=None, metavar: str | None = None) -> None:
    """Add the numeric option ``option`` carrying the value of :data:`musclemetab.settings.NUMBER_KEYS`
    ``[key]``: its type (whole number or number) and, in the help, its unit and range come from
    that table, the one the study file is checked against; :func:`check_number_options` checks
    the value against it after parsing, so both refuse the same values with the same range. To
    declare a new numeric setting, add its row to the table and add the option with this function."""
    from ..settings import NUMBER_KEYS

    entry = NUMBER_KEYS[key]
    action = parser.add_argument(option, type=int if entry.integer else float, default=default, metavar=metavar,
                                 help=f"{help} [{entry.range_text()}]")
    declared = dict(parser.get_default("number_options") or {})
    declared[action.dest] = (option, key)
    parser.set_defaults(number_options=declared)


def check_number_options(args) -> None:
    """Raise :class:`OptionError` naming the option, the value and the range for a value of an
    option declared with :func:`number_option` that its table row refuses (``None``: not given)."""
    from ..settings import check_number

    for dest, (option, key) in (getattr(args, "number_options", None) or {}).items():
        value = getattr(args, dest, None)
        if value is not None:
            check_number(key, value, option=option)


#: Options of a command that override each other, refused together: command -> (option, option,
#: why, remedy). A command adds its pairs here.
EXCLUSIVE_OPTIONS = {
    "solve": (
        ("--grf", "--external-loads", "both give the ground forces", "give one: the ExternalLoads file already "
         "names its force data file"),
        ("--tendon-stiffness", "--parameters", "both give the tendon stiffness", "give one"),
        ("--window", "--cycle", "both give the time window", "give one"),
    ),
}


def check_exclusive(args) -> None:
    """Raise :class:`OptionError` when two options of the command's :data:`EXCLUSIVE_OPTIONS` are both given."""
    for a, b, why, remedy in EXCLUSIVE_OPTIONS.get(getattr(args, "command", None), ()):
        given = [getattr(args, o.lstrip("-").replace("-", "_"), None) for o in (a, b)]
        if all(v not in (None, [], False) for v in given):
            raise OptionError(f"{a} and {b} cannot be used together ({why}); {remedy}")


def add_emg_scale_bounds_argument(parser) -> None:
    """``--emg-scale-bounds LOW:HIGH``: the bounds of the EMG scale factors of the commands that
    estimate them (``solve`` with EMG, ``estimate``); :func:`emg_scale_bounds` reads it."""
    parser.add_argument("--emg-scale-bounds", metavar="LOW:HIGH",
                        help="with --emg: bounds of the EMG scale factors (default 0.05:2.5, EMG-TEN's; the "
                        "MuscleRedundancySolver uses 0.01:5; 1:1 takes the EMG as it is)")


def emg_scale_bounds(args) -> tuple[float, float] | None:
    """The ``--emg-scale-bounds`` of ``args`` as ``(low, high)``, or ``None`` when not given;
    :class:`OptionError` naming the option when it is not ``LOW:HIGH`` with ``0 < LOW <= HIGH``."""
    import math

    text = getattr(args, "emg_scale_bounds", None)
    if text is None:
        return None
    lo, sep, hi = str(text).partition(":")
    try:
        bounds = (float(lo), float(hi)) if sep else None
    except ValueError:
        bounds = None
    if bounds is None or not all(math.isfinite(b) for b in bounds) or not 0 < bounds[0] <= bounds[1]:
        raise OptionError(f"--emg-scale-bounds must be LOW:HIGH with 0 < LOW <= HIGH, e.g. 0.01:5, not {text!r}")
    return bounds


def add_stop_argument(parser) -> None:
    """``--stop optimum|authors``: where IPOPT stops (:data:`musclemetab.redundancy.ipopt.STOPS`)."""
    from ..redundancy.stops import DEFAULT_STOP, STOPS

    parser.add_argument(
        "--stop", default=DEFAULT_STOP, choices=tuple(STOPS),
        help="where the solver stops: optimum (default; the optimum of the problem, IPOPT tolerance 1e-8 with the "
        "adaptive barrier parameter) or authors (the study's settings, tolerance 1e-6 with the monotone barrier, "
        "whose rates lie 4-18 %% above the optimum's; to reproduce the paper's numbers; docs/solver.md)")


def add_solve_flags_argument(parser) -> None:
    """``--show-solve-flags`` of the commands that read a solve's folder (``metabolics``, ``analyse``)."""
    parser.add_argument("--show-solve-flags", action="store_true",
                        help="warn again of the plausibility flags the solve recorded (default: the solve warned of "
                        "them; one note counts them, and OUT/plausibility.json lists them with the command's own; "
                        "--strict warns of them, its reasons to fail)")


def warn_solve_flags(args, solve_flags: dict) -> None:
    """The plausibility flags of the solve folders (``{folder: [Flag]}``): one warning each with
    ``--show-solve-flags`` or ``--strict`` (they are then the reasons of the failure), else one
    note counting them (``solve`` warned of each already)."""
    from ..messages import note
    from ..quality import warn_flags

    if getattr(args, "show_solve_flags", False) or getattr(args, "strict", False):
        for folder, flags in solve_flags.items():
            warn_flags(flags, str(folder))
        return
    n = sum(len(flags) for flags in solve_flags.values())
    if n:
        where = ", ".join(str(folder) for folder, flags in solve_flags.items() if flags)
        note(f"the solve's {n} plausibility flag{'s' if n > 1 else ''} ({where}: summary.json) not repeated; "
             "--show-solve-flags repeats them")

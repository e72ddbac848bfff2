"""The numeric settings of the package, declared once: name, unit, range of possible values,
meaning (and the command-line option carrying each, :func:`musclemetab.commands.options.number_option`).

The study file's keys (:mod:`musclemetab.study.spec`) and the command line's options are both
checked against :data:`NUMBER_KEYS`, so that both refuse the same values with the same range
in the message. A new numeric setting is one row here; the command that takes it declares its
option with ``number_option(parser, "--option", "key", help=...)``. This module imports nothing
heavy, so that building the command-line parser stays cheap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import OptionError

__all__ = ["NumberKey", "NUMBER_KEYS", "check_number", "SwitchKey", "SWITCH_KEYS", "check_switch", "MAX_ITERATIONS",
           "MESH_FREQUENCY_RANGE_HZ", "LOCKED_TOLERANCE"]

#: Resource bounds of a solve: the IPOPT iteration limit (ten times the study's 10000; an
#: iteration of the example trial takes about 0.1 s) and the mesh frequency (intervals per
#: second: below 10 the mesh cannot follow a gait cycle, above 1000 it is finer than any
#: motion-capture rate; see also :data:`musclemetab.redundancy.ipopt.MAX_PROBLEM_MEMORY_MB`)
MAX_ITERATIONS = 100_000
MESH_FREQUENCY_RANGE_HZ = (10.0, 1000.0)
#: How far (rad for a rotation, m for a translation) a motion may take a locked coordinate from
#: the value the model locks it at and still hold it (musclemetab.layout.check_locked_coordinates,
#: the solution's OpenSim model); IK files hold eight decimals of a degree, and OpenSim's IK
#: writes a locked coordinate's value exactly.
LOCKED_TOLERANCE = 1e-4


@dataclass(frozen=True)
class NumberKey:
    """A numeric key of the study file: its unit and the range of physically possible values.

    ``low``/``high`` are inclusive unless ``low_open`` (the value must exceed ``low``).
    ``integer`` keys take whole numbers only (``1.5`` and ``true`` are refused).
    """

    name: str
    unit: str
    low: float
    high: float
    help: str
    low_open: bool = False
    integer: bool = False

    def range_text(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        if self.low_open:
            return f"above {self.low:g}{' (positive)' if self.low == 0 else ''} and at most {self.high:g}{unit}"
        return f"from {self.low:g} to {self.high:g}{unit}"

    def check(self, value, where: str, option: str | None = None) -> float | int:
        """``value`` as a float (an int for integer keys); :class:`OptionError` naming the key
        (or the command-line ``option``), the value and the range otherwise."""
        name = option or f"'{self.name}'"
        at = f"{where}: " if where else ""
        kind = "a whole number" if self.integer else "a number"
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                (self.integer and not isinstance(value, int)):
            raise OptionError(f"{at}{name} must be {kind} ({self.help}, {self.range_text()}), not {value!r}")
        if not math.isfinite(value) or not (self.low < value if self.low_open else self.low <= value) \
                or value > self.high:
            sign = " (it must not be negative)" if value < 0 <= self.low else ""
            shown = f"{value:d}" if self.integer else f"{value:g}"
            raise OptionError(f"{at}{name} = {shown} is not {self.help}: it must be {self.range_text()}{sign}")
        return int(value) if self.integer else float(value)


#: Every numeric key of a study file (and the same value on the command line): name, unit,
#: range of physically possible values, meaning. Every check of these values goes through it.
NUMBER_KEYS: dict[str, NumberKey] = {k.name: k for k in (
    NumberKey("body_mass_kg", "kg", 20.0, 300.0, "a human body mass in kilograms"),
    NumberKey("height_m", "m", 0.5, 2.7, "a human height in metres"),  # optional: muscle masses from the model
    NumberKey("basal_coefficient", "W/kg", 0.0, 10.0, "a basal heat rate per kg (OpenSim's default 1.51, the "
              "paper's 1.2)"),
    NumberKey("basal_exponent", "", 0.0, 2.0, "an exponent of the body mass (1 linear, 0.75 Kleiber's)"),
    NumberKey("assistance_gain", "", -10.0, 10.0, "a factor on the device torque of an assistance profile (1: as in "
              "the file; negative: the device acts the other way)"),
    NumberKey("emg_tolerance", "", 0.0, 1.0, "a half-width of the EMG band in normalised excitation"),
    NumberKey("emg_lowpass_hz", "Hz", 0.0, 100.0, "a cut-off of the EMG envelope's low-pass filter", low_open=True),
    NumberKey("emg_order", "", 2, 12, "an effective order of a zero-lag EMG filter (even)", integer=True),
    NumberKey("emg_delay_s", "s", 0.0, 0.5, "an electromechanical delay"),
    NumberKey("grf_threshold_N", "N", 0.0, 1000.0, "a contact threshold of the vertical force", low_open=True),
    NumberKey("speed_m_per_s", "m/s", 0.0, 15.0, "a walking or running speed", low_open=True),
    NumberKey("measured_W_per_kg", "W/kg", 0.0, 50.0, "a measured metabolic rate per kg of body mass",
              low_open=True),
    NumberKey("vo2_mL_per_s", "mL/s", 0.0, 150.0, "a human oxygen uptake", low_open=True),
    NumberKey("vco2_mL_per_s", "mL/s", 0.0, 200.0, "a human carbon dioxide output", low_open=True),
    NumberKey("vo2_mL_per_min", "mL/min", 0.0, 9000.0, "a human oxygen uptake", low_open=True),
    NumberKey("vco2_mL_per_min", "mL/min", 0.0, 12000.0, "a human carbon dioxide output", low_open=True),
    NumberKey("start_s", "s", -1e5, 1e5, "a time of the trial's files"),
    NumberKey("toe_off_s", "s", -1e5, 1e5, "a time of the trial's files"),
    NumberKey("end_s", "s", -1e5, 1e5, "a time of the trial's files"),
    NumberKey("tendon_stiffness", "", 0.0, 1000.0, "a normalised tendon stiffness kT (the literature's 35)",
              low_open=True),
    NumberKey("weight", "", 0.0, 1e6, "a weight of the energy goal"),
    NumberKey("effort_weight", "", 0.0, 1e6, "a weight of the effort goal"),
    NumberKey("smoothing", "", 0.0, 1e6, "a smoothing parameter", low_open=True),
    NumberKey("max_iter", "", 1, MAX_ITERATIONS, "a number of IPOPT iterations", integer=True),
    NumberKey("tol", "", 0.0, 1.0, "an IPOPT tolerance", low_open=True),
    # command line only (same table, so that a row added here is checked wherever the value is given)
    NumberKey("mesh_frequency_hz", "per s", MESH_FREQUENCY_RANGE_HZ[0], MESH_FREQUENCY_RANGE_HZ[1],
              "a number of mesh intervals per second (the study's 100)"),
    NumberKey("print_level", "", 0, 12, "an IPOPT print level", integer=True),
    NumberKey("emg_weight", "", 0.0, 1e6, "a weight of the EMG tracking cost"),
    NumberKey("workers", "", 1, 1024, "a number of worker processes", integer=True),
    # [uncertainty] (and --uncertainty, --uncertainty-seed)
    NumberKey("samples", "", 0, 100_000, "a number of uncertainty samples per trial unit", integer=True),
    NumberKey("seed", "", 0, 1_000_000, "a seed of the uncertainty samples", integer=True),
)}
def check_number(key: str, value, where: str = "", option: str | None = None) -> float | int:
    """Check ``value`` of the numeric key ``key`` against :data:`NUMBER_KEYS`.

    ``option`` names the command-line option carrying the same value (e.g. ``"--speed"``),
    so that the command line and the study file refuse the same values with the same reason.
    """
    return NUMBER_KEYS[key].check(value, where, option)


@dataclass(frozen=True)
class SwitchKey:
    """A true/false key of the study file: its default, its meaning and the command-line options
    that turn it on (``on_option``) and off (``off_option``) whatever the file says."""

    name: str
    default: bool
    help: str
    on_option: str | None = None
    off_option: str | None = None

    def check(self, value, where: str) -> bool:
        """``value`` as a bool; :class:`OptionError` naming the key and the remedy otherwise."""
        if not isinstance(value, bool):
            at = f"{where}: " if where else ""
            raise OptionError(f"{at}'{self.name}' must be true or false ({self.help}), not {value!r}")
        return value


#: Every true/false key of a study file: name, default, meaning, command-line option.
SWITCH_KEYS: dict[str, SwitchKey] = {k.name: k for k in (
    SwitchKey("warm_start", False, "[solver] warm_start: start each effort solve of a trial from the solve of the "
              "workflow before it (EFFORT-GEN -> EFFORT-CAL -> EFFORT-TEN); false (the default): every solve from "
              "static optimisation", on_option="--warm-start", off_option="--cold-start"),
    SwitchKey("best_start", False, "[solver] best_start: solve each effort solve of a trial that has a workflow "
              "before it twice, from static optimisation and from that workflow's solution, and keep the lower "
              "objective (unit.json 'starts' records both and the whole-body rates' spread; docs/study.md, Which "
              "optimum); false (the default): one start", on_option="--best-start"),
    SwitchKey("sensitivity", False, "[uncertainty] sensitivity: each effort trial unit (one leg, forward fiber "
              "dynamics, no EMG or energy goal) also writes sensitivity.csv, the derivative of each rate per log of "
              "each muscle parameter at the optimum (docs/uncertainty.md, Sensitivities); false (the default): not",
              on_option="--sensitivity"),
    SwitchKey("keep_flagged", False, "[uncertainty] keep_flagged: the bands take every converged sample, also those "
              "with a plausibility flag (docs/uncertainty.md, Bands); false (the default): a flagged sample is left "
              "out of the bands and listed", on_option="--keep-flagged-samples"),
)}


def check_switch(key: str, value, where: str = "") -> bool:
    """Check ``value`` of the true/false key ``key`` against :data:`SWITCH_KEYS`."""
    return SWITCH_KEYS[key].check(value, where)

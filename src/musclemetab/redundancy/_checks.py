"""Checks of options shared by the solver's settings types: each raises
:class:`~musclemetab.errors.OptionError` naming the option, its value and what it may be."""

from __future__ import annotations

import math
from typing import Sequence

from ..errors import OptionError

__all__ = ["check_option", "check_weights", "check_non_negative", "check_factor_bounds"]

#: how the factors shared by muscles are represented: one variable per coupled group, or one per
#: muscle with equality constraints
COUPLINGS = ("constraints", "shared")
#: the EMG goals of an EMG-informed or EMG-TEN problem: bound rows |e - s E| <= tolerance with the
#: tracking cost (constrained), bound rows of tolerance 0 (driven), or the tracking cost alone
EMG_MODES = ("constrained", "driven", "tracking")


def check_option(name: str, value, allowed: Sequence):
    """``value`` when it is one of ``allowed``."""
    if value not in allowed:
        raise OptionError(f"{name} must be one of {', '.join(repr(a) for a in allowed)}, not {value!r}")
    return value


def check_non_negative(name: str, value, note: str = "") -> None:
    """A finite number >= 0 (``note``: what 0 means, e.g. `` (0: EMG-driven)``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value >= 0):
        raise OptionError(f"{name} must be a non-negative number{note}, not {value!r}")


def check_weights(settings, names: Sequence[str]) -> None:
    """The weights ``names`` of ``settings`` (attributes): non-negative numbers."""
    for name in names:
        check_non_negative(f"the weight {name}", getattr(settings, name))


def check_factor_bounds(what: str, bounds) -> tuple[float, float]:
    """``(low, high)`` of scale factors as floats, ``0 < low <= high`` finite."""
    try:
        lo, hi = (float(v) for v in bounds)
    except (TypeError, ValueError):
        lo = hi = math.nan
    if not (0 < lo <= hi and math.isfinite(hi)):
        raise OptionError(f"{what} must be (low, high) with 0 < low <= high, not {bounds!r}")
    return lo, hi

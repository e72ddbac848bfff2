"""Checks and numerics shared by the analysis modules (time axes, interval integrals)."""

from __future__ import annotations

import numpy as np

from ..errors import DataMismatchError, OptionError
from ..events import as_signal, as_time  # noqa: F401  (the time-axis checks of the gait events)


def interp_at(t: np.ndarray, y: np.ndarray, tq: float) -> np.ndarray:
    """Linear interpolation of ``y`` (last axis = time) at one time ``tq`` within ``t``."""
    k = int(np.searchsorted(t, tq, side="right")) - 1
    k = min(max(k, 0), t.size - 2)
    w = (tq - t[k]) / (t[k + 1] - t[k])
    return y[..., k] * (1.0 - w) + y[..., k + 1] * w


def integrate_interval(t: np.ndarray, y: np.ndarray, a: float, b: float) -> np.ndarray:
    """``integral_a^b y dt`` by the trapezoidal rule, ``a <= b`` inside ``[t[0], t[-1]]``.

    The samples strictly inside ``(a, b)`` are used as they are; the values at ``a`` and
    ``b`` are linearly interpolated between their neighbouring samples, so that the
    integral is exactly that of the piecewise-linear interpolant of the samples. Works
    along the last axis of ``y``.
    """
    if b < a:
        raise OptionError(f"integration interval [{a:g}, {b:g}] s runs backwards")
    if b == a:
        return np.zeros(y.shape[:-1])
    inside = (t > a) & (t < b)
    tt = np.concatenate(([a], t[inside], [b]))
    yy = np.concatenate(
        (interp_at(t, y, a)[..., None], y[..., inside], interp_at(t, y, b)[..., None]), axis=-1
    )
    return np.trapezoid(yy, tt, axis=-1)


def coverage(t: np.ndarray, start_s: float, end_s: float, tolerance_s: float | None, what: str):
    """The part ``[a, b]`` of the cycle ``[start_s, end_s]`` that the samples cover.

    The samples may miss at most ``tolerance_s`` at either end (default: 1.5 times the
    largest sample interval); the missing part is not extrapolated. Raises
    :class:`DataMismatchError` when more is missing.
    """
    if tolerance_s is None:
        tolerance_s = 1.5 * float(np.max(np.diff(t)))
    if not (np.isfinite(tolerance_s) and tolerance_s >= 0):
        raise OptionError(f"coverage tolerance must be a non-negative number of seconds, not {tolerance_s!r}")
    miss_start = t[0] - start_s
    miss_end = end_s - t[-1]
    if miss_start > tolerance_s or miss_end > tolerance_s:
        raise DataMismatchError(
            f"{what} spans {t[0]:g}-{t[-1]:g} s but the gait cycle spans {start_s:g}-{end_s:g} s "
            f"(more than {tolerance_s:g} s is missing); give samples that cover the cycle, or another cycle"
        )
    return max(start_s, float(t[0])), min(end_s, float(t[-1]))

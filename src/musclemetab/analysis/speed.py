"""Walking speed from the root translation of an inverse-kinematics motion.

When a study gives no speed for a trial, the average walking speed over the gait cycle is
taken as the net horizontal displacement of the model's root body divided by the cycle's
duration:

    v = sqrt(Δx² + Δz²) / Δt

with ``x`` and ``z`` the root joint's horizontal translation coordinates between the first
and last frames of the cycle. With the model given they are read from it
(:meth:`musclemetab.layout.ModelLayout.forward_coordinates`: the coordinates of the joint
attached to the ground that move its body perpendicular to gravity), whatever their names.
Without a model the rule is OpenSim's naming of such coordinates: the first IK columns ending
in ``_tx`` and ``_tz``. On a treadmill the root hardly moves (OpenSim's gait2392 example:
under 1 cm/s): a net speed below :data:`MIN_OVERGROUND_SPEED_M_PER_S` is refused, and the
trial's speed must be given. Over a whole gait
cycle the pelvis returns to the same phase of its oscillation, so the net displacement
measures the average forward speed; walking direction (±x, ±z) does not matter.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import DataMismatchError

__all__ = ["walking_speed_from_ik", "MIN_OVERGROUND_SPEED_M_PER_S"]

#: Below this net speed (m/s) the subject walked on a treadmill (or stood): no speed from the kinematics.
MIN_OVERGROUND_SPEED_M_PER_S = 0.2


def walking_speed_from_ik(
    ik,
    *,
    start_s: float | None = None,
    end_s: float | None = None,
    padding_s: float = 0.05,
    columns: tuple[str, ...] | None = None,
    model=None,
) -> float:
    """Average horizontal walking speed (m/s) over a cycle of an IK motion.

    Parameters
    ----------
    ik
        Path of an IK ``.mot`` file or a table from :func:`musclemetab.io.read_storage`.
    start_s, end_s
        The cycle (default: the motion less ``padding_s`` at both ends, the padding of
        the example data).
    columns
        The horizontal root translations (m); default from ``model``, else the naming rule.
    model
        The ``.osim`` model (path) whose forward coordinates to use.
    """
    from ..io import read_storage, require_columns

    df = ik if hasattr(ik, "columns") else read_storage(ik)
    where = str(df.attrs.get("path", ik if isinstance(ik, (str, os.PathLike)) else "IK"))
    if columns is None:
        if model is not None:
            from ..layout import read_layout

            columns = read_layout(model).forward_coordinates()
        else:
            columns = tuple(c for suffix in ("_tx", "_tz")
                            for c in [next((c for c in df.columns if str(c).endswith(suffix)), None)] if c)
            if not columns:
                raise DataMismatchError(f"{where}: no column ending in _tx or _tz (root translation); give the model "
                                        "or the speed (a study trial's speed_m_per_s, --speed on the command line)")
    require_columns(df, list(columns), what="root translation column")
    t = df.index.to_numpy(dtype=float)
    t0 = t[0] + padding_s if start_s is None else float(start_s)
    t1 = t[-1] - padding_s if end_s is None else float(end_s)
    if not (t[0] - 1e-9 <= t0 < t1 <= t[-1] + 1e-9):
        raise DataMismatchError(
            f"{where}: cycle {t0:.3f}-{t1:.3f} s is not inside the motion ({t[0]:.3f}-{t[-1]:.3f} s); "
            "give a cycle within the file, or the speed (a study trial's speed_m_per_s, --speed on the command line)"
        )
    d = [np.interp(t1, t, df[c].to_numpy(float)) - np.interp(t0, t, df[c].to_numpy(float)) for c in columns]
    v = float(np.sqrt(np.sum(np.square(d))) / (t1 - t0))
    if v < MIN_OVERGROUND_SPEED_M_PER_S:
        raise DataMismatchError(
            f"{where}: the root body moves {v:.3f} m/s over the cycle ({', '.join(columns)}): treadmill walking, "
            "whose speed the kinematics cannot give; give the speed (a study trial's speed_m_per_s, --speed on the "
            "command line)"
        )
    return v

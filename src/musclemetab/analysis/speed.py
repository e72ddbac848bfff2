"""Walking speed from the pelvis translation of an inverse-kinematics motion.

When a study gives no speed for a trial, the average walking speed over the gait cycle is
taken as the net horizontal displacement of the pelvis divided by the cycle's duration:

    v = sqrt(Δx² + Δz²) / Δt

with ``x`` and ``z`` the pelvis translations in the ground's horizontal plane (OpenSim's
y axis is vertical) between the first and last frames of the cycle. Over a whole gait
cycle the pelvis returns to the same phase of its oscillation, so the net displacement
measures the average forward speed; walking direction (±x, ±z) does not matter.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import DataMismatchError

__all__ = ["walking_speed_from_ik"]


def walking_speed_from_ik(
    ik,
    *,
    start_s: float | None = None,
    end_s: float | None = None,
    padding_s: float = 0.05,
    columns: tuple[str, str] = ("pelvis_tx", "pelvis_tz"),
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
        The two horizontal pelvis translations (m).
    """
    from ..io import read_storage, require_columns

    df = ik if hasattr(ik, "columns") else read_storage(ik)
    where = str(df.attrs.get("path", ik if isinstance(ik, (str, os.PathLike)) else "IK"))
    require_columns(df, list(columns), what="pelvis translation column")
    t = df.index.to_numpy(dtype=float)
    t0 = t[0] + padding_s if start_s is None else float(start_s)
    t1 = t[-1] - padding_s if end_s is None else float(end_s)
    if not (t[0] - 1e-9 <= t0 < t1 <= t[-1] + 1e-9):
        raise DataMismatchError(
            f"{where}: cycle {t0:.3f}-{t1:.3f} s is not inside the motion ({t[0]:.3f}-{t[-1]:.3f} s); "
            "give start_s and end_s within the file, or the trial's speed_m_per_s"
        )
    d = [np.interp(t1, t, df[c].to_numpy(float)) - np.interp(t0, t, df[c].to_numpy(float)) for c in columns]
    return float(np.hypot(*d) / (t1 - t0))

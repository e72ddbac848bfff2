"""Figure of a passive calibration: target, generic and calibrated passive moment-angle curves.

One row per calibration trial (ankle, knee, hip), one panel per block of the trial (a sweep
of the trial's joint with the other joints fixed; the fixed angles, rounded to a degree, in
the panel's title): the target passive moments (black), those of the generic parameters
(dashed) and those of the calibrated parameters, against the trial's joint angle in degrees;
moments in N m. :func:`passive_fit_figure` draws it from arrays (no file I/O, the Agg canvas,
never ``pyplot``); :func:`save_passive_fit_figure` writes it as PNG.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..messages import name_list

__all__ = ["passive_fit_figure", "save_passive_fit_figure", "PASSIVE_FIT_DPI"]

#: Resolution of the PNG (dots per inch).
PASSIVE_FIT_DPI = 110


def _short(name: str) -> str:
    return name.replace("_r", "").replace("_angle", "").replace("_flexion", "")


def passive_fit_figure(trials: Sequence, generic_Nm: Mapping[str, np.ndarray], calibrated_Nm: Mapping[str, np.ndarray]):
    """The moment-angle curves of every trial and block (module docstring).

    ``trials``: the calibration trials, each with ``joint``, ``dof``, ``angles_rad`` (F, J),
    ``angle_names``, ``target_angle_rad`` (F,), ``target_Nm`` (F,) and ``block`` (F,)
    (:class:`musclemetab.calibration.CalibrationTrial`); ``generic_Nm`` and
    ``calibrated_Nm``: joint -> (F,) passive moments of the two parameter sets. Returns a
    :class:`matplotlib.figure.Figure`.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ncol = max(len(np.unique(t.block)) for t in trials)
    fig = Figure(figsize=(4 * ncol, 3.2 * len(trials)))
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(trials), ncol, squeeze=False)
    for r, t in enumerate(trials):
        q = np.degrees(t.target_angle_rad)
        blocks = np.unique(t.block)
        for c in range(ncol):
            ax = axes[r, c]
            if c >= len(blocks):
                ax.axis("off")
                continue
            sel = t.block == blocks[c]
            ax.plot(q[sel], t.target_Nm[sel], "k-", lw=2, label="target")
            ax.plot(q[sel], generic_Nm[t.joint][sel], "C0--", label="generic")
            ax.plot(q[sel], calibrated_Nm[t.joint][sel], "C3-", label="calibrated")
            fixed = [f"{_short(n)} {float(np.round(np.degrees(t.angles_rad[sel][0, i]))) + 0.0:.0f}°"
                     for i, n in enumerate(t.angle_names) if n != t.dof]
            ax.set_title(f"{t.joint} block {c + 1} ({name_list(fixed)})", fontsize=9)
            ax.set_xlabel(f"{t.dof} (deg)")
            ax.set_ylabel("passive moment (N m)")
            ax.grid(alpha=0.3)
            if r == 0 and c == 0:
                ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def save_passive_fit_figure(fig, path: str | os.PathLike) -> Path:
    """Write the figure as a PNG at :data:`PASSIVE_FIT_DPI` to ``path``."""
    path = Path(path)
    fig.savefig(path, dpi=PASSIVE_FIT_DPI)
    return path

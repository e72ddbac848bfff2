"""A lab trial in OpenSim's frame and SI units: markers and force plates."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Markers", "Plate", "LabTrial", "UP", "horizontal", "RMS_LIMIT_M", "MAX_LIMIT_M"]

#: OpenSim's vertical axis (y) in its ground frame.
UP = np.array([0.0, 1.0, 0.0])

#: OpenSim's best practice for marker errors (Hicks et al. 2015, J Biomech Eng 137:020905): the
#: RMS marker error of a pose stays under 2 cm ...
RMS_LIMIT_M = 0.02
#: ... and its largest marker error under 4 cm
MAX_LIMIT_M = 0.04


def horizontal(xyz: np.ndarray) -> np.ndarray:
    """The horizontal components (x, z) of points in OpenSim's frame (last axis of size 3)."""
    return np.asarray(xyz)[..., [0, 2]]


@dataclass
class Markers:
    """Marker trajectories: ``xyz`` (frames x markers x 3) in metres, NaN where a marker is missing;
    ``data_rate_hz``: the sampling rate the file states, when it states one."""

    time: np.ndarray
    names: list[str]
    xyz: np.ndarray
    data_rate_hz: float | None = None

    @property
    def rate_hz(self) -> float:
        if self.data_rate_hz:
            return float(self.data_rate_hz)
        return float(1.0 / np.median(np.diff(self.time))) if len(self.time) > 1 else 0.0

    def uniform_time(self) -> np.ndarray | None:
        """The frames' times on the stated rate's grid (first time + i / rate) when the file's
        times are that grid rounded (off by less than a quarter frame, e.g. 0.017 for 1/60 s),
        ``None`` when they are the grid already or not a rounding of it."""
        if not self.data_rate_hz or len(self.time) < 2:
            return None
        grid = self.time[0] + np.arange(len(self.time)) / self.data_rate_hz
        off = float(np.max(np.abs(self.time - grid)))
        return grid if 1e-7 < off < 0.25 / self.data_rate_hz else None

    def marker(self, name: str) -> np.ndarray:
        return self.xyz[:, self.names.index(name), :]


@dataclass
class Plate:
    """One force plate: the force (N) and moment (N m) of the ground on the body, in OpenSim's
    ground frame, the moment taken about ``centre`` (the middle of the plate's surface, m);
    ``corners`` (4 x 3, m) outline the surface."""

    number: int
    time: np.ndarray
    force: np.ndarray
    moment: np.ndarray
    centre: np.ndarray
    corners: np.ndarray
    offset_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    offset_moment: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def vertical(self) -> np.ndarray:
        return self.force @ UP

    def centre_of_pressure(self, threshold_n: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Centre of pressure on the surface (n x 3, m) and free moment about the vertical (n, N m).

        From the moment about the surface centre: the moment of the force at a point ``d`` of
        the surface plus a moment ``T`` about the vertical ``n``, ``M = d x F + T n``, gives
        ``d = n x M / (n . F)`` (since ``n . d = 0``) and ``T = (M - d x F) . n``. Samples
        whose vertical force is at or below ``threshold_n`` are zero.
        """
        fv = self.vertical()
        on = fv > max(threshold_n, 1e-9)
        d = np.zeros_like(self.force)
        d[on] = np.cross(UP, self.moment[on]) / fv[on, None]
        free = np.zeros(len(fv))
        free[on] = (self.moment[on] - np.cross(d[on], self.force[on])) @ UP
        cop = np.where(on[:, None], self.centre + d, 0.0)
        return cop, free


@dataclass
class LabTrial:
    """What a lab's file holds, in OpenSim's frame: markers, plates, and how it was turned
    (``rotation``: lab coordinates -> OpenSim's, ``p_osim = rotation @ p_lab``)."""

    path: Path
    markers: Markers
    plates: list[Plate]
    rotation: np.ndarray
    notes: dict = field(default_factory=dict)

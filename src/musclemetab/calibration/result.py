"""Results of a passive calibration: the solves in memory and the folder they are written to.

:class:`CalibrationResult` holds what :func:`.passive.calibrate_passive` computed: the data,
the calibrated solve and the generic-parameter reference, with :meth:`~CalibrationResult.fit_summary`.
:class:`PassiveCalibration` is what a calibration folder holds, typed: the calibrated
parameters (``passive_parameters.csv``, ``muscle,kPE,s0,sM``, 10 significant digits) and the
fit summary (``fit.json``); :meth:`PassiveCalibration.write` writes the folder atomically
(with the figure ``passive_fit.png`` when one is given) and :meth:`PassiveCalibration.load`
reads it back.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputFileError
from .problem import KPE_BOUNDS, S0_BOUNDS, SM_FIXED, PassiveSolution
from .trials import CalibrationData

__all__ = ["PARAMETERS_FILE", "FIT_FILE", "FIGURE_FILE", "CalibrationResult", "PassiveCalibration", "parameters_csv"]

PARAMETERS_FILE = "passive_parameters.csv"
FIT_FILE = "fit.json"
FIGURE_FILE = "passive_fit.png"
#: Distance (in the parameter's units) within which a calibrated value counts as on its bound.
AT_BOUND = 0.01


def parameters_csv(parameters: Mapping[str, Sequence[float]]) -> str:
    """The text of ``passive_parameters.csv``: ``muscle,kPE,s0,sM``, one row per muscle
    (``sM`` 0.6 when a muscle gives two values), 10 significant digits."""
    lines = ["muscle,kPE,s0,sM"]
    for m, p in parameters.items():
        k, s = float(p[0]), float(p[1])
        sm = float(p[2]) if len(p) > 2 else SM_FIXED
        lines.append(f"{m},{k:.10g},{s:.10g},{sm:.10g}")
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class CalibrationResult:
    """The calibration data, the calibrated solve and the generic-parameter reference."""

    data: CalibrationData
    calibrated: PassiveSolution
    generic: PassiveSolution

    def fit_summary(self) -> dict:
        """RMS errors (per joint and per block), largest reserves, solver statistics of both
        solves, parameters on a bound, bounds, ``kT``, muscles per trial and the sources."""
        d = self.data
        at_bound = {}
        for m, (k, s, _) in self.calibrated.parameters.items():
            flags = []
            if k - KPE_BOUNDS[0] < AT_BOUND:
                flags.append("kPE lower")
            if KPE_BOUNDS[1] - k < AT_BOUND:
                flags.append("kPE upper")
            if s - S0_BOUNDS[0] < AT_BOUND:
                flags.append("s0 lower")
            if S0_BOUNDS[1] - s < AT_BOUND:
                flags.append("s0 upper")
            at_bound[m] = flags
        return {
            "units": "N m",
            "rms_generic_Nm": self.generic.rms_Nm(d),
            "rms_calibrated_Nm": self.calibrated.rms_Nm(d),
            "rms_per_block_generic_Nm": self.generic.rms_per_block_Nm(d),
            "rms_per_block_calibrated_Nm": self.calibrated.rms_per_block_Nm(d),
            "max_abs_reserve_generic_Nm": {j: float(np.abs(r).max()) for j, r in self.generic.reserve_Nm.items()},
            "max_abs_reserve_calibrated_Nm": {
                j: float(np.abs(r).max()) for j, r in self.calibrated.reserve_Nm.items()
            },
            "solver": {"calibrated": self.calibrated.stats, "generic": self.generic.stats},
            "parameters_at_bound": at_bound,
            "bounds": {"kPE": list(KPE_BOUNDS), "s0": list(S0_BOUNDS), "sM": SM_FIXED},
            "tendon_stiffness": {m: float(k) for m, k in zip(d.muscles, d.tendon_stiffness)},
            "muscles_per_trial": {t.joint: list(t.muscles) for t in d.trials},
            "source": d.source,
        }

    def record(self) -> PassiveCalibration:
        """The calibrated parameters and the fit summary, as written to a folder."""
        return PassiveCalibration(dict(self.calibrated.parameters), self.fit_summary())


@dataclass(frozen=True)
class PassiveCalibration:
    """A calibration folder's content: ``parameters`` (muscle -> (kPE, s0, sM)) and ``fit``
    (the fit summary, :meth:`CalibrationResult.fit_summary`)."""

    parameters: dict
    fit: dict

    def write(self, out_dir: str | os.PathLike, figure=None) -> dict[str, Path]:
        """Write :data:`PARAMETERS_FILE` and :data:`FIT_FILE` (and :data:`FIGURE_FILE` from
        ``figure``, a matplotlib figure, when given) into ``out_dir`` atomically: the folder
        appears complete or not at all, its files listed in the folder's ``.musclemetab-files``
        (a file the package did not write is not replaced). Returns ``{file name: path}``."""
        from ..io import atomic_directory

        out_dir = Path(out_dir)
        names = [PARAMETERS_FILE, FIT_FILE]
        with atomic_directory(out_dir, mark=True) as tmp:
            (tmp / PARAMETERS_FILE).write_text(parameters_csv(self.parameters), encoding="utf-8")
            (tmp / FIT_FILE).write_text(json.dumps(self.fit, indent=2) + "\n", encoding="utf-8")
            if figure is not None:
                from ..report.passive_figure import save_passive_fit_figure

                save_passive_fit_figure(figure, tmp / FIGURE_FILE)
                names.append(FIGURE_FILE)
        return {name: out_dir / name for name in names}

    @classmethod
    def load(cls, folder: str | os.PathLike) -> PassiveCalibration:
        """Read a folder written by :meth:`write` (parameters to the file's 10 digits)."""
        from ..passive import read_passive_parameters as _read

        folder = Path(folder)
        missing = [n for n in (PARAMETERS_FILE, FIT_FILE) if not (folder / n).is_file()]
        if missing:
            raise InputFileError(
                f"{folder}: no {' and no '.join(missing)}; give a folder written by musclemetab calibrate-passive"
            )
        try:
            fit = json.loads((folder / FIT_FILE).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputFileError(f"{folder / FIT_FILE}: cannot be read as JSON ({exc}); write the calibration again") from None
        values = _read(folder / PARAMETERS_FILE).values
        return cls({str(m): tuple(float(x) for x in v) for m, v in values.items()}, fit)

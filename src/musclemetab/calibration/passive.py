"""Passive force-length calibration from passive joint moments: the workflow and the parameter files.

:func:`calibrate_passive` loads one leg's calibration trials (:mod:`.trials`), solves the
calibration problem (:mod:`.problem`) and the same problem with the generic parameters
(``kPE = 4, s0 = 1``, the reference of every fit-quality figure) and returns a
:class:`.result.CalibrationResult`; :func:`write_calibration` writes its folder
(``passive_parameters.csv``, ``fit.json`` and the figure ``passive_fit.png``,
:mod:`musclemetab.report.passive_figure`). :func:`read_passive_parameters` reads a parameter
file (the calibration's CSV or the reference implementation's MAT file),
:func:`write_passive_parameters` writes one and :func:`mirror_to_left` copies right-leg values
to the left leg. The root-finding check of the equilibria is :mod:`.equilibrium`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

from .problem import KPE_GENERIC, S0_GENERIC, SM_FIXED, solve_passive
from .result import CalibrationResult, parameters_csv
from .trials import load_calibration_data

if TYPE_CHECKING:
    from ..redundancy.ipopt import SolverOptions

__all__ = [
    "calibrate_passive",
    "write_calibration",
    "read_passive_parameters",
    "write_passive_parameters",
    "mirror_to_left",
]


def calibrate_passive(
    model_path: str | os.PathLike,
    trials: str | os.PathLike | Mapping,
    *,
    tendon_stiffness: Mapping[str, float] | None = None,
    use_cache: bool = True,
    options: SolverOptions | None = None,
    side: str = "r",
) -> CalibrationResult:
    """Load the trials, solve the calibration NLP and the generic-parameter reference (``side``: see
    :func:`.trials.load_calibration_data`; ``options``: IPOPT's settings of both solves, see
    :func:`.problem.solve_passive`)."""
    data = load_calibration_data(model_path, trials, tendon_stiffness=tendon_stiffness, use_cache=use_cache,
                                 side=side)
    generic = solve_passive(data, {m: (KPE_GENERIC, S0_GENERIC, SM_FIXED) for m in data.muscles}, options=options)
    calibrated = solve_passive(data, None, options=options)
    return CalibrationResult(data, calibrated, generic)


def write_calibration(result: CalibrationResult, out_dir: str | os.PathLike) -> dict:
    """Write ``passive_parameters.csv``, ``fit.json`` and ``passive_fit.png`` atomically."""
    from ..report.passive_figure import passive_fit_figure

    figure = passive_fit_figure(result.data.trials, result.generic.moments_Nm, result.calibrated.moments_Nm)
    return result.record().write(out_dir, figure=figure)


def write_passive_parameters(path: str | os.PathLike, parameters: Mapping[str, Sequence[float]]) -> Path:
    """Write ``muscle,kPE,s0,sM`` (one row per muscle, names with side suffix), atomically, listed
    in the folder's ``.musclemetab-files`` (a file the package did not write is not replaced)."""
    from ..io import atomic_write_text

    return atomic_write_text(path, parameters_csv(parameters), mark=True)


def read_passive_parameters(path: str | os.PathLike) -> dict:
    """Passive force-length parameters ``{muscle: (kPE, s0, sM)}`` from a file.

    Accepts the ``passive_parameters.csv`` written by :func:`write_calibration` (columns
    ``muscle,kPE,s0,sM``) or the reference implementation's ``passiveMoments.mat``
    (calibrated values of ``sim.Results.onlyParam``; ``sM = 0.6``). Parsing is done by
    :func:`musclemetab.passive.read_passive_parameters` (the reader the
    muscle redundancy solver uses); entries with non-finite values (the MAT file's left
    leg) are left out. Use :func:`mirror_to_left` to copy right-leg values to the left leg.
    """
    from ..passive import read_passive_parameters as _read

    values = _read(path).values
    return {
        str(m): (float(v[0]), float(v[1]), float(v[2]))
        for m, v in values.items()
        if all(math.isfinite(float(x)) for x in v)
    }


def mirror_to_left(parameters: Mapping[str, Sequence[float]]) -> dict:
    """Copy every ``*_r`` entry to ``*_l`` (symmetry), keeping existing ``*_l`` entries."""
    out = dict(parameters)
    for m, p in parameters.items():
        if m.endswith("_r"):
            out.setdefault(m[:-2] + "_l", tuple(p))
    return out

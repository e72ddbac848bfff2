"""Passive force-length parameters by muscle name (``kPE``, ``s0``, ``sM``) and their files.

The calibration writes them (``passive_parameters.csv``), the solver's EFFORT-CAL, EFFORT-TEN
and EMG-TEN workflows read them; the study's ``passiveMoments.mat`` is read too. Names are
matched by muscle name; a table without side suffix (``soleus``) applies to both ``soleus_r``
and ``soleus_l``, and a value for one side is used for the other when the table has no value
for it (the study copies right-leg values to the left leg).
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .errors import InputFileError, MissingColumnError, UnknownMuscleError
from .messages import name_list

__all__ = ["PassiveParameters", "read_passive_parameters", "generic_passive_parameters",
           "reference_passive_parameters", "base_name", "PASSIVE_RANGES"]

GENERIC_KPE, GENERIC_S0, GENERIC_SM = 4.0, 1.0, 0.6
#: Plausible ranges of passive parameters read from a file (generic 4, 1, 0.6; the study's
#: calibration bounds kPE to 3-5 and s0 to 0.8-1.2). Values outside are typos or other
#: conventions, and overflow the exponential passive curve.
PASSIVE_RANGES = {"kPE": (0.1, 50.0), "s0": (0.25, 4.0), "sM": (0.05, 2.0)}


def base_name(muscle: str) -> str:
    """``soleus_r`` -> ``soleus``; names without a side suffix are returned unchanged."""
    if muscle.endswith(("_r", "_l")):
        return muscle[:-2]
    return muscle


def _mirror(muscle: str) -> str | None:
    if muscle.endswith("_r"):
        return muscle[:-2] + "_l"
    if muscle.endswith("_l"):
        return muscle[:-2] + "_r"
    return None


@dataclass(frozen=True)
class PassiveParameters:
    """Passive force-length parameters by muscle name: ``{name: (kPE, s0, sM)}`` and the source."""

    values: Mapping[str, tuple[float, float, float]]
    source: str

    def lookup(self, muscle: str) -> tuple[float, float, float] | None:
        for key in (muscle, _mirror(muscle), base_name(muscle)):
            if key is None:
                continue
            v = self.values.get(key)
            if v is not None and all(math.isfinite(x) for x in v):
                return v
        return None

    def for_muscles(self, muscles: Sequence[str]) -> np.ndarray:
        """``(M, 3)`` array of kPE, s0, sM; raises :class:`UnknownMuscleError` for gaps."""
        out, missing = [], []
        for m in muscles:
            v = self.lookup(m)
            if v is None:
                missing.append(m)
                v = (math.nan,) * 3
            out.append(v)
        not_finite = [m for m in missing if any(self.values.get(k) is not None for k in
                                                (m, _mirror(m), base_name(m)) if k is not None)]
        if not_finite:
            raise InputFileError(
                f"{self.source}: the passive parameters (kPE, s0, sM) of {name_list(not_finite)} are not finite "
                "numbers (inf or NaN); give finite values (calibrate again, or correct the file)"
            )
        if missing:
            raise UnknownMuscleError(
                f"{self.source}: no passive parameters for {name_list(missing)}; the calibration must "
                "cover every muscle of the problem: calibrate this model's passive muscles (musclemetab "
                "calibrate-passive --model MODEL --trials FOLDER --out DIR, then --passive DIR/passive_parameters.csv), "
                "or use the effort-gen workflow"
            )
        return np.array(out, dtype=float)


def generic_passive_parameters(muscles: Sequence[str]) -> PassiveParameters:
    return PassiveParameters({m: (GENERIC_KPE, GENERIC_S0, GENERIC_SM) for m in muscles}, "generic")


def reference_passive_parameters() -> PassiveParameters:
    """The published passive calibration shipped with the package (side-free names, sM = 0.6)."""
    from .properties import study_passive_parameters

    values = {m: (kpe, s0, GENERIC_SM) for m, (kpe, s0) in study_passive_parameters().items()}
    return PassiveParameters(values, "package:study_passive_parameters.csv (published calibration)")


def read_passive_parameters(path: str | os.PathLike) -> PassiveParameters:
    """Read calibrated passive parameters from ``passive_parameters.csv`` or ``passiveMoments.mat``."""
    path = Path(path)
    if path.is_dir():
        raise InputFileError(f"{path} is a folder, not a passive-parameter file; give the path of the file")
    if not path.is_file():
        raise InputFileError(f"{path}: no such passive-parameter file; check the --passive path")
    if path.suffix.lower() == ".mat":
        return _read_passive_mat(path)
    if path.suffix.lower() in (".csv", ".txt"):
        return _read_passive_csv(path)
    raise InputFileError(
        f"{path}: unknown passive-parameter format '{path.suffix}'; give a passive_parameters.csv "
        "(columns muscle,kPE,s0,sM) or the study's passiveMoments.mat"
    )


def _read_passive_csv(path: Path) -> PassiveParameters:
    try:
        text = path.read_text(encoding="utf-8-sig")  # with or without a byte-order mark
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: cannot be read ({exc})") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    cols = [c.strip() for c in (reader.fieldnames or [])]
    need = ["muscle", "kPE", "s0"]
    missing = [c for c in need if c not in cols]
    if missing:
        raise MissingColumnError(
            f"{path}: missing column{'s' if len(missing) > 1 else ''} {name_list(missing)}; a passive "
            f"parameter table has columns muscle,kPE,s0,sM (found {', '.join(cols) or 'none'})"
        )
    values = {}
    for i, row in enumerate(reader, start=2):
        row = {k.strip(): (v or "").strip() for k, v in row.items() if k is not None}
        try:
            kpe, s0 = float(row["kPE"]), float(row["s0"])
            sm = float(row["sM"]) if row.get("sM") else GENERIC_SM
        except ValueError:
            raise InputFileError(f"{path}: row {i} ('{row.get('muscle')}') holds a value that is not a number") from None
        if not (kpe > 0 and sm > 0 and math.isfinite(s0)):
            raise InputFileError(f"{path}: row {i} ('{row['muscle']}'): kPE and sM must be positive, s0 finite")
        values[row["muscle"]] = (kpe, s0, sm)
    if not values:
        raise InputFileError(f"{path}: no rows; the passive parameter table is empty")
    _check_passive_ranges(values, path)
    return PassiveParameters(values, str(path))


def _check_passive_ranges(values: Mapping[str, tuple[float, float, float]], path) -> None:
    """:class:`InputFileError` naming the file, muscle and parameter outside :data:`PASSIVE_RANGES`."""
    for muscle, triple in values.items():
        for name, v in zip(("kPE", "s0", "sM"), triple):
            lo, hi = PASSIVE_RANGES[name]
            if math.isfinite(v) and not lo <= v <= hi:
                raise InputFileError(
                    f"{path}: muscle '{muscle}' has {name} = {v:g}, outside the plausible {lo:g}-{hi:g}; "
                    "fix the value (the generic values are kPE 4, s0 1, sM 0.6)"
                )


def _read_passive_mat(path: Path) -> PassiveParameters:
    import scipy.io

    try:
        mat = scipy.io.loadmat(str(path), squeeze_me=True, struct_as_record=False)
    except Exception as exc:  # scipy raises several types on malformed files
        raise InputFileError(f"{path}: not a readable MATLAB file ({exc})") from None
    try:
        only = mat["sim"].Results.onlyParam
        names = [str(n) for n in np.atleast_1d(only.MuscleNames)]
        kpe = np.atleast_1d(np.asarray(only.calParam.kpe, dtype=float))
        ksf = np.atleast_1d(np.asarray(only.calParam.ksf, dtype=float))
    except (KeyError, AttributeError):
        raise InputFileError(
            f"{path}: no sim.Results.onlyParam.calParam (kpe, ksf) with MuscleNames; this is not a "
            "passive calibration result of the study"
        ) from None
    if not (len(names) == kpe.size == ksf.size):
        raise InputFileError(f"{path}: {len(names)} muscle names but {kpe.size} kpe and {ksf.size} ksf values")
    values = {n: (float(k), float(s), GENERIC_SM) for n, k, s in zip(names, kpe, ksf)}
    _check_passive_ranges(values, path)
    return PassiveParameters(values, str(path))

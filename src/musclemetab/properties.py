"""Per-muscle properties: one table, and the rules that individualise a muscle.

The package table (``musclemetab/data/muscle_properties.csv``) holds, per muscle of the
Rajagopal (2015) lower limb (side-free names: ``soleus``; models append ``_r``/``_l``):
slow-twitch fraction (Uchida et al. 2016 compilation, 0.5 where unknown), share of total
lower-limb muscle volume (Handsfield et al. 2014, split equally over the model's sub-parts),
function groups, tendon-stiffness and passive-calibration coupling groups, the default EMG
channel of the example data, and the published calibrated passive parameters.

Rules (see ``docs/method.md``):

* total lower-limb muscle volume, Handsfield et al. (2014) regression as used by the study:
  ``V_total [cm^3] = 47 * m_body [kg] * h [m] + 1285``;
* muscle volume ``V_i = volume_percent_i / 100 * V_total``;
* muscle mass ``m_i = rho * V_i`` with ``rho = 1059.7 kg/m^3``;
* individualised maximal isometric force ``F0_i = sigma * V_i / lMo_i`` with specific
  tension ``sigma = 0.6 MPa`` and the (scaled) optimal fibre length (PCSA = V/lMo, no
  pennation factor). This reproduces the example model's forces to better than 1e-6.

Names are always matched by muscle name and side, never by position.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from importlib import resources

import numpy as np
import pandas as pd

from .errors import OptionError, UnknownMuscleError

__all__ = [
    "MUSCLE_DENSITY_KG_PER_M3",
    "SPECIFIC_TENSION_PA",
    "property_table",
    "split_side",
    "muscle_property",
    "slow_twitch_fraction",
    "total_muscle_volume_m3",
    "muscle_volumes_m3",
    "muscle_masses_kg",
    "individualised_max_isometric_force_N",
]

MUSCLE_DENSITY_KG_PER_M3 = 1059.7
SPECIFIC_TENSION_PA = 0.6e6
HANDSFIELD_SLOPE_CM3_PER_KG_M = 47.0
HANDSFIELD_INTERCEPT_CM3 = 1285.0


@functools.lru_cache(maxsize=1)
def property_table() -> pd.DataFrame:
    """The package's muscle property table, indexed by side-free muscle name."""
    with resources.files("musclemetab").joinpath("data/muscle_properties.csv").open() as f:
        df = pd.read_csv(f, comment="#", keep_default_na=False, na_values=[""])
    for col in ("function_groups", "sign_changing_dofs", "tendon_stiffness_group",
                "passive_calibration_trials", "passive_coupling_group", "emg_channel"):
        df[col] = df[col].fillna("")
    return df.set_index("muscle")


def split_side(name: str) -> tuple[str, str]:
    """``'soleus_r' -> ('soleus', 'r')``; names without a side suffix get ``''``."""
    if len(name) > 2 and name[-2] == "_" and name[-1] in "rl":
        return name[:-2], name[-1]
    return name, ""


def _rows(names: Sequence[str], what: str) -> pd.DataFrame:
    table = property_table()
    base = [split_side(n)[0] for n in names]
    missing = [n for n, b in zip(names, base) if b not in table.index]
    if missing:
        raise UnknownMuscleError(
            f"no {what} for muscle{'s' if len(missing) > 1 else ''} {', '.join(missing)} in the muscle "
            "property table; the table covers the Rajagopal lower-limb muscles "
            f"({', '.join(table.index[:5])}, ...): rename the muscles or pass the values explicitly"
        )
    return table.loc[base]


def muscle_property(names: Sequence[str], column: str) -> np.ndarray:
    """One column of the property table for ``names`` (with or without side suffix)."""
    if column not in property_table().columns:
        raise OptionError(f"the muscle property table has no column '{column}'")
    return _rows(names, column)[column].to_numpy()


def slow_twitch_fraction(names: Sequence[str], default: float | None = None) -> np.ndarray:
    """Slow-twitch fibre fraction per muscle.

    With ``default`` given, muscles absent from the table get it (the study used 0.5);
    without, they raise :class:`UnknownMuscleError`.
    """
    if default is None:
        return _rows(names, "slow-twitch fraction")["slow_twitch_fraction"].to_numpy(dtype=float)
    table = property_table()
    return np.array(
        [float(table.at[split_side(n)[0], "slow_twitch_fraction"]) if split_side(n)[0] in table.index else default
         for n in names]
    )


def _check_subject(body_mass_kg: float, height_m: float) -> None:
    if not (np.isfinite(body_mass_kg) and 10.0 <= body_mass_kg <= 400.0):
        raise OptionError(f"body mass {body_mass_kg!r} kg is not plausible; give the mass in kilograms")
    if not (np.isfinite(height_m) and 0.5 <= height_m <= 2.6):
        raise OptionError(f"height {height_m!r} m is not plausible; give the height in metres")


def total_muscle_volume_m3(body_mass_kg: float, height_m: float) -> float:
    """Total lower-limb muscle volume, ``(47 m h + 1285) cm^3``, in m^3."""
    _check_subject(body_mass_kg, height_m)
    return (HANDSFIELD_SLOPE_CM3_PER_KG_M * body_mass_kg * height_m + HANDSFIELD_INTERCEPT_CM3) * 1e-6


def muscle_volumes_m3(names: Sequence[str], body_mass_kg: float, height_m: float) -> np.ndarray:
    """Volume of each muscle (m^3): its table share of the total lower-limb volume."""
    share = _rows(names, "volume share")["volume_percent"].to_numpy(dtype=float) / 100.0
    return share * total_muscle_volume_m3(body_mass_kg, height_m)


def muscle_masses_kg(names: Sequence[str], body_mass_kg: float, height_m: float) -> np.ndarray:
    """Mass of each muscle (kg): volume times 1059.7 kg/m^3."""
    return MUSCLE_DENSITY_KG_PER_M3 * muscle_volumes_m3(names, body_mass_kg, height_m)


def individualised_max_isometric_force_N(
    names: Sequence[str],
    optimal_fiber_length_m: Sequence[float],
    body_mass_kg: float,
    height_m: float,
    specific_tension_Pa: float = SPECIFIC_TENSION_PA,
) -> np.ndarray:
    """Maximal isometric force ``sigma * V_i / lMo_i`` (N) from body mass and height."""
    lmo = np.asarray(optimal_fiber_length_m, dtype=float)
    if lmo.shape != (len(names),):
        raise OptionError(f"{len(names)} muscle names but {lmo.size} optimal fibre lengths")
    if np.any(~np.isfinite(lmo)) or np.any(lmo <= 0):
        raise OptionError("optimal fibre lengths must be positive, in metres")
    return specific_tension_Pa * muscle_volumes_m3(names, body_mass_kg, height_m) / lmo

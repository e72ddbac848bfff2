"""Per-muscle properties: one anatomical table, aliases per model family, and the rules.

Two package tables (parsed once, see ``docs/muscles.md``):

* ``data/anatomical_muscles.csv``: one row per anatomical muscle of the lower-limb volume
  regression (side-free id such as ``gluteus_medius``): share of total lower-limb muscle
  volume (Handsfield et al. 2014, as coded by the study), slow-twitch fraction (Uchida et
  al. 2016 compilation, 0.5 where unknown), specific tension, function groups, the tendon
  and EMG scale groups of EMG-TEN, the passive-calibration trials and coupling group, the
  example data's EMG channel and the report's default muscle list;
* ``data/muscle_aliases.csv``: model muscle name (side-free) -> anatomical muscle(s), per
  model family (Rajagopal, gait2392 / gait2354 / Delp 1990 / Hamner 2010 / Arnold 2010,
  gait10dof18musc), with an optional explicit volume share.

Rules:

* total lower-limb muscle volume, Handsfield et al. (2014) regression as used by the study:
  ``V_total [cm^3] = 47 * m_body [kg] * h [m] + 1285``;
* a model muscle's volume is ``sum_a f_a * volume_percent_a / 100 * V_total`` over the
  anatomical muscles ``a`` it stands for, with ``f_a`` its explicit share (the study's
  model: equal splits), else its maximal isometric force over the summed force of all
  muscles of the same side standing for ``a`` (split muscles share, lumped ones add);
* slow-twitch fraction and specific tension: volume-weighted mean over the parts;
* muscle mass ``m_i = rho * V_i`` with ``rho = 1059.7 kg/m^3``;
* a lumped muscle of a reduced model, whose maximal isometric force stands for anatomical
  muscles the model has no muscle for (e.g. a vastus carrying the force of all three vasti):
  ``m_i = rho * F0_i * lMo_i / sigma_model`` with the model's own specific tension, and one
  :class:`~musclemetab.errors.LumpedMuscleWarning` (:func:`lumped_muscles`);
* a muscle the tables cannot place: ``m_i = F0_i / sigma * rho * lMo_i`` (the rule of
  OpenSim's metabolic probes, with the package's ``sigma = 0.6 MPa``), slow-twitch
  fraction 0.5, and one :class:`~musclemetab.errors.MuscleTableWarning` naming every such
  muscle (``strict=True``: :class:`~musclemetab.errors.UnknownMuscleError` instead);
* individualised maximal isometric force ``F0_i = sigma * V_i / lMo_i`` (PCSA = V/lMo, no
  pennation factor). This reproduces the example model's forces to better than 1e-6.

Overrides per muscle (mass, slow-twitch fraction, specific tension, function groups,
anatomical placement) come from a CSV (:func:`read_muscle_properties`). Names are always
matched by muscle name and side (``_r``/``_l``, also ``_R``/``_L``; case-insensitive),
never by position.
"""

from __future__ import annotations

import csv
import functools
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from importlib import resources
from pathlib import Path

import numpy as np

from .errors import InputFileError, LumpedMuscleWarning, MuscleTableWarning, OptionError, UnknownMuscleError
from .messages import name_list, user_stacklevel

__all__ = [
    "MUSCLE_DENSITY_KG_PER_M3",
    "SPECIFIC_TENSION_PA",
    "FALLBACK_SLOW_TWITCH_FRACTION",
    "metabolic_properties",
    "MuscleRecord",
    "MuscleOverrides",
    "anatomical_table",
    "alias_table",
    "property_table",
    "model_family",
    "resolve_muscles",
    "read_muscle_properties",
    "as_overrides",
    "split_side",
    "muscle_property",
    "slow_twitch_fraction",
    "total_muscle_volume_m3",
    "muscle_volumes_m3",
    "muscle_masses_kg",
    "LumpedMuscle",
    "lumped_muscles",
    "individualised_max_isometric_force_N",
    "coupling_groups",
    "tendon_groups",
    "emg_scale_groups",
    "default_emg_mapping",
    "report_muscles",
    "study_passive_parameters",
    "tendon_literature",
    "unplaced_muscles",
    "warn_unplaced",
    "GROUPS",
    "DOF_GROUPS",
    "dof_group_pair",
    "has_function_group",
]

MUSCLE_DENSITY_KG_PER_M3 = 1059.7
SPECIFIC_TENSION_PA = 0.6e6
FALLBACK_SLOW_TWITCH_FRACTION = 0.5
HANDSFIELD_SLOPE_CM3_PER_KG_M = 47.0
HANDSFIELD_INTERCEPT_CM3 = 1285.0

_TEXT_COLUMNS = ("function_groups", "primary_group", "tendon", "emg_scale_group", "passive_calibration_trials",
                 "passive_coupling_group", "emg_channel", "lump_group")


_NUMBER_COLUMNS = ("volume_percent", "slow_twitch_fraction", "specific_tension_Pa", "report_order")


def _read_package_csv(name: str) -> list[dict[str, str]]:
    """The rows of a package table (``#`` lines are comments), each ``{column: text}``.

    Read with the standard library's :mod:`csv`, so that placing muscles (which every solve
    does) does not import pandas; :func:`anatomical_table` and :func:`alias_table` give the
    same rows as data frames."""
    with resources.files("musclemetab").joinpath(f"data/{name}").open(encoding="utf-8") as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


@functools.lru_cache(maxsize=1)
def _anatomical_rows() -> dict[str, dict]:
    """``{anatomical_muscle: {column: value}}`` in table order: numbers as floats (NaN when
    empty), text as strings ("" when empty)."""
    rows = {}
    for row in _read_package_csv("anatomical_muscles.csv"):
        key = row.pop("anatomical_muscle")
        rows[key] = {c: (float(v) if v.strip() else float("nan")) if c in _NUMBER_COLUMNS else v
                     for c, v in row.items()}
    return rows


@dataclass(frozen=True)
class _Alias:
    model_name: str
    key: str  # lower-case model name
    anatomical: tuple[str, ...]
    families: tuple[str, ...]
    volume_share: float  # NaN: split by maximal isometric force


@functools.lru_cache(maxsize=1)
def _aliases() -> tuple[_Alias, ...]:
    anat = _anatomical_rows()
    out = tuple(_Alias(r["model_name"], r["model_name"].lower(), tuple(r["anatomical_muscles"].split()),
                       tuple(r["family"].split()), float(Fraction(r["volume_share"])) if r["volume_share"] else np.nan)
                for r in _read_package_csv("muscle_aliases.csv"))
    bad = sorted({a for r in out for a in r.anatomical if a not in anat})
    if bad:  # pragma: no cover - package data consistency (tested)
        raise OptionError(f"muscle_aliases.csv names unknown anatomical muscles {name_list(bad)}")
    return out


def anatomical_table():
    """Anatomical muscles (side-free ids), a :class:`pandas.DataFrame` indexed by ``anatomical_muscle``."""
    import pandas as pd

    df = pd.DataFrame.from_dict(_anatomical_rows(), orient="index")
    df.index.name = "anatomical_muscle"
    return df


def alias_table():
    """Model muscle names (side-free) per family -> anatomical muscle(s) and explicit share.

    A :class:`pandas.DataFrame`, columns: ``model_name``, ``key`` (lower-case name),
    ``anatomical`` (tuple of ids), ``families`` (tuple), ``volume_share`` (float or NaN).
    """
    import pandas as pd

    return pd.DataFrame([{"model_name": a.model_name, "anatomical_muscles": " ".join(a.anatomical),
                          "family": " ".join(a.families), "volume_share": a.volume_share, "anatomical": a.anatomical,
                          "families": a.families, "key": a.key} for a in _aliases()])


def split_side(name: str) -> tuple[str, str]:
    """``'soleus_r' -> ('soleus', 'r')`` (also ``_R``/``_L``); no side suffix gives ``''``."""
    if len(name) > 2 and name[-2] == "_" and name[-1] in "rlRL":
        return name[:-2], name[-1].lower()
    return name, ""


def model_family(names: Sequence[str]) -> str:
    """The alias family that places most of ``names`` (ties: the family with fewer names)."""
    keys = {split_side(n)[0].lower() for n in names}
    aliases = _aliases()
    best, best_score = "", (0, 0)
    families = list(dict.fromkeys(f for a in aliases for f in a.families))
    for fam in families:
        in_fam = {a.key for a in aliases if fam in a.families}
        score = (len(keys & in_fam), -len(in_fam))
        if score[0] and score > best_score:
            best, best_score = fam, score
    return best


# ---------------------------------------------------------------------------------------
# Overrides
# ---------------------------------------------------------------------------------------

_OVERRIDE_COLUMNS = ("anatomical_muscles", "mass_kg", "slow_twitch_fraction", "specific_tension_Pa",
                     "function_groups")


@dataclass(frozen=True)
class MuscleOverrides:
    """Per-muscle overrides: ``{name: {column: value}}``; a side-free name covers both sides."""

    values: Mapping[str, Mapping[str, object]] = field(default_factory=dict)
    source: str = "overrides"

    def for_muscle(self, name: str) -> dict:
        base, _ = split_side(name)
        out: dict = {}
        for key in (base, base.lower(), name, name.lower()):
            out.update(self.values.get(key, {}))
        return out

    def __bool__(self) -> bool:
        return bool(self.values)

    def check_names(self, names: Sequence[str], *, tables: bool = False) -> None:
        """Raise :class:`UnknownMuscleError` for a row that names none of the muscles ``names``
        (a row matches a muscle by its name, or by its side-free name on either side).

        ``names`` must be all the model's muscles (a solve covers a subset); with ``tables``, a
        row naming a muscle of the package's alias table passes too (for callers that know only
        the solved muscles)."""
        bases = {split_side(n)[0].lower() for n in names}
        if tables:
            bases |= {a.key for a in _aliases()}
        unknown = [row for row in self.values if split_side(row)[0].lower() not in bases]
        if unknown:
            import difflib

            near = {row: difflib.get_close_matches(row, list(names), n=3, cutoff=0.6) for row in unknown}
            listed = "; ".join(f"'{row}'" + (f" (near: {', '.join(m)})" if m else "") for row, m in near.items())
            raise UnknownMuscleError(
                f"{self.source}: muscle row{'s' if len(unknown) > 1 else ''} {listed} name{'' if len(unknown) > 1 else 's'}"
                f" no muscle of the model; fix the name (the model's muscles: {', '.join(list(names)[:6])}"
                f"{', ...' if len(names) > 6 else ''})"
            )

    def with_column(self, column: str, values: Mapping[str, float] | None) -> "MuscleOverrides":
        """A copy with ``{muscle: value}`` set for one column (these take precedence)."""
        if not values:
            return self
        merged = {k: dict(v) for k, v in self.values.items()}
        for name, v in values.items():
            merged.setdefault(name, {})[column] = float(v)
        return MuscleOverrides(merged, self.source)


def _override_value(col: str, raw: str, where: str, error=InputFileError):
    if col == "anatomical_muscles":
        ids = tuple(raw.split())
        unknown = [a for a in ids if a not in _anatomical_rows()]
        if unknown:
            raise error(
                f"{where}: unknown anatomical muscle {name_list(unknown)}; use ids of the package table "
                f"(e.g. {', '.join(list(_anatomical_rows())[:3])}; see docs/muscles.md)"
            )
        return ids
    if col == "function_groups":
        return tuple(raw.split())
    try:
        v = float(raw)
    except ValueError:
        v = float("nan")
    lo, hi, what = _OVERRIDE_RANGES[col]
    ok = np.isfinite(v) and (lo <= v <= hi if col == "slow_twitch_fraction" else lo < v <= hi)
    if not ok:
        raise error(f"{where}: '{raw}' is not {what}")
    return v


#: Possible values of the numeric override columns: (low, high, what); 0 excluded but for the fraction
_OVERRIDE_RANGES = {
    "slow_twitch_fraction": (0.0, 1.0, "a fraction in [0, 1]"),
    "mass_kg": (0.0, 10.0, "a muscle mass in kg (above 0, at most 10 kg; the largest human muscles weigh "
                           "about 1 kg)"),
    "specific_tension_Pa": (0.0, 5e6, "a specific tension in Pa (above 0, at most 5e6 Pa; the literature gives "
                                      "1e5 to 1e6 Pa)"),
}


def read_muscle_properties(path: str | Path) -> MuscleOverrides:
    """Read a muscle-properties override CSV.

    Columns: ``muscle`` (model name; without side suffix it applies to both sides) and any
    of ``anatomical_muscles`` (space-separated ids of the anatomical table), ``mass_kg``,
    ``slow_twitch_fraction``, ``specific_tension_Pa``, ``function_groups``. Empty cells
    keep the table's value.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such muscle-properties file; check the --muscle-properties path")
    import pandas as pd

    try:
        df = pd.read_csv(path, comment="#", dtype=str, keep_default_na=False, skipinitialspace=True)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: not a readable CSV ({str(exc).splitlines()[0]})") from None
    if "muscle" not in df.columns:
        raise InputFileError(f"{path}: no 'muscle' column; expected columns muscle,{','.join(_OVERRIDE_COLUMNS)}")
    extra = [c for c in df.columns if c != "muscle" and c not in _OVERRIDE_COLUMNS]
    if extra:
        raise InputFileError(
            f"{path}: unknown column{'s' if len(extra) > 1 else ''} {name_list(extra)}; "
            f"allowed: muscle,{','.join(_OVERRIDE_COLUMNS)}"
        )
    values: dict[str, dict] = {}
    for i, row in df.iterrows():
        name = str(row["muscle"]).strip()
        if not name:
            raise InputFileError(f"{path}: line {i + 2} has no muscle name")
        if name in values:
            raise InputFileError(f"{path}: muscle '{name}' appears twice; give one line per muscle")
        values[name] = {
            c: _override_value(c, str(row[c]).strip(), f"{path}: muscle '{name}', column '{c}'")
            for c in _OVERRIDE_COLUMNS if c in df.columns and str(row[c]).strip()
        }
    return MuscleOverrides(values, str(path))


def as_overrides(overrides) -> MuscleOverrides:
    """A :class:`MuscleOverrides` from ``None``, a CSV path, a mapping or itself."""
    if overrides is None:
        return MuscleOverrides()
    if isinstance(overrides, MuscleOverrides):
        return overrides
    if isinstance(overrides, (str, Path)):
        return read_muscle_properties(overrides)
    return MuscleOverrides(_mapping_rows(overrides), "muscle properties")


def _mapping_rows(overrides: Mapping) -> dict:
    """``{muscle: {column: value}}`` given in Python, checked as a CSV's rows are (the columns of
    :func:`read_muscle_properties`, their ranges; ``anatomical_muscles`` and ``function_groups``
    as a space-separated string or a sequence of names): :class:`OptionError` naming the muscle."""
    rows = {}
    for name, row in overrides.items():
        if not isinstance(row, Mapping):
            raise OptionError(f"muscle properties: the entry of muscle '{name}' must map columns to values "
                              f"(e.g. {{'mass_kg': 0.5}}), not {row!r}")
        extra = [c for c in row if c not in _OVERRIDE_COLUMNS]
        if extra:
            raise OptionError(f"muscle properties: muscle '{name}': unknown column{'s' if len(extra) > 1 else ''} "
                              f"{name_list(extra)}; allowed: {', '.join(_OVERRIDE_COLUMNS)}")
        rows[str(name)] = {
            c: _override_value(c, " ".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v).strip(),
                               f"muscle properties: muscle '{name}', column '{c}'", OptionError)
            for c, v in row.items()
        }
    return rows


# ---------------------------------------------------------------------------------------
# Resolution
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MuscleRecord:
    """What the tables (and overrides) say of one model muscle."""

    name: str
    side: str
    anatomical: tuple[str, ...]  # anatomical ids; () = not placed
    volume_fraction: tuple[float, ...]  # fraction of each anatomical muscle's volume
    volume_percent: float  # share of total lower-limb muscle volume (%); NaN when not placed
    slow_twitch_fraction: float
    specific_tension_Pa: float
    function_groups: tuple[str, ...]
    tendon: str
    emg_scale_group: str
    coupling_group: str
    calibration_trials: str
    emg_channels: tuple[str, ...]
    mass_kg_override: float | None = None
    family: str = ""
    fallback: tuple[str, ...] = ()  # quantities taken from the fallback rule
    #: the group of the muscle's main action (``primary_group`` of the table; of a model muscle
    #: standing for several anatomical muscles, that of the largest by volume; with
    #: ``function_groups`` overridden, their first): "" when not placed
    primary_group: str = ""

    @property
    def placed(self) -> bool:
        return bool(self.anatomical)


def _forces(names: Sequence[str], f0) -> dict[str, float]:
    if f0 is None:
        return {}
    if isinstance(f0, Mapping):
        return {n: float(f0[n]) for n in names if n in f0}
    arr = np.asarray(f0, dtype=float)
    if arr.shape != (len(names),):
        raise OptionError(f"{len(names)} muscle names but {arr.size} maximal isometric forces")
    return dict(zip(names, arr.tolist()))


def _common(values: Sequence[str]) -> str:
    vals = set(values)
    return values[0] if len(vals) == 1 else ""


def resolve_muscles(
    names: Sequence[str],
    max_isometric_force_N=None,
    overrides=None,
    strict: bool = False,
    warn: bool = True,
) -> tuple[MuscleRecord, ...]:
    """Place each model muscle in the anatomical table (one record per name, same order).

    ``max_isometric_force_N`` (array aligned with ``names`` or ``{name: F0}``) sets the
    volume split of muscles without an explicit share. ``overrides``: a
    :class:`MuscleOverrides`, a CSV path or ``{name: {column: value}}``. Muscles the tables
    cannot place get slow-twitch fraction 0.5 and the fallback mass rule; they are named in
    one warning, or, with ``strict``, in an :class:`UnknownMuscleError`.
    """
    names = list(names)
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise OptionError(f"muscle names repeated: {name_list(dup)}")
    ov = as_overrides(overrides)
    anat = _anatomical_rows()
    family = model_family(names)
    lookup: dict[str, tuple[tuple[str, ...], float]] = {}
    for a in _aliases():
        if a.key not in lookup or family in a.families:
            lookup[a.key] = (a.anatomical, a.volume_share)
    forces = _forces(names, max_isometric_force_N)

    placement: dict[str, tuple[tuple[str, ...], float]] = {}
    for n in names:
        o = ov.for_muscle(n)
        if "anatomical_muscles" in o:
            placement[n] = (tuple(o["anatomical_muscles"]), np.nan)
        else:
            placement[n] = lookup.get(split_side(n)[0].lower(), ((), np.nan))
    # F0-proportional split over the muscles of one side standing for the same anatomical muscle
    sharers: dict[tuple[str, str], list[str]] = {}
    for n, (ids, share) in placement.items():
        if np.isnan(share):
            for a in ids:
                sharers.setdefault((a, split_side(n)[1]), []).append(n)

    def fraction(n: str, a: str) -> float:
        ids, share = placement[n]
        if not np.isnan(share):
            return share
        group = sharers[(a, split_side(n)[1])]
        if len(group) == 1:
            return 1.0
        if any(m not in forces for m in group):
            return float("nan")  # needs the forces; volumes and masses ask for them
        total = sum(forces[m] for m in group)
        return forces[n] / total

    records = []
    unplaced = []
    for n in names:
        o = ov.for_muscle(n)
        ids, _ = placement[n]
        side = split_side(n)[1]
        fb: list[str] = []
        if ids:
            rows = [anat[a] for a in ids]

            def column(c):
                return [r[c] for r in rows]

            frac = tuple(fraction(n, a) for a in ids)
            vol = np.array(frac) * np.array(column("volume_percent"), dtype=float)
            wvol = np.where(np.isnan(vol), np.array(column("volume_percent"), dtype=float), vol)
            w = wvol / wvol.sum() if wvol.sum() > 0 else np.full(len(ids), 1.0 / len(ids))
            vp = float(vol.sum())
            fst = float(w @ np.array(column("slow_twitch_fraction"), dtype=float))
            sigma = float(w @ np.array(column("specific_tension_Pa"), dtype=float))
            groups: list[str] = []
            for g in " ".join(column("function_groups")).split():
                if g not in groups:
                    groups.append(g)
            primary = column("primary_group")[int(np.argmax(w))] if len(ids) else ""
            tendon = _common(column("tendon"))
            emg_group = _common(column("emg_scale_group"))
            coupling = _common(column("passive_coupling_group"))
            trials = "+".join(dict.fromkeys(t for s in column("passive_calibration_trials") for t in s.split("+") if t))
            channels = tuple(c for c in column("emg_channel") if c)
        else:
            frac, vp, fst, sigma, groups = (), float("nan"), FALLBACK_SLOW_TWITCH_FRACTION, SPECIFIC_TENSION_PA, []
            primary = ""
            tendon = emg_group = coupling = trials = ""
            channels = ()
            if "mass_kg" not in o:
                fb.append("mass")
            if "slow_twitch_fraction" not in o:
                fb.append("slow_twitch_fraction")
        if fb:
            unplaced.append(n)
        records.append(MuscleRecord(
            name=n, side=side, anatomical=tuple(ids), volume_fraction=tuple(frac), volume_percent=vp,
            slow_twitch_fraction=float(o.get("slow_twitch_fraction", fst)),
            specific_tension_Pa=float(o.get("specific_tension_Pa", sigma)),
            function_groups=tuple(o.get("function_groups", groups)),
            tendon=tendon, emg_scale_group=emg_group, coupling_group=coupling, calibration_trials=trials,
            emg_channels=channels, mass_kg_override=o.get("mass_kg"), family=family, fallback=tuple(fb),
            primary_group=(o["function_groups"][0].split("/")[0] if o.get("function_groups") else primary),
        ))
    _report_unplaced(unplaced, strict, warn)
    return tuple(records)


def unplaced_muscles(names: Sequence[str], overrides=None) -> list[str]:
    """The muscles of ``names`` that take a fallback value (not placed by table or overrides)."""
    return [r.name for r in resolve_muscles(names, overrides=overrides, warn=False) if r.fallback]


def warn_unplaced(names: Sequence[str]) -> None:
    """The one :class:`MuscleTableWarning` naming every muscle in ``names`` (none: nothing)."""
    _report_unplaced(list(names), False, True)


def _report_unplaced(unplaced: Sequence[str], strict: bool, warn: bool) -> None:
    if not unplaced:
        return
    s = "s" if len(unplaced) > 1 else ""
    how = ("place them with a muscle-properties CSV (columns muscle,anatomical_muscles or "
           "muscle,mass_kg,slow_twitch_fraction; see docs/muscles.md): --muscle-properties on the command line, "
           "a study subject's muscle_properties")
    if strict:
        raise UnknownMuscleError(
            f"muscle{s} {name_list(unplaced)} not in the anatomical muscle table (--strict); {how}"
        )
    if warn:
        warnings.warn(
            f"muscle{s} {name_list(unplaced)} not in the anatomical muscle table: mass from F0/specific "
            f"tension x density x lMo, slow-twitch fraction 0.5; to override, {how}",
            MuscleTableWarning, stacklevel=user_stacklevel(),
        )


# ---------------------------------------------------------------------------------------
# Volumes, masses, strength
# ---------------------------------------------------------------------------------------


def check_subject(body_mass_kg: float, height_m: float) -> None:
    """Raise :class:`OptionError` unless the body mass (10-400 kg) and the height (0.5-2.6 m) are
    plausible for a person, i.e. given in kilograms and metres."""
    if not (np.isfinite(body_mass_kg) and 10.0 <= body_mass_kg <= 400.0):
        raise OptionError(f"body mass {body_mass_kg!r} kg is not plausible; give the mass in kilograms")
    if not (np.isfinite(height_m) and 0.5 <= height_m <= 2.6):
        raise OptionError(f"height {height_m!r} m is not plausible; give the height in metres")


def total_muscle_volume_m3(body_mass_kg: float, height_m: float) -> float:
    """Total lower-limb muscle volume, ``(47 m h + 1285) cm^3``, in m^3."""
    check_subject(body_mass_kg, height_m)
    return (HANDSFIELD_SLOPE_CM3_PER_KG_M * body_mass_kg * height_m + HANDSFIELD_INTERCEPT_CM3) * 1e-6


def _check_split(recs: Sequence[MuscleRecord]) -> None:
    """Muscles sharing a volume by maximal isometric force need the forces."""
    need = [r.name for r in recs if r.placed and np.isnan(r.volume_percent)]
    if need:
        raise OptionError(
            f"muscles {name_list(need)} share an anatomical muscle's volume in proportion to maximal isometric "
            "force; give the model's forces (max_isometric_force_N)"
        )


def _placed_records(names, max_isometric_force_N, overrides, what: str) -> tuple[MuscleRecord, ...]:
    recs = resolve_muscles(names, max_isometric_force_N, overrides, warn=False)
    _check_split(recs)
    missing = [r.name for r in recs if not r.placed]
    if missing:
        raise UnknownMuscleError(
            f"no {what} for muscle{'s' if len(missing) > 1 else ''} {name_list(missing)}: not in the anatomical "
            "muscle table; place them with a muscle-properties CSV (column anatomical_muscles) or see docs/muscles.md"
        )
    return recs


def muscle_volumes_m3(names: Sequence[str], body_mass_kg: float, height_m: float,
                      max_isometric_force_N=None, overrides=None) -> np.ndarray:
    """Volume of each muscle (m^3) from its anatomical share of the total lower-limb volume.

    The table's volume: a lumped muscle named after one part (:func:`lumped_muscles`) gets that
    part's volume here; its mass (:func:`muscle_masses_kg`) follows its force."""
    recs = _placed_records(names, max_isometric_force_N, overrides, "volume share")
    share = np.array([r.volume_percent for r in recs]) / 100.0
    return share * total_muscle_volume_m3(body_mass_kg, height_m)


def muscle_masses_kg(
    names: Sequence[str],
    body_mass_kg: float,
    height_m: float,
    max_isometric_force_N=None,
    optimal_fiber_length_m=None,
    overrides=None,
    strict: bool = False,
) -> np.ndarray:
    """Mass of each muscle (kg): table volume times 1059.7 kg/m^3.

    Muscles the table cannot place take ``F0 / sigma * rho * lMo`` when
    ``max_isometric_force_N`` and ``optimal_fiber_length_m`` are given (one warning naming
    them; ``strict``: an error); without them they raise :class:`UnknownMuscleError`.
    Lumped muscles (:func:`lumped_muscles`, which needs both arrays) take
    ``rho F0 lMo / sigma_model`` and are named in one :class:`LumpedMuscleWarning`.
    Override masses (``overrides``) are used as given.
    """
    names = list(names)
    recs = resolve_muscles(names, max_isometric_force_N, overrides, strict=strict, warn=False)
    _check_split([r for r in recs if r.mass_kg_override is None])
    v_total = total_muscle_volume_m3(body_mass_kg, height_m)
    forces = _forces(names, max_isometric_force_N)
    lmo = _forces(names, optimal_fiber_length_m)
    out = np.empty(len(names))
    missing = []
    for i, r in enumerate(recs):
        if r.mass_kg_override is not None:
            out[i] = r.mass_kg_override
        elif r.placed:
            out[i] = MUSCLE_DENSITY_KG_PER_M3 * r.volume_percent / 100.0 * v_total
        elif r.name in forces and r.name in lmo:
            out[i] = forces[r.name] / r.specific_tension_Pa * MUSCLE_DENSITY_KG_PER_M3 * lmo[r.name]
        else:
            missing.append(r.name)
    if missing:
        raise UnknownMuscleError(
            f"no volume share for muscle{'s' if len(missing) > 1 else ''} {name_list(missing)} in the anatomical "
            "muscle table; give the model's maximal isometric forces and optimal fiber lengths (fallback rule) "
            "or a muscle-properties CSV (see docs/muscles.md)"
        )
    _report_unplaced([r.name for r in recs if r.fallback], strict, True)
    lumps = _find_lumps(recs, forces, lmo, v_total)
    for i, r in enumerate(recs):
        if r.name in lumps:
            out[i] = lumps[r.name].mass_kg
    _report_lumps(lumps)
    return out


@dataclass(frozen=True)
class LumpedMuscle:
    """A model muscle whose maximal isometric force stands for more anatomical muscles than its name.

    ``own``: the anatomical muscle(s) its name places it on; ``absent``: the members of their
    lump groups that no muscle of the same side stands for; ``force_ratio``:
    ``F0 lMo / (sigma_model V_table)``, the force over the force its own part would have in the
    model (1 for a muscle that is not lumped); ``threshold``: ``sqrt((V_own + V_absent) / V_own)``,
    the ratio above which it is taken as the lump; ``mass_kg = rho F0 lMo / sigma_model``.
    """

    name: str
    own: tuple[str, ...]
    absent: tuple[str, ...]
    table_mass_kg: float
    mass_kg: float
    force_ratio: float
    threshold: float
    model_specific_tension_Pa: float


def lumped_muscles(names: Sequence[str], body_mass_kg: float, height_m: float, max_isometric_force_N,
                   optimal_fiber_length_m, overrides=None) -> dict[str, LumpedMuscle]:
    """The muscles of ``names`` taken as lumps of several anatomical muscles, ``{name: LumpedMuscle}``.

    Reduced models represent a group of synergists (column ``lump_group`` of the anatomical
    table: the vasti, the gastrocnemii, the hamstrings, iliacus and psoas, the dorsiflexors, the
    adductors) by one muscle carrying their summed maximal isometric force, named after one of
    them (a ``vas_int`` for the three vasti) or after the group (gait10dof18musc's ``vasti``,
    which the alias table already places on all three). A muscle is taken as a lump when

    * its lump group has members that no muscle of the same side (in ``names``) stands for, and
    * its force ratio ``F0 lMo / (sigma_model V_table)`` exceeds ``sqrt(e)``, the geometric
      midpoint between 1 (its own part alone) and ``e = (V_own + V_absent) / V_own`` (all the
      absent members too).

    ``sigma_model`` is the model's own specific tension: ``sigma`` (0.6 MPa) times the median
    over the placed muscles of ``F0 lMo / (sigma V_table)``, 1 for a model whose forces follow
    the volume rule (the study's), about 0.66 for gait2392's generic forces. A lump's mass is
    ``rho F0 lMo / sigma_model`` (the rule of OpenSim's probes at the model's specific tension):
    for summed forces and one part's ``lMo``, the parts' summed mass to the spread of their
    ``lMo``. Muscles with an override mass, and muscles the table cannot place, are never lumps.
    The median and the absent members are taken over the muscles resolved together (a
    solution's muscles), as for the split rule.
    """
    names = list(names)
    recs = resolve_muscles(names, max_isometric_force_N, overrides, warn=False)
    return _find_lumps(recs, _forces(names, max_isometric_force_N), _forces(names, optimal_fiber_length_m),
                       total_muscle_volume_m3(body_mass_kg, height_m))


def _find_lumps(recs: Sequence[MuscleRecord], forces: Mapping[str, float], lmo: Mapping[str, float],
                v_total: float) -> dict[str, LumpedMuscle]:
    anat = _anatomical_rows()
    usable = [r for r in recs if r.placed and r.mass_kg_override is None and r.name in forces and r.name in lmo
              and np.isfinite(r.volume_percent) and r.volume_percent > 0]
    if not usable:
        return {}
    ratio = {r.name: forces[r.name] * lmo[r.name] / (r.specific_tension_Pa * r.volume_percent / 100.0 * v_total)
             for r in usable}
    scale = float(np.median(list(ratio.values())))
    if not (np.isfinite(scale) and scale > 0):
        return {}
    present: dict[str, set[str]] = {}
    for r in recs:
        present.setdefault(r.side, set()).update(r.anatomical)
    group = {a: row["lump_group"] for a, row in anat.items()}
    volume = {a: row["volume_percent"] for a, row in anat.items()}
    out = {}
    for r in usable:
        groups = {group[a] for a in r.anatomical if group[a]}
        absent = tuple(a for a in anat if group[a] in groups and a not in present[r.side])
        if not absent:
            continue
        e = (r.volume_percent + sum(volume[a] for a in absent)) / r.volume_percent
        rel = ratio[r.name] / scale
        if rel > np.sqrt(e):
            sigma_model = r.specific_tension_Pa * scale
            out[r.name] = LumpedMuscle(
                name=r.name, own=r.anatomical, absent=absent,
                table_mass_kg=MUSCLE_DENSITY_KG_PER_M3 * r.volume_percent / 100.0 * v_total,
                mass_kg=MUSCLE_DENSITY_KG_PER_M3 * forces[r.name] * lmo[r.name] / sigma_model,
                force_ratio=rel, threshold=float(np.sqrt(e)), model_specific_tension_Pa=sigma_model,
            )
    return out


def _report_lumps(lumps: Mapping[str, LumpedMuscle]) -> None:
    if not lumps:
        return
    anat = _anatomical_rows()
    s = "s" if len(lumps) > 1 else ""
    each = "; ".join(
        f"{m.name}: F0 {m.force_ratio:.2f} times its part's ({', '.join(anat[a]['name'] for a in m.own)}; "
        f"lump above {m.threshold:.2f}), taken to stand for {', '.join(anat[a]['name'] for a in m.absent)} too: "
        f"mass {m.mass_kg:.3f} kg (rho F0 lMo / {m.model_specific_tension_Pa / 1e6:.3f} MPa) instead of "
        f"{m.table_mass_kg:.3f} kg"
        for m in lumps.values())
    warnings.warn(
        f"lumped muscle{s}, maximal isometric force far above the anatomical muscle named: {each}; to choose "
        "otherwise, give mass_kg or anatomical_muscles in a --muscle-properties CSV (see docs/muscles.md)",
        LumpedMuscleWarning, stacklevel=user_stacklevel(),
    )


def slow_twitch_fraction(names: Sequence[str], default: float | None = None, overrides=None,
                         max_isometric_force_N=None) -> np.ndarray:
    """Slow-twitch fiber fraction per muscle (volume-weighted over a lumped muscle's parts).

    With ``default`` given, muscles absent from the table get it (the study used 0.5);
    without, they raise :class:`UnknownMuscleError`.
    """
    recs = resolve_muscles(names, max_isometric_force_N, overrides, warn=False)
    missing = [r.name for r in recs if "slow_twitch_fraction" in r.fallback]
    if missing and default is None:
        raise UnknownMuscleError(
            f"no slow-twitch fraction for muscle{'s' if len(missing) > 1 else ''} {name_list(missing)} in the "
            "anatomical muscle table; give one in a muscle-properties CSV (see docs/muscles.md)"
        )
    return np.array([default if "slow_twitch_fraction" in r.fallback else r.slow_twitch_fraction for r in recs],
                    dtype=float)


def metabolic_properties(names: Sequence[str], body_mass_kg: float, height_m: float, max_isometric_force_N,
                         optimal_fiber_length_m, overrides=None, strict: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Mass (kg) and slow-twitch fraction of each muscle as the metabolic models take them: the
    volume rule of :func:`muscle_masses_kg` and :func:`slow_twitch_fraction` (0.5 for a muscle
    the table cannot place), with ``overrides`` first. The metabolic rates of a solution and the
    energy goal of the muscle redundancy problem both use this."""
    overrides = as_overrides(overrides)
    masses = muscle_masses_kg(names, body_mass_kg, height_m, max_isometric_force_N, optimal_fiber_length_m,
                              overrides=overrides, strict=strict)
    fst = slow_twitch_fraction(names, FALLBACK_SLOW_TWITCH_FRACTION, overrides=overrides,
                               max_isometric_force_N=max_isometric_force_N)
    return masses, fst


def individualised_max_isometric_force_N(
    names: Sequence[str],
    optimal_fiber_length_m: Sequence[float],
    body_mass_kg: float,
    height_m: float,
    specific_tension_Pa: float | None = None,
    max_isometric_force_N=None,
    overrides=None,
) -> np.ndarray:
    """Maximal isometric force ``sigma * V_i / lMo_i`` (N) from body mass and height.

    ``specific_tension_Pa`` ``None``: each muscle's table (or override) value, 0.6 MPa.
    ``max_isometric_force_N`` (the model's) sets the split of muscles sharing a volume. The
    volumes are the table's (:func:`muscle_volumes_m3`): place a lumped muscle named after one
    part on all its parts (override ``anatomical_muscles``) before individualising its force.
    """
    lmo = np.asarray(optimal_fiber_length_m, dtype=float)
    if lmo.shape != (len(names),):
        raise OptionError(f"{len(names)} muscle names but {lmo.size} optimal fiber lengths")
    if np.any(~np.isfinite(lmo)) or np.any(lmo <= 0):
        raise OptionError("optimal fiber lengths must be positive, in metres")
    recs = _placed_records(names, max_isometric_force_N, overrides, "volume share")
    sigma = (np.array([r.specific_tension_Pa for r in recs]) if specific_tension_Pa is None
             else float(specific_tension_Pa))
    vol = np.array([r.volume_percent for r in recs]) / 100.0 * total_muscle_volume_m3(body_mass_kg, height_m)
    return sigma * vol / lmo


# ---------------------------------------------------------------------------------------
# Groups and lists from the table
# ---------------------------------------------------------------------------------------


def _grouped(names: Sequence[str], attr: str) -> dict[str, tuple[str, ...]]:
    """``{group_side: muscles}`` for a record attribute, members in table order then name."""
    recs = resolve_muscles(names, warn=False)
    order = {a: i for i, a in enumerate(_anatomical_rows())}
    out: dict[str, list[MuscleRecord]] = {}
    for r in recs:
        g = getattr(r, attr)
        if g:
            out.setdefault(f"{g}_{r.side}" if r.side else g, []).append(r)
    return {k: tuple(r.name for r in sorted(v, key=lambda r: (min(order[a] for a in r.anatomical), r.name)))
            for k, v in out.items()}


def coupling_groups(names: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Passive-calibration coupling groups (``P1_r``: muscles), per side."""
    return _grouped(names, "coupling_group")


def tendon_groups(names: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Muscles sharing one tendon in the tendon-stiffness estimation (``achilles_r``: ...)."""
    return _grouped(names, "tendon")


def emg_scale_groups(names: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Muscles sharing one EMG scale factor in EMG-TEN (``vasti_r``: ...)."""
    return _grouped(names, "emg_scale_group")


def default_emg_mapping(names: Sequence[str]) -> dict[str, list[str]]:
    """EMG channel(s) of the example data per model muscle that has one in the table."""
    return {r.name: list(r.emg_channels) for r in resolve_muscles(names, warn=False) if r.emg_channels}


def report_muscles(names: Sequence[str]) -> list[str]:
    """The report's default muscle list for a model: per listed anatomical muscle (table
    ``report_order``), the middle one of the model muscles standing for it."""
    recs = resolve_muscles(names, warn=False)
    anat = _anatomical_rows()
    out = []
    listed = [a for a in anat if np.isfinite(anat[a]["report_order"])]
    for a in sorted(listed, key=lambda a: anat[a]["report_order"]):
        for side in dict.fromkeys(r.side for r in recs):
            parts = [r.name for r in recs if r.side == side and a in r.anatomical]
            if parts and parts[(len(parts) - 1) // 2] not in out:
                out.append(parts[(len(parts) - 1) // 2])
    return out


@functools.lru_cache(maxsize=1)
def tendon_literature() -> dict[str, tuple[float, float, str]]:
    """``{tendon: (stiffness_N_per_mm, reference_force_fraction, source)}`` (EFFORT-TEN default)."""
    return {r["tendon"]: (float(r["stiffness_N_per_mm"]), float(r["reference_force_fraction"]), r["source"])
            for r in _read_package_csv("tendon_stiffness_literature.csv")}


@functools.lru_cache(maxsize=1)
def study_passive_parameters() -> dict[str, tuple[float, float]]:
    """Published calibrated ``(kPE, s0)`` of the study's example subject, by side-free name."""
    return {r["muscle"]: (float(r["kpe"]), float(r["s0"])) for r in _read_package_csv("study_passive_parameters.csv")}


# ---------------------------------------------------------------------------------------
# Compatibility view
# ---------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def property_table():
    """The study's model's muscles (side-free names) with their resolved properties.

    A view of the anatomical table through the Rajagopal aliases: ``anatomical_name``,
    ``slow_twitch_fraction``, ``volume_percent``, ``function_groups``,
    ``tendon_stiffness_group``, ``passive_calibration_trials``, ``passive_coupling_group``,
    ``emg_channel``, ``kpe_calibrated_reference``, ``s0_calibrated_reference``.
    """
    import pandas as pd

    names = [a.model_name for a in _aliases() if "rajagopal" in a.families]
    anat = _anatomical_rows()
    passive = study_passive_parameters()
    rows = []
    for r in resolve_muscles(names, warn=False):
        rows.append(dict(
            muscle=r.name, anatomical_name=" + ".join(anat[a]["name"] for a in r.anatomical),
            slow_twitch_fraction=r.slow_twitch_fraction, volume_percent=r.volume_percent,
            function_groups=" ".join(r.function_groups),
            tendon_stiffness_group={"achilles": "PF", "patellar": "VA"}.get(r.tendon, ""),
            passive_calibration_trials=r.calibration_trials, passive_coupling_group=r.coupling_group,
            emg_channel=" ".join(r.emg_channels),
            kpe_calibrated_reference=passive.get(r.name, (np.nan, np.nan))[0],
            s0_calibrated_reference=passive.get(r.name, (np.nan, np.nan))[1],
        ))
    return pd.DataFrame(rows).set_index("muscle")


def muscle_property(names: Sequence[str], column: str) -> np.ndarray:
    """One column of :func:`property_table` for ``names`` (with or without side suffix)."""
    table = property_table()
    if column not in table.columns:
        raise OptionError(f"the muscle property table has no column '{column}'")
    base = [split_side(n)[0] for n in names]
    missing = [n for n, b in zip(names, base) if b not in table.index]
    if missing:
        raise UnknownMuscleError(f"no {column} for muscles {name_list(missing)} in the muscle property table")
    return table.loc[base, column].to_numpy()


# ---------------------------------------------------------------------------------------
# Function groups of the DOFs
# ---------------------------------------------------------------------------------------

#: the muscle function groups (the ``function_groups`` of the muscle table, and the groups the
#: analysis assigns by moment arm)
GROUPS = ("PF", "DF", "KE", "KF", "HE", "HF", "HAD", "HAB", "HIR", "HER")
#: DOF name without side suffix -> (group of positive moment arms, group of negative ones)
DOF_GROUPS = {
    "ankle_angle": ("DF", "PF"),
    "knee_angle": ("KF", "KE"),
    "hip_flexion": ("HF", "HE"),
    "hip_adduction": ("HAD", "HAB"),
    "hip_rotation": ("HIR", "HER"),
}


def dof_group_pair(dof: str, dof_groups: Mapping[str, tuple[str, str]] | None = None) -> tuple[str, str]:
    """``(positive_group, negative_group)`` of a DOF (exact name, else name less ``_r``/``_l``)."""
    table = dict(DOF_GROUPS)
    if dof_groups:
        table.update(dof_groups)
    if dof in table:
        pair = table[dof]
    else:
        stem = dof[:-2] if dof.endswith(("_r", "_l")) else dof
        if stem not in table:
            raise OptionError(
                f"DOF '{dof}' belongs to no muscle group; known DOFs: {', '.join(DOF_GROUPS)} (with _r/_l). "
                "Pass dof_groups={dof: (positive_group, negative_group)} or leave the DOF out"
            )
        pair = table[stem]
    pair = tuple(pair)
    bad = [g for g in pair if g not in GROUPS]
    if len(pair) != 2 or bad:
        raise OptionError(
            f"the groups of DOF '{dof}' must be two of {', '.join(GROUPS)}, not {pair!r}"
        )
    return pair  # type: ignore[return-value]


def has_function_group(dof: str, dof_groups: Mapping[str, tuple[str, str]] | None = None) -> bool:
    """Whether :func:`dof_group_pair` places the DOF (a subtalar or toe joint has no group)."""
    try:
        dof_group_pair(dof, dof_groups)
    except OptionError:
        return False
    return True

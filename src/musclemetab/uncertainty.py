"""Uncertainty bands of the metabolic estimates: priors of the muscle properties, their samples
and the bands of the rates (``docs/uncertainty.md``).

Priors (:func:`read_priors`)
    One row per property: ``F0``, ``lMo``, ``lTs``, ``kT``, ``kPE``, ``s0``, ``sM`` (the
    muscle-tendon parameters of the solve, :class:`~musclemetab.redundancy.parameters.MuscleTendonParameters`),
    ``muscle_mass`` and ``slow_twitch_fraction`` (the metabolic models' muscle properties) and
    ``height`` (the subject's, in the muscle-volume rule of :mod:`musclemetab.properties`), each
    with a ``distribution`` of a multiplicative factor and its ``spread``:

    * ``lognormal``: factor ``exp(spread z)`` (``spread`` is the SD of the log of the factor);
    * ``normal``: factor ``max(1 + spread z, 0.05)``;

    ``z`` standard normal. The package's table is ``data/uncertainty_priors.csv``; a CSV of the
    same columns (``--uncertainty-priors FILE``) replaces rows by parameter and muscle (an empty
    ``muscle``: every muscle; a model muscle name or a side-free name: that muscle). A spread of 0
    keeps the property at its nominal value. Slow-twitch fractions are clipped to [0, 1] after the factor.

Samples (:func:`draw`)
    Sample ``k`` of a trial takes point ``k`` of a scrambled Sobol' sequence (Owen scrambling,
    :class:`scipy.stats.qmc.Sobol`) of dimension ``9 M + 1`` (nine factors per muscle, in the order
    of :data:`MUSCLE_PARAMETERS` then muscle, and the height) with the study's seed, mapped to
    standard normal ``z`` by the inverse normal CDF. The point depends on the seed, the muscles and
    ``k`` only: a sample is the same whatever the number of samples asked for, on any worker.

Bands (:func:`band`, :func:`band_table`)
    The median and the 5 and 95 % quantiles (``numpy.quantile``, linear interpolation) of a rate
    over the plausible samples (converged, no plausibility flag; every converged one with
    ``keep_flagged``); below :data:`QUANTILE_SAMPLES` samples the min and max, and below
    :data:`MIN_BAND_SAMPLES` the band is marked as from few samples (:func:`band_kind`). Where the
    nominal value lies in its band and why it may lie outside: :func:`nominal_quantile`,
    :func:`nominal_note`. Which parameters make a band's width: :func:`width_contributions`.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import InputFileError, UnknownMuscleError
from .messages import name_list

__all__ = ["Prior", "Priors", "Draw", "read_priors", "default_priors", "draw", "band", "BAND_SUFFIXES",
           "MUSCLE_PARAMETERS", "SOLVE_PARAMETERS", "GLOBAL_PARAMETERS", "PARAMETERS", "DISTRIBUTIONS",
           "PRIORS_FILE", "DEFAULT_SEED", "zero_priors", "MIN_NORMAL_FACTOR", "adapted_start", "sample_start", "band_table", "with_bands",
           "band_kind", "expected_coverage", "nominal_quantile", "nominal_note", "width_contributions",
           "top_parameters_text", "muscle_tendons", "dimension", "draw_from_normal", "sampled_properties", "TENDON_PREFIX", "QUANTILE_SAMPLES", "MIN_BAND_SAMPLES", "NOT_CONVERGED", "TOP_PARAMETERS"]

PRIORS_FILE = "uncertainty_priors.csv"
#: solve parameter -> field of MuscleTendonParameters
SOLVE_PARAMETERS = {
    "F0": "max_isometric_force_N",
    "lMo": "optimal_fiber_length_m",
    "lTs": "tendon_slack_length_m",
    "kT": "tendon_stiffness",
    "kPE": "passive_kpe",
    "s0": "passive_s0",
    "sM": "passive_sm",
}
#: per-muscle parameters, in the order of the sample's dimensions
MUSCLE_PARAMETERS = (*SOLVE_PARAMETERS, "muscle_mass", "slow_twitch_fraction")
GLOBAL_PARAMETERS = ("height",)
PARAMETERS = (*MUSCLE_PARAMETERS, *GLOBAL_PARAMETERS)
DISTRIBUTIONS = ("lognormal", "normal")
#: the seed of the samples when none is given
DEFAULT_SEED = 1
#: a normal factor never goes below this (a property stays positive)
MIN_NORMAL_FACTOR = 0.05
#: the column suffixes of a band: 5 %, median, 95 %
BAND_SUFFIXES = ("_p05", "_p50", "_p95")
_COLUMNS = ("parameter", "distribution", "spread", "muscle", "source", "population", "value_taken", "note")
#: the largest spread accepted (a lognormal factor of e^2 per SD is no prior)
MAX_SPREAD = 2.0


#: the prefix of a ``muscle`` cell naming the muscles of an anatomical tendon
#: (``tendon:achilles``: the triceps surae; ``anatomical_muscles.csv``, column ``tendon``)
TENDON_PREFIX = "tendon:"


@dataclass(frozen=True)
class Prior:
    """One row of the priors: the ``parameter``'s factor distribution and spread, for ``muscle``
    (``""``: every muscle; a muscle, a side-free name or ``tendon:<tendon>``, the muscles of an
    anatomical tendon), where the number comes from (``source``: paper, table), the
    ``population`` measured, the ``value_taken`` from it and a ``note`` (how the spread follows)."""

    parameter: str
    distribution: str
    spread: float
    muscle: str = ""
    source: str = ""
    population: str = ""
    value_taken: str = ""
    note: str = ""

    def factor(self, z):
        """The factor for standard normal ``z`` (array or number)."""
        z = np.asarray(z, dtype=float)
        if self.distribution == "lognormal":
            return np.exp(self.spread * z)
        return np.maximum(1.0 + self.spread * z, MIN_NORMAL_FACTOR)


@dataclass(frozen=True)
class Priors:
    """The prior table: rows by ``(parameter, muscle)``; ``source`` names where it was read."""

    rows: tuple[Prior, ...]
    source: str = "package table"
    files: tuple[str, ...] = field(default=(), compare=False)

    def prior(self, parameter: str, muscle: str = "", tendon: str | None = None) -> Prior:
        """The row for ``parameter`` of ``muscle``: its own row, else its side-free name's, else
        that of its anatomical tendon (``tendon``, e.g. ``achilles``; looked up when not given),
        else the parameter's row for every muscle."""
        from .properties import split_side

        rows = {(r.parameter, r.muscle): r for r in self.rows}
        if tendon is None and muscle and any(r.muscle.startswith(TENDON_PREFIX) for r in self.rows):
            tendon = muscle_tendons((muscle,)).get(muscle)
        for key in (muscle, split_side(muscle)[0] if muscle else None, TENDON_PREFIX + tendon if tendon else None,
                    ""):
            if key is not None and (parameter, key) in rows:
                return rows[(parameter, key)]
        return Prior(parameter, "lognormal", 0.0, "", "not in the table: no spread")

    def check_muscles(self, muscles: Sequence[str], of: str = "the problem") -> None:
        """:class:`UnknownMuscleError` for a row naming no muscle of ``muscles`` (by name or
        side-free name; a ``tendon:`` row names a group, which a model may lack); the message
        calls them the muscles ``of`` (the problem, a model)."""
        from .properties import split_side

        known = set(muscles) | {split_side(m)[0] for m in muscles}
        unknown = sorted({r.muscle for r in self.rows if r.muscle and r.muscle not in known
                          and not r.muscle.startswith(TENDON_PREFIX)})
        if unknown:
            raise UnknownMuscleError(
                f"{self.source}: muscle{'s' if len(unknown) > 1 else ''} {name_list(unknown)} of the uncertainty "
                f"priors name{'' if len(unknown) > 1 else 's'} no muscle of {of} "
                f"({name_list(muscles, 6)}); fix the name or leave the 'muscle' cell empty for every muscle")

    def table(self):
        """The rows as a pandas table (the columns of the CSV)."""
        import pandas as pd

        return pd.DataFrame([[getattr(r, c) for c in _COLUMNS] for r in self.rows], columns=list(_COLUMNS))

    def digest(self) -> str:
        """SHA-256 of the rows' values (what a sample's result depends on; not the sources' text)."""
        content = sorted((r.parameter, r.distribution, repr(float(r.spread)), r.muscle) for r in self.rows)
        return hashlib.sha256(json.dumps(content).encode()).hexdigest()

    @property
    def all_zero(self) -> bool:
        return all(r.spread == 0 for r in self.rows)


def _read_rows(text_source, where: str) -> list[Prior]:
    import pandas as pd

    try:
        df = pd.read_csv(text_source, comment="#", dtype=str, keep_default_na=False, skipinitialspace=True)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{where}: not a readable CSV ({str(exc).splitlines()[0]}); expected columns "
                             f"{','.join(_COLUMNS)}") from None
    missing = [c for c in ("parameter", "spread") if c not in df.columns]
    extra = [c for c in df.columns if c not in _COLUMNS]
    if missing or extra:
        what = f"no column {name_list(missing)}" if missing else f"unknown column {name_list(extra)}"
        raise InputFileError(f"{where}: {what} (its columns: {', '.join(map(str, df.columns)) or 'none'}); a priors "
                             f"file has the columns {','.join(_COLUMNS)}, all but parameter and spread optional")
    rows, seen = [], set()
    for i, row in df.iterrows():
        line = f"{where}: line {i + 2}"
        name = str(row["parameter"]).strip()
        if name not in PARAMETERS:
            import difflib

            near = difflib.get_close_matches(name, PARAMETERS, n=1)
            raise InputFileError(f"{line}: unknown parameter '{name}'{f' (did you mean {near[0]}?)' if near else ''}; "
                                 f"the parameters are {', '.join(PARAMETERS)}")
        dist = str(row.get("distribution", "") or "lognormal").strip().lower() or "lognormal"
        if dist not in DISTRIBUTIONS:
            raise InputFileError(f"{line}: distribution '{dist}' of {name} is not one of {', '.join(DISTRIBUTIONS)}")
        raw = str(row["spread"]).strip()
        try:
            spread = float(raw)
        except ValueError:
            spread = math.nan
        if not (math.isfinite(spread) and 0.0 <= spread <= MAX_SPREAD):
            raise InputFileError(f"{line}: spread '{raw}' of {name} must be a number from 0 to {MAX_SPREAD:g} (the SD "
                                 "of the factor's log for lognormal, of the factor for normal)")
        muscle = str(row.get("muscle", "") or "").strip()
        if muscle.startswith(TENDON_PREFIX):
            from .properties import tendon_literature

            tendons = sorted(tendon_literature())
            if muscle[len(TENDON_PREFIX):] not in tendons:
                raise InputFileError(f"{line}: '{muscle}' names no anatomical tendon; the tendons are "
                                     f"{', '.join(TENDON_PREFIX + t for t in tendons)}")
        if muscle and name in GLOBAL_PARAMETERS:
            raise InputFileError(f"{line}: {name} is the subject's, not a muscle's; leave the 'muscle' cell empty")
        if (name, muscle) in seen:
            raise InputFileError(f"{line}: {name}{f' of {muscle}' if muscle else ''} appears twice; give one line each")
        seen.add((name, muscle))
        rows.append(Prior(name, dist, spread, muscle, *(str(row.get(c, "") or "").strip()
                                                        for c in ("source", "population", "value_taken", "note"))))
    return rows


def default_priors() -> Priors:
    """The package's priors (``data/uncertainty_priors.csv``)."""
    from importlib import resources

    with resources.files("musclemetab").joinpath(f"data/{PRIORS_FILE}").open() as f:
        return Priors(tuple(_read_rows(f, f"musclemetab/data/{PRIORS_FILE}")), "package table")


def read_priors(path: str | os.PathLike | None = None) -> Priors:
    """The package's priors with the rows of the CSV ``path`` in place of theirs (same parameter
    and muscle; a row for every muscle, empty ``muscle``, in place of all the package's rows of its
    parameter, those of single muscles and tendons too); :class:`InputFileError` naming the file, line and value for an unknown parameter
    or distribution or a spread out of range."""
    base = default_priors()
    if path is None:
        return base
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such uncertainty-priors file; check the --uncertainty-priors path "
                             f"(columns {','.join(_COLUMNS)})")
    own = _read_rows(path, str(path))
    keys = {(r.parameter, r.muscle) for r in own}
    every = {r.parameter for r in own if not r.muscle}  # a row for every muscle replaces all the package's
    rows = tuple(r for r in base.rows if (r.parameter, r.muscle) not in keys and r.parameter not in every) + tuple(own)
    return Priors(rows, str(path), (str(path),))


def zero_priors() -> Priors:
    """The package's priors with every spread 0 (the bands collapse to the nominal result)."""
    from dataclasses import replace

    return Priors(tuple(replace(r, spread=0.0) for r in default_priors().rows), "all spreads zero")


@dataclass(frozen=True)
class Draw:
    """The factors of one sample: ``factors[parameter]`` an array over ``muscles`` (per-muscle
    parameters) and ``height`` a number."""

    index: int
    muscles: tuple[str, ...]
    factors: dict
    height: float

    def parameters(self, params):
        """``params`` (:class:`~musclemetab.redundancy.parameters.MuscleTendonParameters`, any
        muscles of this draw) with the solve parameters multiplied by their factors."""
        from .redundancy.parameters import PARAMETER_FIELDS, MuscleTendonParameters

        pos = {m: i for i, m in enumerate(self.muscles)}
        missing = [n for n in params.names if n not in pos]
        if missing:
            from .errors import DataMismatchError

            raise DataMismatchError(f"the sample has no factors for muscle(s) {name_list(missing)}")
        idx = np.array([pos[n] for n in params.names], dtype=int)
        kw = {f: np.asarray(getattr(params, f), dtype=float).copy() for f in PARAMETER_FIELDS}
        for p, fname in SOLVE_PARAMETERS.items():
            kw[fname] = kw[fname] * self.factors[p][idx]
        return MuscleTendonParameters(names=params.names, sources={**params.sources, "uncertainty sample": self.index},
                                      **kw)

    def table(self):
        """One row per muscle, one column per factor (and the height factor on every row)."""
        import pandas as pd

        df = pd.DataFrame({"muscle": list(self.muscles), **{p: self.factors[p] for p in MUSCLE_PARAMETERS}})
        df["height"] = self.height
        return df


def sampled_properties(draw_: Draw, solution, body_mass_kg: float, height_m: float | None, overrides=None):
    """``(masses_kg, slow_twitch)``, dictionaries by muscle of ``solution``: the muscle masses (the
    volume rule at the sampled height, :func:`musclemetab.properties.metabolic_properties`, of the
    solution's own F0 and lMo) and slow-twitch fractions with the sample's factors."""
    from .properties import metabolic_properties

    params = solution.parameters.subset(solution.muscles)
    height = None if height_m is None else height_m * draw_.height
    masses, fst = metabolic_properties(list(solution.muscles), body_mass_kg, height, params.max_isometric_force_N,
                                       params.optimal_fiber_length_m, overrides=overrides)
    pos = [draw_.muscles.index(m) for m in solution.muscles]
    masses = np.asarray(masses, dtype=float) * draw_.factors["muscle_mass"][pos]
    fst = np.clip(np.asarray(fst, dtype=float) * draw_.factors["slow_twitch_fraction"][pos], 0.0, 1.0)
    return dict(zip(solution.muscles, masses.tolist())), dict(zip(solution.muscles, fst.tolist()))


def sobol_normal(dimension: int, index: int, seed: int) -> np.ndarray:
    """Point ``index`` of the scrambled Sobol' sequence of ``dimension`` with ``seed``, as standard normal values."""
    import warnings

    from scipy.stats import norm, qmc

    engine = qmc.Sobol(dimension, scramble=True, seed=int(seed))
    if index:
        engine.fast_forward(int(index))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # balance of a single point: not asked for
        u = engine.random(1)[0]
    return norm.ppf(np.clip(u, 1e-12, 1.0 - 1e-12))


def muscle_tendons(muscles: Sequence[str]) -> dict[str, str]:
    """``{muscle: anatomical tendon}`` (``achilles``, ``patellar``) of the muscles that share one
    (:func:`musclemetab.properties.tendon_groups`, side-free)."""
    from .properties import tendon_groups

    out = {}
    for group, members in tendon_groups(list(muscles)).items():
        for m in members:
            out[m] = group.rsplit("_", 1)[0] if group.rsplit("_", 1)[-1] in ("r", "l") else group
    return out


def draw(priors: Priors, muscles: Sequence[str], index: int, seed: int) -> Draw:
    """The factors of sample ``index`` for ``muscles`` (module doc)."""
    muscles = tuple(muscles)
    priors.check_muscles(muscles)
    z = sobol_normal(dimension(muscles), index, seed)
    return draw_from_normal(priors, muscles, index, z)


def dimension(muscles: Sequence[str]) -> int:
    """The number of standard normal values a sample of ``muscles`` takes: nine per muscle and the height."""
    return len(MUSCLE_PARAMETERS) * len(muscles) + len(GLOBAL_PARAMETERS)


def draw_from_normal(priors: Priors, muscles: Sequence[str], index: int, z) -> Draw:
    """The factors of the standard normal values ``z`` (:func:`dimension` of them, in the order of
    the module doc) for ``muscles``: sample ``index``."""
    muscles = tuple(muscles)
    m = len(muscles)
    z = np.asarray(z, dtype=float)
    tendons = muscle_tendons(muscles)
    factors = {}
    for j, p in enumerate(MUSCLE_PARAMETERS):
        zj = z[j * m:(j + 1) * m]
        factors[p] = np.array([float(priors.prior(p, mu, tendons.get(mu, "")).factor(zk))
                               for mu, zk in zip(muscles, zj)])
    height = float(priors.prior("height").factor(z[-1]))
    return Draw(int(index), muscles, factors, height)


#: from this many plausible samples on, a band is the 5-95 % quantiles; below it the band is the
#: samples' min-max (their 5 and 95 % quantiles would be little more than the two extremes)
QUANTILE_SAMPLES = 20
#: a band from fewer plausible samples than this is marked ``few samples`` (``uncertainty_band``)
MIN_BAND_SAMPLES = 10
#: the ``sample_flags`` of a sample whose solve did not converge
NOT_CONVERGED = "not_converged"
#: a band is called skewed when one side (median to the 95 % or to the 5 % end) is this many
#: times the other
SKEW_RATIO = 2.0
#: a nominal this close to its band's end (relative) is at the end, not outside: the solves'
#: rates agree to about 0.15 % at the package's stop (docs/solver.md)
NOMINAL_TOLERANCE = 1e-3
#: parameters named in ``uncertainty_top_parameters``
TOP_PARAMETERS = 3


def band_kind(n: int) -> str:
    """What a band of ``n`` plausible samples is: ``"5-95 %"`` (quantiles, ``n >=``
    :data:`QUANTILE_SAMPLES`), ``"min-max"`` (fewer) or ``"min-max, few samples"`` (fewer than
    :data:`MIN_BAND_SAMPLES`); ``"none"`` without samples."""
    if n <= 0:
        return "none"
    if n >= QUANTILE_SAMPLES:
        return "5-95 %"
    return "min-max" if n >= MIN_BAND_SAMPLES else "min-max, few samples"


def expected_coverage(n: int) -> float:
    """The chance that a new draw of the same distribution lies inside the band of ``n``
    exchangeable samples: ``(n - 1)/(n + 1)`` for the min-max, ``0.9 (n - 1)/(n + 1)`` for the
    5-95 % quantiles of linear interpolation (the expected mass between two order statistics,
    interpolated)."""
    if n < 2:
        return math.nan
    return (0.9 if n >= QUANTILE_SAMPLES else 1.0) * (n - 1) / (n + 1)


def band(values) -> tuple[float, float, float]:
    """``(low, median, high)`` of the finite ``values``: the 5 and 95 % quantiles
    (``numpy.quantile``, linear interpolation) from :data:`QUANTILE_SAMPLES` values on, else the
    min and max (:func:`band_kind`); NaN when there are none."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return (math.nan, math.nan, math.nan)
    q = np.quantile(v, [0.05, 0.5, 0.95]) if v.size >= QUANTILE_SAMPLES else (v.min(), np.median(v), v.max())
    return float(q[0]), float(q[1]), float(q[2])


def nominal_quantile(values, nominal: float) -> float:
    """Where ``nominal`` lies among the finite ``values``: the share of them below it (ties count
    half), 0-1; NaN without values."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size or not math.isfinite(nominal):
        return math.nan
    return float(((v < nominal).sum() + 0.5 * (v == nominal).sum()) / v.size)


def nominal_note(nominal: float, used, rejected=(), nominal_quality: str = "ok", unit: str = "") -> str:
    """In words, where the nominal value lies against the band of the ``used`` samples' values and,
    when outside it, why: how many samples lie on the other side, the band's skew, the
    ``rejected`` samples' values on the nominal's side (those the band left out), the nominal's own
    plausibility flags (``nominal_quality``), too few samples. ``""`` without a band."""
    v = np.asarray(used, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size or not math.isfinite(nominal):
        return ""
    lo, mid, hi = band(v)
    kind = band_kind(v.size)
    if lo <= nominal <= hi:
        return f"inside its band ({kind}, {v.size} samples)"
    if abs(nominal - (lo if nominal < lo else hi)) <= NOMINAL_TOLERANCE * abs(nominal):
        return (f"at the {'low' if nominal < lo else 'high'} end of its band ({kind}, {v.size} samples), within "
                f"{100 * NOMINAL_TOLERANCE:g} % (the solver's tolerance)")
    below = nominal < lo
    side, other = ("below", "above") if below else ("above", "below")
    beyond = int((v > nominal).sum() if below else (v < nominal).sum())
    why = [f"{beyond} of {v.size} plausible samples lie {other} it: moving the properties "
           f"{'raised' if below else 'lowered'} the rate in {'all' if beyond == v.size else 'most'} of them"]
    up, down = hi - mid, mid - lo
    if up > SKEW_RATIO * down:
        why.append(f"the band is skewed upwards (95 % end {up:.3g} above the median, 5 % end {down:.3g} below)"
                   if kind == "5-95 %" else f"the band is skewed upwards (max {up:.3g} above the median, min "
                   f"{down:.3g} below)")
    elif down > SKEW_RATIO * up:
        why.append(f"the band is skewed downwards ({'5 % end' if kind == '5-95 %' else 'min'} {down:.3g} below "
                   f"the median, {'95 % end' if kind == '5-95 %' else 'max'} {up:.3g} above)")
    r = np.asarray(rejected, dtype=float)
    r = r[np.isfinite(r)]
    if r.size:
        near = int((r < lo).sum() if below else (r > hi).sum())
        why.append(f"{r.size} flagged sample{'s' if r.size > 1 else ''} left out, {near} of them {side} the band")
    if nominal_quality and nominal_quality not in ("ok", "not checked"):
        why.append(f"the nominal solve itself is flagged ({nominal_quality})")
    if v.size < MIN_BAND_SAMPLES:
        why.append(f"only {v.size} plausible samples")
    return f"{side} its band ({kind}, {v.size} samples): " + "; ".join(why)


def _used(group, keep_flagged: bool):
    """The rows of ``group`` (one per sample) that make the band: no flag (``sample_flags`` empty),
    or every converged one with ``keep_flagged``."""
    flags = group["sample_flags"].astype(object).fillna("").astype(str) if "sample_flags" in group else None
    if flags is None:
        return group.index == group.index
    return (flags == "") | (keep_flagged & (flags != NOT_CONVERGED))


def band_table(samples, keys: Sequence[str], columns: Sequence[str], *, keep_flagged: bool = False,
               nominal=None, note_column: str | None = None, listing: bool = False):
    """The bands of ``columns`` of the table ``samples`` (one row per sample and key; ``sample``
    and ``sample_flags``: the sample's plausibility flags, ``""`` for none, :data:`NOT_CONVERGED`
    for a solve that did not converge), one row per key: ``<column>_p05``, ``_p50``, ``_p95``
    (:func:`band`) over the plausible samples (every converged one with ``keep_flagged``),
    ``uncertainty_samples`` (how many), ``uncertainty_rejected`` (how many were left out) and
    ``uncertainty_band`` (:func:`band_kind`). With ``listing``: ``uncertainty_flagged_samples``,
    ``"<sample>: <flags>"`` of every sample with a flag (``(kept)`` with ``keep_flagged``). With
    ``nominal`` (the table of the nominal values, one row per key) and ``note_column``:
    ``<note_column>_nominal_quantile`` (:func:`nominal_quantile`) and ``uncertainty_note``
    (:func:`nominal_note`)."""
    import pandas as pd

    rows = []
    cols = [c for c in columns if c in samples]
    nominal_rows = {}
    if nominal is not None and note_column is not None and note_column in nominal:
        for _, r in nominal.iterrows():
            nominal_rows[tuple(r[k] for k in keys)] = r
    for key, group in samples.groupby(list(keys), sort=False, dropna=False):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(keys, key))
        use = _used(group, keep_flagged)
        used = group[use]
        row["uncertainty_samples"] = int(len(used))
        row["uncertainty_rejected"] = int(len(group) - len(used))
        row["uncertainty_band"] = band_kind(len(used))
        if listing:
            flagged = group[group["sample_flags"].astype(object).fillna("").astype(str) != ""] if "sample_flags" in group else group[:0]
            row["uncertainty_flagged_samples"] = "; ".join(
                f"{int(s)}: {f}{' (kept)' if keep_flagged and f != NOT_CONVERGED else ''}"
                for s, f in zip(flagged["sample"], flagged["sample_flags"].astype(str)))
        for c in cols:
            lo, mid, hi = band(pd.to_numeric(used[c], errors="coerce"))
            row[c + "_p05"], row[c + "_p50"], row[c + "_p95"] = lo, mid, hi
        if key in nominal_rows:
            nom = nominal_rows[key]
            x = float(pd.to_numeric(nom[note_column], errors="coerce"))
            vals = pd.to_numeric(used[note_column], errors="coerce")
            row[note_column + "_nominal_quantile"] = nominal_quantile(vals, x)
            row["uncertainty_note"] = nominal_note(
                x, vals, pd.to_numeric(group.loc[~use, note_column], errors="coerce"),
                str(nom.get("quality", "ok")))
        rows.append(row)
    return pd.DataFrame(rows)


def with_bands(table, bands, keys: Sequence[str]):
    """``table`` with the band columns of ``bands`` beside each rate (and a rate's
    ``_nominal_quantile`` after them), then the columns about the samples
    (``uncertainty_samples``, 0 for rows without samples, ``uncertainty_rejected``,
    ``uncertainty_band``, ...)."""
    import pandas as pd

    if bands is None or not len(bands):
        out = table.copy()
        out["uncertainty_samples"] = 0
        return out
    merged = table.merge(bands, on=list(keys), how="left", validate="many_to_one")
    for c in ("uncertainty_samples", "uncertainty_rejected"):
        if c in merged:
            merged[c] = pd.to_numeric(merged[c]).fillna(0).astype(int)
    order = []
    for c in table.columns:
        order.append(c)
        order += [c + s for s in (*BAND_SUFFIXES, "_nominal_quantile") if c + s in merged]
    order += [c for c in bands.columns if c not in order and c not in keys]
    return merged[order]


def width_contributions(sensitivity, priors: Priors, rate: str = "whole_body"):
    """Which parameters make the width of a band: for each ``(model, parameter, muscle)`` of the
    ``sensitivity.csv`` table (:mod:`musclemetab.redundancy.sensitivity`) with ``rate``, the
    linearised standard deviation that the parameter's prior gives the rate,
    ``|dR/dlog p| x spread`` (``spread``: the SD of ``log p`` for a lognormal factor, of the factor,
    i.e. of ``log p`` to first order, for a normal one). Columns ``model``, ``parameter``,
    ``muscle``, ``sd`` (the rate's unit), largest first within each model. Parameters without a
    prior (``vmax``, ``alpha0``) contribute nothing; the muscle masses, fiber types and height
    are not in the sensitivities."""
    d = sensitivity[sensitivity["rate"].astype(str) == rate]
    tendons = muscle_tendons(sorted(set(d["muscle"].astype(str))))
    spread = np.array([priors.prior(str(p), str(m), tendons.get(str(m), "")).spread if p in MUSCLE_PARAMETERS
                       else 0.0 for p, m in zip(d["parameter"], d["muscle"])], dtype=float)
    out = d[["model", "parameter", "muscle"]].copy()
    out["sd"] = np.abs(d["d_rate_d_log_p"].to_numpy(float)) * spread
    out = out[out["sd"] > 0]
    return out.sort_values(["model", "sd"], ascending=[True, False], kind="stable", ignore_index=True)


def top_parameters_text(contributions, top: int = TOP_PARAMETERS, digits: int = 3) -> str:
    """``"lTs semimem_r 0.21; ..."``: the ``top`` rows of one model's :func:`width_contributions`."""
    return "; ".join(f"{p} {m} {sd:.{digits}g}" for p, m, sd in
                     contributions[["parameter", "muscle", "sd"]].head(top).itertuples(index=False))


def adapted_start(solution, params):
    """A warm start for the problem with the parameters ``params``, from ``solution`` (solved with
    its own parameters on the same mesh): the same tendon forces (N), so that the moments stay
    balanced, with the fiber states that give them under ``params``.

    The musculotendon length follows from the solution (``lMT = sqrt(lM^2 - w^2) + lTs l~T``, with
    ``l~T`` the inverse of the tendon curve at its force); under ``params`` the tendon takes
    ``l~T = fT^-1(FT / F0)``, the fiber ``lM = sqrt((lMT - lTs l~T)^2 + w^2)`` (``l~M`` within
    0.2-1.6), its velocity the derivative of a not-a-knot spline through ``l~M``, and the activation
    the Hill equilibrium ``a = (F~T / cos(alpha) - fPE) / (fL fV)`` within [0, 1] (the excitation
    the same). A starting point only: the solve finds the optimum.
    """
    from dataclasses import replace

    from scipy.interpolate import CubicSpline

    from .muscle import active_force_length, force_velocity, passive_force_length, tendon_length_from_force

    p0 = solution.parameters.subset(solution.muscles)
    p1 = params.subset(solution.muscles)
    force = np.asarray(solution.tendon_force_N, dtype=float)
    lm0 = np.asarray(solution.lm_norm, dtype=float) * p0.optimal_fiber_length_m
    lmt = (np.sqrt(np.maximum(lm0**2 - p0.width_m**2, 0.0))
           + p0.tendon_slack_length_m * tendon_length_from_force(force / p0.max_isometric_force_N, p0.tendon_stiffness))
    ft = force / p1.max_isometric_force_N
    along = lmt - p1.tendon_slack_length_m * tendon_length_from_force(ft, p1.tendon_stiffness)
    lm_norm = np.clip(np.sqrt(np.maximum(along, 0.0)**2 + p1.width_m**2) / p1.optimal_fiber_length_m, 0.2, 1.6)
    lm = lm_norm * p1.optimal_fiber_length_m
    cos_alpha = np.sqrt(np.maximum(lm**2 - p1.width_m**2, 1e-12)) / lm
    velocity = CubicSpline(solution.time_s, lm_norm, axis=0, bc_type="not-a-knot")(solution.time_s, 1)
    fl = active_force_length(lm_norm)
    fv = force_velocity(velocity / p1.max_contraction_velocity)
    fpe = passive_force_length(lm_norm, p1.passive_kpe, p1.passive_s0, p1.passive_sm)
    with np.errstate(divide="ignore", invalid="ignore"):
        activation = np.nan_to_num(np.clip((ft / cos_alpha - fpe) / (fl * fv), 0.0, 1.0), nan=0.0)
    return replace(solution, lm_norm=lm_norm, activation=activation, excitation=activation.copy(),
                   fiber_velocity_lmo_per_s=velocity, parameters=p1, multipliers=None)


def sample_start(solution, params):
    """The warm start of a sample with the parameters ``params`` from the nominal ``solution``: the
    nominal's optimum as IPOPT left it, multipliers included (:attr:`Solution.multipliers
    <musclemetab.redundancy.solution.Solution.multipliers>`, IPOPT's warm start), when the solution
    holds them, else :func:`adapted_start`. From the multipliers a sample of the example's normal
    trial takes about half the iterations of a cold solve, from the adapted start nearly as many
    (docs/uncertainty.md, "Cost")."""
    return solution if getattr(solution, "multipliers", None) else adapted_start(solution, params)

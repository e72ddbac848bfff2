"""Muscle function groups and the distribution of muscle rates by moment-arm ratio.

Ten groups (``docs/analysis.md``), two per degree of freedom, by the sign of the moment
arm in OpenSim's convention (``r = -dl/dq``: positive when tension produces a positive
generalised moment). For the Rajagopal / gait2392 family of models a positive coordinate
is ankle dorsiflexion, knee flexion, hip flexion, hip adduction and hip internal rotation
on both sides, so:

* ``ankle_angle``: positive -> DF (dorsiflexors), negative -> PF (plantarflexors);
* ``knee_angle``: positive -> KF (knee flexors), negative -> KE (knee extensors);
* ``hip_flexion``: positive -> HF (hip flexors), negative -> HE (hip extensors);
* ``hip_adduction``: positive -> HAD (adductors), negative -> HAB (abductors);
* ``hip_rotation``: positive -> HIR (internal rotators), negative -> HER (external
  rotators).

DOF names are matched without their side suffix (``_r``/``_l``); other models or
conventions are handled with the ``dof_groups`` argument (``{dof: (positive_group,
negative_group)}``).

Distribution rule (``docs/analysis.md``, after Uchida et al. 2016): at each instant the
rate of muscle ``i`` is split over the DOFs it spans in proportion to the absolute
moment arms, and each share goes to the group given by the *instantaneous* sign of the
moment arm::

    w_i,d(t)  = |r_i,d(t)| / sum_d' |r_i,d'(t)|      over DOFs with |r_i,d'(t)| > threshold
    Edot_g(t) = sum_i sum_d w_i,d(t) Edot_i(t) [group(i, d, t) == g]

Choices the study leaves open (UNCERTAIN, exposed as parameters or documented here):
absolute moment arms (not signed), instantaneous weights and assignment (not cycle
averages), a DOF-level split (the three hip DOFs separately, as the reported adductor,
abductor and rotator shares imply), and a threshold of 1 mm (``threshold_m``) at or
below which a moment arm counts as zero (the gastrocnemii's spurious 1e-4 m hip moment
arms are thereby ignored).

A muscle with no moment arm above the threshold at an instant goes, for that instant,
to an extra bucket ``other``, so that the ten groups plus ``other`` always sum to the
whole leg. (With the five right-leg DOFs of the example model every one of the 40
muscles has a moment arm above 1 mm at every frame of the three example trials, so
``other`` is empty there; it matters for reduced DOF sets.)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import DataMismatchError, OptionError
from ..events import as_signal, as_time, coverage, integrate_interval
from ..events import GaitCycle
from ..properties import DOF_GROUPS, GROUPS, dof_group_pair, has_function_group
from ..messages import name_list

__all__ = [
    "GROUPS",
    "OTHER",
    "GROUPS_WITH_OTHER",
    "GROUP_NAMES",
    "DOF_GROUPS",
    "DEFAULT_THRESHOLD_M",
    "dof_group_pair",
    "group_weights",
    "has_function_group",
    "group_rates",
    "group_shares",
    "muscle_membership",
    "membership_table",
    "group_key_table",
    "write_group_key",
]

OTHER = "other"
GROUPS_WITH_OTHER = GROUPS + (OTHER,)
GROUP_NAMES = {
    "PF": "ankle plantarflexors",
    "DF": "ankle dorsiflexors",
    "KE": "knee extensors",
    "KF": "knee flexors",
    "HE": "hip extensors",
    "HF": "hip flexors",
    "HAD": "hip adductors",
    "HAB": "hip abductors",
    "HIR": "hip internal rotators",
    "HER": "hip external rotators",
    OTHER: "no moment arm above the threshold",
}
#: Moment arms at or below this magnitude (m) count as zero.
DEFAULT_THRESHOLD_M = 1e-3


def _moment_arms(moment_arms_m, dofs) -> tuple[np.ndarray, list[str]]:
    r = np.asarray(moment_arms_m, dtype=float)
    dofs = [str(d) for d in dofs]
    if r.ndim != 3:
        raise DataMismatchError(
            f"moment_arms_m must have shape (time, dofs, muscles), not {r.shape}"
        )
    if r.shape[1] != len(dofs):
        raise DataMismatchError(
            f"moment_arms_m has {r.shape[1]} DOFs along axis 1 but {len(dofs)} DOF names were given ({name_list(dofs)})"
        )
    if len(set(dofs)) != len(dofs):
        raise OptionError(f"DOF list {dofs} names a DOF twice")
    if not np.all(np.isfinite(r)):
        raise OptionError("moment_arms_m holds NaN or infinite values")
    return r, dofs


def _threshold(threshold_m) -> float:
    try:
        thr = float(threshold_m)
    except (TypeError, ValueError):
        raise OptionError(f"threshold_m must be a number of metres, not {threshold_m!r}") from None
    if not (np.isfinite(thr) and thr >= 0):
        raise OptionError(f"threshold_m must be a non-negative number of metres, not {threshold_m!r}")
    return thr


def group_weights(
    moment_arms_m,
    dofs: Sequence[str],
    threshold_m: float = DEFAULT_THRESHOLD_M,
    *,
    dof_groups: Mapping[str, tuple[str, str]] | None = None,
) -> np.ndarray:
    """Share of each muscle's rate that goes to each group, at every instant.

    Parameters
    ----------
    moment_arms_m : (T, D, M) m
        Moment arms (OpenSim convention) of ``M`` muscles about ``D`` DOFs at ``T`` times.
    dofs : D DOF names, e.g. ``ankle_angle_r``
    threshold_m : m
        Moment arms with ``|r| <= threshold_m`` count as zero (1 mm).
    dof_groups : optional ``{dof: (positive_group, negative_group)}`` overrides.

    Returns
    -------
    (T, 11, M) array
        Weights over :data:`GROUPS_WITH_OTHER` (the ten groups, then ``other``); for each
        muscle and time they are non-negative and sum to 1. ``other`` is 1 where no
        moment arm of the muscle exceeds the threshold.
    """
    r, dofs = _moment_arms(moment_arms_m, dofs)
    thr = _threshold(threshold_m)
    pairs = [dof_group_pair(d, dof_groups) for d in dofs]
    a = np.where(np.abs(r) > thr, np.abs(r), 0.0)
    total = a.sum(axis=1)  # (T, M)
    spans = total > 0
    w = np.divide(a, total[:, None, :], out=np.zeros_like(a), where=spans[:, None, :])
    out = np.zeros((r.shape[0], len(GROUPS_WITH_OTHER), r.shape[2]))
    for j, (pos, neg) in enumerate(pairs):
        out[:, GROUPS.index(pos), :] += np.where(r[:, j, :] > 0, w[:, j, :], 0.0)
        out[:, GROUPS.index(neg), :] += np.where(r[:, j, :] < 0, w[:, j, :], 0.0)
    out[:, -1, :] = ~spans
    return out


def group_rates(rate_W, weights) -> np.ndarray:
    """Group rates (W) from muscle rates and :func:`group_weights`.

    ``Edot_g(t) = sum_i weights[t, g, i] * rate_W[i, t]``.

    Parameters
    ----------
    rate_W : (M, T) W, one row per muscle (same muscle order as the weights)
    weights : (T, G, M)

    Returns
    -------
    (G, T) array, W
    """
    e = np.asarray(rate_W, dtype=float)
    w = np.asarray(weights, dtype=float)
    if e.ndim != 2 or w.ndim != 3:
        raise DataMismatchError(
            f"rate_W must be (muscles, time) and weights (time, groups, muscles); got {e.shape} and {w.shape}"
        )
    if w.shape[0] != e.shape[1] or w.shape[2] != e.shape[0]:
        raise DataMismatchError(
            f"rate_W has shape {e.shape} (muscles, time) but weights have {w.shape} (time, groups, muscles); "
            "interpolate the moment arms to the rate's times and order the muscles alike"
        )
    if not np.all(np.isfinite(e)):
        raise OptionError("rate_W holds NaN or infinite values")
    return np.einsum("tgm,mt->gt", w, e)


def group_shares(
    time_s,
    group_rate_W,
    total_W,
    groups: Sequence[str] = GROUPS_WITH_OTHER,
    *,
    cycle: GaitCycle | None = None,
    coverage_tolerance_s: float | None = None,
) -> dict[str, float]:
    """Relative cost of each group: ``integral Edot_g dt / integral Edot_total dt * 100 %``.

    Parameters
    ----------
    time_s : (T,) s
    group_rate_W : (G, T) W, e.g. from :func:`group_rates`
    total_W : (T,) W, or (M, T) summed over muscles: the whole leg's rate
    groups : the G group names, in row order (default the ten groups and ``other``)
    cycle : integrate over this gait cycle (trapezoidal rule, rates at the cycle limits
        linearly interpolated, see :func:`musclemetab.analysis.phases.phase_shares`);
        default over the whole sample span
    coverage_tolerance_s : as in :func:`~musclemetab.analysis.phases.phase_shares`

    Returns
    -------
    dict ``{group: percent}``; with the default rows and ``total_W`` the sum of the
    muscles' rates the values sum to 100.
    """
    t = as_time(time_s, "time_s")
    g = as_signal(group_rate_W, t, "group_rate_W")
    tot = as_signal(total_W, t, "total_W")
    if tot.ndim > 1:
        tot = tot.reshape(-1, t.size).sum(axis=0)
    groups = [str(x) for x in groups]
    if g.ndim != 2 or g.shape[0] != len(groups):
        raise DataMismatchError(
            f"group_rate_W has shape {g.shape}; expected ({len(groups)}, {t.size}) for groups {', '.join(groups)}"
        )
    if cycle is None:
        a, b = float(t[0]), float(t[-1])
    else:
        a, b = coverage(t, cycle.start_s, cycle.end_s, coverage_tolerance_s, "group_rate_W")
    whole = float(integrate_interval(t, tot, a, b))
    if whole == 0:
        raise DataMismatchError("the whole leg's metabolic energy is 0 J; group shares are undefined")
    parts = integrate_interval(t, g, a, b)
    return {name: float(100.0 * p / whole) for name, p in zip(groups, parts)}


def _stack_trials(moment_arms_m) -> np.ndarray:
    if isinstance(moment_arms_m, np.ndarray):
        return moment_arms_m
    arrays = [np.asarray(x, dtype=float) for x in moment_arms_m]
    if arrays and arrays[0].ndim == 3:
        shapes = {x.shape[1:] for x in arrays}
        if len(shapes) != 1:
            raise DataMismatchError(
                f"the trials' moment arms have different (dofs, muscles) shapes {sorted(shapes)}; "
                "compute them for the same DOFs and muscles"
            )
        return np.concatenate(arrays, axis=0)
    return np.asarray(moment_arms_m, dtype=float)


def muscle_membership(
    moment_arms_m,
    dofs: Sequence[str],
    muscles: Sequence[str],
    threshold_m: float = DEFAULT_THRESHOLD_M,
    *,
    dof_groups: Mapping[str, tuple[str, str]] | None = None,
):
    """Group membership of each muscle about each DOF from the sign of its moment arms.

    Parameters
    ----------
    moment_arms_m : (T, D, M) m, or a list of such arrays (several trials, concatenated)
    dofs, muscles : names along axes 1 and 2
    threshold_m : m, moment arms of magnitude at or below it are ignored (1 mm)

    Returns
    -------
    pandas.DataFrame
        One row per (DOF, muscle) with ``dof``, ``muscle``, ``positive_group``,
        ``negative_group``, ``min_m``, ``max_m``, ``mean_m`` and ``membership``:
        ``"positive"`` (some ``r > threshold`` and never ``r < -threshold``),
        ``"negative"``, ``"sign_changing"`` (beyond the threshold on both sides) or
        ``"none"`` (never beyond it).
    """
    import pandas as pd

    r, dofs = _moment_arms(_stack_trials(moment_arms_m), dofs)
    muscles = [str(m) for m in muscles]
    if r.shape[2] != len(muscles):
        raise DataMismatchError(
            f"moment_arms_m has {r.shape[2]} muscles along axis 2 but {len(muscles)} muscle names were given"
        )
    thr = _threshold(threshold_m)
    rows = []
    for j, d in enumerate(dofs):
        pos_g, neg_g = dof_group_pair(d, dof_groups)
        for i, m in enumerate(muscles):
            x = r[:, j, i]
            above, below = bool(np.any(x > thr)), bool(np.any(x < -thr))
            kind = ("sign_changing" if above and below else "positive" if above
                    else "negative" if below else "none")
            rows.append(dict(dof=d, muscle=m, positive_group=pos_g, negative_group=neg_g,
                             min_m=float(x.min()), max_m=float(x.max()), mean_m=float(x.mean()),
                             membership=kind))
    return pd.DataFrame(rows)


def membership_table(
    moment_arms_m,
    dofs: Sequence[str],
    muscles: Sequence[str],
    threshold_m: float = DEFAULT_THRESHOLD_M,
    *,
    dof_groups: Mapping[str, tuple[str, str]] | None = None,
):
    """The ``docs/analysis.md`` table: members of each DOF's two groups, and sign-changers.

    Arguments as :func:`muscle_membership`. Returns a DataFrame indexed by DOF with
    columns ``positive_group``, ``positive`` (tuple of muscles, input order),
    ``negative_group``, ``negative`` and ``sign_changing``.
    """
    import pandas as pd

    long = muscle_membership(moment_arms_m, dofs, muscles, threshold_m, dof_groups=dof_groups)
    rows = []
    for d, sub in long.groupby("dof", sort=False):
        rows.append(dict(
            dof=d,
            positive_group=sub["positive_group"].iloc[0],
            positive=tuple(sub.loc[sub.membership == "positive", "muscle"]),
            negative_group=sub["negative_group"].iloc[0],
            negative=tuple(sub.loc[sub.membership == "negative", "muscle"]),
            sign_changing=tuple(sub.loc[sub.membership == "sign_changing", "muscle"]),
        ))
    return pd.DataFrame(rows).set_index("dof")


def group_key_table(dof_groups: Mapping[str, tuple[str, str]] | None = None):
    """The key of the group abbreviations: ``group``, ``name``, ``dof``, ``moment_arm_sign``
    and the results column ``share_<group>_pct`` (one row per group and ``other``)."""
    import pandas as pd

    pairs = dict(DOF_GROUPS if dof_groups is None else dof_groups)
    rows = []
    for g in GROUPS_WITH_OTHER:
        dof, sign = "", ""
        for d, (pos, neg) in pairs.items():
            if g in (pos, neg):
                dof, sign = d, "positive" if g == pos else "negative"
        rows.append({"group": g, "name": GROUP_NAMES.get(g, g), "dof": dof, "moment_arm_sign": sign,
                     "column": f"share_{g}_pct"})
    return pd.DataFrame(rows)


def write_group_key(path, dof_groups: Mapping[str, tuple[str, str]] | None = None):
    """Write :func:`group_key_table` as CSV (atomically); returns the path."""
    from ..io.atomic import atomic_path

    with atomic_path(path) as tmp:
        group_key_table(dof_groups).to_csv(tmp, index=False)
    return path

"""Repeated-measures correlation and Bland-Altman limits of agreement.

Repeated-measures correlation (Bland & Altman 1995a, "Calculating correlation
coefficients with repeated observations: Part 1 -- correlation within subjects", BMJ
310:446; Bakdash & Marusich 2017, rmcorr) as written in ``docs/analysis.md``. For subjects
``s`` with paired observations ``(x_sk, y_sk)``::

    x~_sk = x_sk - mean_k x_sk ,  y~_sk = y_sk - mean_k y_sk     (within-subject centring)
    beta     = sum x~ y~ / sum x~^2                               (common slope)
    SS_model = beta^2 sum x~^2 ,  SS_error = sum (y~ - beta x~)^2
    r_rm     = sign(beta) sqrt(SS_model / (SS_model + SS_error))
    df       = N - S - 1
    t        = r_rm sqrt(df / (1 - r_rm^2)) ,  p two-sided from Student's t(df)

i.e. the ANCOVA ``y_sk = alpha_s + beta x_sk + e`` with one intercept per subject and a
common slope; ``alpha_s = mean_k y_sk - beta mean_k x_sk``.

Bland-Altman (Bland & Altman 1986, Lancet 327:307): differences ``d = estimated -
measured``, bias ``mean(d)``, ``SD`` the sample standard deviation (``n - 1``), 95 %
limits of agreement ``bias +- 1.96 SD``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataMismatchError, OptionError

__all__ = ["RmCorr", "rmcorr", "BlandAltman", "bland_altman"]


@dataclass(frozen=True)
class RmCorr:
    """Result of :func:`rmcorr`.

    ``slope`` (units of y per unit of x), ``r`` (-), two-sided ``p``, ``df`` = N - S - 1,
    ``intercepts`` ``{subject: alpha_s}``, ``n_subjects`` S, ``n`` N observations, and the
    ``t`` statistic.
    """

    slope: float
    r: float
    p: float
    df: int
    intercepts: dict
    n_subjects: int
    n: int
    t: float


def _vector(x, name: str) -> np.ndarray:
    try:
        v = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise OptionError(f"{name} must hold numbers") from None
    if v.ndim != 1:
        raise DataMismatchError(f"{name} must be 1-D, not of shape {v.shape}")
    if not np.all(np.isfinite(v)):
        k = int(np.flatnonzero(~np.isfinite(v))[0])
        raise OptionError(f"{name} holds NaN or infinite values (first at position {k}); remove those observations")
    return v


def rmcorr(x, y, subject) -> RmCorr:
    """Repeated-measures correlation of ``y`` on ``x`` (``docs/analysis.md``).

    Parameters
    ----------
    x, y : (N,) paired observations (any units)
    subject : (N,) subject label of each observation (any hashable values)

    Subjects with a single observation add nothing to the sums (their centred values are
    zero) and leave ``df`` unchanged (one observation, one intercept).

    Raises
    ------
    DataMismatchError
        Lengths differ; fewer than two subjects; ``df < 1``; ``x`` or ``y`` constant
        within every subject.
    OptionError
        NaN or non-numeric values, or missing subject labels.
    """
    xv, yv = _vector(x, "x"), _vector(y, "y")
    subj = np.asarray(subject, dtype=object)
    if subj.ndim != 1:
        raise DataMismatchError(f"subject must be 1-D, not of shape {subj.shape}")
    if not (xv.size == yv.size == subj.size):
        raise DataMismatchError(
            f"x, y and subject must have the same length, not {xv.size}, {yv.size} and {subj.size}"
        )
    if any(s is None or (isinstance(s, float) and np.isnan(s)) for s in subj):
        raise OptionError("subject holds missing labels; give every observation a subject")
    labels = list(dict.fromkeys(subj.tolist()))
    n, n_s = xv.size, len(labels)
    if n_s < 2:
        raise DataMismatchError(
            f"repeated-measures correlation needs at least two subjects, got {n_s}"
        )
    df = n - n_s - 1
    if df < 1:
        raise DataMismatchError(
            f"{n} observations of {n_s} subjects leave {df} degrees of freedom (N - S - 1); "
            "give more observations per subject"
        )
    index = {s: k for k, s in enumerate(labels)}
    code = np.array([index[s] for s in subj.tolist()])
    count = np.bincount(code, minlength=n_s)
    mx = np.bincount(code, weights=xv, minlength=n_s) / count
    my = np.bincount(code, weights=yv, minlength=n_s) / count
    xc, yc = xv - mx[code], yv - my[code]
    sxx, syy = float(xc @ xc), float(yc @ yc)
    if sxx == 0:
        raise DataMismatchError("x does not vary within any subject; the within-subject slope is undefined")
    if syy == 0:
        raise DataMismatchError("y does not vary within any subject; the correlation is undefined")
    beta = float(xc @ yc) / sxx
    ss_model = beta**2 * sxx
    ss_error = float(np.sum((yc - beta * xc) ** 2))
    r = float(np.sign(beta) * np.sqrt(ss_model / (ss_model + ss_error)))
    if abs(r) >= 1.0:
        t, p = float(np.sign(r) * np.inf), 0.0
    else:
        from scipy.special import stdtr  # Student-t CDF (imported when needed: scipy is slow to import)

        t = r * np.sqrt(df / (1.0 - r * r))
        p = float(2.0 * stdtr(df, -abs(t)))
    intercepts = {s: float(my[k] - beta * mx[k]) for s, k in index.items()}
    return RmCorr(slope=beta, r=r, p=p, df=int(df), intercepts=intercepts, n_subjects=n_s, n=int(n), t=float(t))


@dataclass(frozen=True)
class BlandAltman:
    """Bland-Altman agreement: ``bias`` = mean(estimated - measured), sample ``sd`` of the
    differences, 95 % limits ``lower``/``upper`` = bias -+ ``z`` sd, ``n`` pairs."""

    bias: float
    sd: float
    lower: float
    upper: float
    n: int
    z: float = 1.96


def bland_altman(estimated, measured, *, z: float = 1.96) -> BlandAltman:
    """Bias and 95 % limits of agreement of ``estimated`` against ``measured``.

    ``d = estimated - measured``; ``bias = mean(d)``; ``sd = std(d, ddof=1)``; limits
    ``bias -+ z sd`` with ``z = 1.96``. Same units as the inputs.

    Raises :class:`DataMismatchError` for different lengths or fewer than two pairs, and
    :class:`OptionError` for NaN or a non-positive ``z``.
    """
    e, m = _vector(estimated, "estimated"), _vector(measured, "measured")
    if e.size != m.size:
        raise DataMismatchError(f"estimated and measured must have the same length, not {e.size} and {m.size}")
    if e.size < 2:
        raise DataMismatchError(f"Bland-Altman limits need at least two pairs, got {e.size}")
    if not (np.isfinite(z) and z > 0):
        raise OptionError(f"z must be a positive number, not {z!r}")
    d = e - m
    bias = float(d.mean())
    sd = float(d.std(ddof=1))
    return BlandAltman(bias=bias, sd=sd, lower=bias - z * sd, upper=bias + z * sd, n=int(e.size), z=float(z))

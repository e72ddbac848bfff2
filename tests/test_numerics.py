"""The solve path's NumPy numerics (``musclemetab._numerics``) against SciPy and hand-worked cases.

SciPy stays a dependency of the package (calibration, EMG files, reports); the solve path
does without it, so these tests hold the NumPy code to SciPy's results: Butterworth
coefficients to 1e-13 relative, zero-phase filtering and splines to 1e-12, the bounded least
squares to the same minimiser.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.optimize import lsq_linear
from scipy.signal import butter, filtfilt

from musclemetab._numerics import NotAKnotSpline, box_least_squares, butterworth, filter_padlen
from musclemetab._numerics import filtfilt as np_filtfilt


# --------------------------------------------------------------------------- Butterworth
@pytest.mark.parametrize("order", [1, 2, 3, 4, 6, 8])
@pytest.mark.parametrize("btype,wn", [("lowpass", 0.12), ("lowpass", 0.02), ("lowpass", 0.7), ("highpass", 0.05),
                                      ("highpass", 0.5), ("bandpass", (0.02, 0.4)), ("bandpass", (0.2, 0.9))])
def test_butterworth_equals_scipy(order, btype, wn):
    b, a = butterworth(order, wn, btype)
    b_ref, a_ref = butter(order, wn, btype=btype)
    assert b.dtype == a.dtype == np.float64
    assert b.shape == b_ref.shape and a.shape == a_ref.shape
    np.testing.assert_allclose(b, b_ref, rtol=1e-13, atol=1e-13 * np.max(np.abs(b_ref)))
    np.testing.assert_allclose(a, a_ref, rtol=1e-13, atol=1e-13 * np.max(np.abs(a_ref)))


def test_butterworth_by_hand():
    """First order low-pass at a quarter of the sampling rate (wn = 0.5): the analog pole
    -W with W = 4 tan(pi/4) = 4 maps to z = (4 - 4)/(4 + 4) = 0, the zero to -1, and the
    DC gain is 1: b = [1/2, 1/2], a = [1, 0]."""
    b, a = butterworth(1, 0.5)
    np.testing.assert_allclose(b, [0.5, 0.5], atol=1e-15)
    np.testing.assert_allclose(a, [1.0, 0.0], atol=1e-15)
    # the low-pass response is that of a Butterworth: |H|^2 = 1/(1 + (tan(w/2)/tan(wc/2))^(2n))
    b, a = butterworth(6, 0.12)
    w = np.linspace(0.01, 3.1, 50)
    zi = np.exp(-1j * w)
    h = np.polyval(b[::-1], zi) / np.polyval(a[::-1], zi)
    expected = 1.0 / (1.0 + (np.tan(w / 2) / np.tan(np.pi * 0.12 / 2)) ** 12)
    np.testing.assert_allclose(np.abs(h) ** 2, expected, rtol=1e-9, atol=1e-13)


def test_butterworth_refuses_bad_cutoffs():
    for wn in (0.0, 1.0, 1.5, -0.1):
        with pytest.raises(ValueError, match="between 0 and 1"):
            butterworth(4, wn)
    with pytest.raises(ValueError, match="bandpass"):
        butterworth(4, 0.2, "bandpass")
    with pytest.raises(ValueError, match="positive integer"):
        butterworth(0, 0.2)


# --------------------------------------------------------------------------- zero phase
@pytest.mark.parametrize("order,cutoff_hz,fs_hz,btype", [
    (6, 6.0, 100.0, "lowpass"), (6, 6.0, 120.0, "lowpass"), (2, 6.0, 60.0, "lowpass"), (4, 35.0, 1000.0, "lowpass"),
    (2, (20.0, 400.0), 2000.0, "bandpass"), (3, 10.0, 200.0, "highpass"), (1, 15.0, 100.0, "lowpass"),
])
def test_filtfilt_equals_scipy(order, cutoff_hz, fs_hz, btype):
    rng = np.random.default_rng(order)
    x = np.cumsum(rng.normal(size=(157, 4)), axis=0) + 3.0
    wn = np.asarray(cutoff_hz) / (fs_hz / 2)
    b, a = butter(order, wn, btype=btype)
    padlen = filter_padlen(b, a)
    ref = filtfilt(b, a, x, axis=0, padtype="odd", padlen=padlen)
    scale = np.max(np.abs(ref))
    np.testing.assert_allclose(np_filtfilt(b, a, x, padlen), ref, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(np_filtfilt(b, a, x[:, 2]), ref[:, 2], rtol=0, atol=1e-12 * scale)  # 1-D
    # 3-D: the columns are every trailing index
    x3 = x.reshape(157, 2, 2)
    np.testing.assert_allclose(np_filtfilt(b, a, x3, padlen), ref.reshape(157, 2, 2), rtol=0, atol=1e-12 * scale)
    # another padding, as SciPy's own default (3 max(len(a), len(b)))
    ref21 = filtfilt(b, a, x, axis=0, padtype="odd")
    np.testing.assert_allclose(np_filtfilt(b, a, x, 3 * max(len(a), len(b))), ref21, rtol=0, atol=1e-12 * scale)


def test_filtfilt_keeps_a_constant_and_refuses_short_signals():
    """Started from the steady state of a step scaled by the first (padded) sample, a
    low-pass with DC gain 1 returns a constant unchanged, with no start-up transient."""
    b, a = butterworth(6, 0.12)
    const = np.full((60, 2), [2.5, -7.0])
    np.testing.assert_allclose(np_filtfilt(b, a, const), const, rtol=1e-10)
    with pytest.raises(ValueError, match="needs more"):
        np_filtfilt(b, a, const[:18])


# --------------------------------------------------------------------------- splines
@pytest.mark.parametrize("n", [2, 3, 4, 5, 12, 121])
def test_spline_equals_scipy_not_a_knot(n):
    rng = np.random.default_rng(n)
    x = np.sort(rng.uniform(0.0, 1.3, n)) if n > 3 else np.array([0.0, 0.4, 1.1][:n])
    y = rng.normal(size=(n, 3, 2))
    ref = CubicSpline(x, y, axis=0, bc_type="not-a-knot")
    sp = NotAKnotSpline(x, y)
    q = np.concatenate([np.linspace(x[0], x[-1], 97), x, [x[0] - 0.05, x[-1] + 0.05]])
    for nu in (0, 1):
        r = ref(q, nu)
        np.testing.assert_allclose(sp(q, nu), r, rtol=0, atol=1e-12 * np.max(np.abs(r)))
    assert sp(q).shape == (q.size, 3, 2)
    np.testing.assert_allclose(sp(x), y, atol=1e-13)  # it interpolates


def test_spline_on_a_uniform_mesh_and_by_hand():
    t = np.linspace(0.37, 1.55, 119)
    y = np.column_stack([np.sin(3 * t), t**3 - t, np.exp(-t)])
    mesh = np.linspace(t[0], t[-1], 101)
    sp, ref = NotAKnotSpline(t, y), CubicSpline(t, y, axis=0, bc_type="not-a-knot")
    np.testing.assert_allclose(sp(mesh), ref(mesh), rtol=0, atol=1e-13)
    np.testing.assert_allclose(sp(mesh, 1), ref(mesh, 1), rtol=0, atol=1e-11)
    # a cubic is reproduced exactly by a not-a-knot spline, derivative included
    np.testing.assert_allclose(sp(mesh)[:, 1], mesh**3 - mesh, atol=1e-12)
    np.testing.assert_allclose(sp(mesh, 1)[:, 1], 3 * mesh**2 - 1, atol=1e-10)
    # three points: the parabola through them; y = (x - 1)^2 at 0, 1, 3
    p = NotAKnotSpline([0.0, 1.0, 3.0], [1.0, 0.0, 4.0])
    np.testing.assert_allclose(p(np.array([2.0, -1.0])), [1.0, 4.0], atol=1e-14)
    np.testing.assert_allclose(p(np.array([2.0]), 1), [2.0], atol=1e-14)
    with pytest.raises(ValueError, match="increasing"):
        NotAKnotSpline([0.0, 1.0, 1.0, 2.0], [0.0, 1.0, 2.0, 3.0])


# --------------------------------------------------------------------------- bounded least squares
def _scipy_bvls(A, b, weight):
    m = A.shape[1]
    sw = np.sqrt(weight)
    sol = lsq_linear(np.vstack([np.eye(m), sw * A]), np.concatenate([np.zeros(m), sw * b]),
                     bounds=(0.0, 1.0), method="bvls", tol=1e-12)
    return np.clip(sol.x, 0.0, 1.0)


def _objective(a, A, b, weight):
    r = b - A @ a
    return a @ a + weight * r @ r


def test_box_least_squares_equals_scipy_on_random_problems():
    """Seeded problems shaped like a frame of the static optimisation (5 DOFs, 40 muscles,
    forces per unit activation up to ~1e3 N m, moments up to ~5e3 N m), some with muscles
    that cross no DOF, some with the upper bound active."""
    rng = np.random.default_rng(2024)
    n_upper = 0
    for k in range(120):
        A = rng.normal(size=(5, 40)) * rng.uniform(1.0, 1000.0)
        if k % 4 == 0:
            A[:, :12] = 0.0
        b = rng.normal(size=5) * (50.0 if k % 3 else 5000.0)
        a = box_least_squares(A, b, 1000.0)
        ref = _scipy_bvls(A, b, 1000.0)
        assert np.all((a >= 0.0) & (a <= 1.0))
        np.testing.assert_allclose(a, ref, rtol=0, atol=1e-7)
        f, f_ref = _objective(a, A, b, 1000.0), _objective(ref, A, b, 1000.0)
        assert f <= f_ref * (1 + 1e-12) + 1e-300
        n_upper += int(np.any(a == 1.0))
    assert n_upper >= 10  # the upper bound was exercised


def test_box_least_squares_by_hand():
    """One muscle: the minimiser of a^2 + w (b - A a)^2 is w A b / (1 + w A^2), clipped."""
    w = 1000.0
    for A, b in ((2.0, 1.0), (2.0, 5.0), (2.0, -1.0), (0.0, 3.0)):
        expected = min(max(w * A * b / (1 + w * A * A), 0.0), 1.0)
        np.testing.assert_allclose(box_least_squares(np.array([[A]]), np.array([b]), w), [expected], atol=1e-15)
    # two muscles on one DOF, equal arms: the optimum shares the moment equally
    a = box_least_squares(np.array([[10.0, 10.0]]), np.array([8.0]), w)
    expected = w * 10 * 8 / (1 + 2 * w * 100)
    np.testing.assert_allclose(a, [expected, expected], atol=1e-14)

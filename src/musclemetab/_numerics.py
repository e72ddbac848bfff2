"""Small numerical building blocks of the solve path, in NumPy alone.

The solver's start-up must not import SciPy's signal, interpolate or optimize packages
(about two CPU seconds of imports for three small computations), so these are written
here from their equations:

* :func:`butterworth` -- digital Butterworth design ``(b, a)``: the analog prototype's poles
  ``p_k = -exp(i pi (2k - n + 1) / (2n))``, ``k = 0..n-1`` (unit cut-off, no zeros), the
  cut-off pre-warped to ``W = 4 tan(pi wn / 2)`` (normalised frequency ``wn`` = cut-off
  over Nyquist, sampling interval 1/2), the frequency transformation (low-pass
  ``s -> s/W``; high-pass ``s -> W/s``; band-pass ``s -> (s^2 + W0^2)/(s B)`` with
  ``W0 = sqrt(W1 W2)``, ``B = W2 - W1``), the bilinear transform ``z = (4 + s)/(4 - s)``
  (zeros at infinity go to ``z = -1``) with the gain that keeps the transfer function
  equal, and the polynomials ``b = k prod(1 - z_i z^-1)``, ``a = prod(1 - p_i z^-1)``.
* :func:`filtfilt` -- zero-phase filtering along axis 0: odd reflection of ``padlen``
  samples at both ends (``2 x_0 - x_{padlen..1}``, ``2 x_end - x_{end-1..end-padlen}``), a
  forward pass of the direct-form-II-transposed recursion started from the steady state of
  a unit step scaled by the first padded sample, then the same backward, padding removed.
* :class:`NotAKnotSpline` -- cubic spline interpolation with not-a-knot end conditions
  (third derivative continuous at the second and second-to-last knots), from the
  tridiagonal system for the knot slopes; values and first derivative.
* :func:`box_least_squares` -- ``min ||a||^2 + w ||b - A a||^2, lo <= a <= hi``, a strictly
  convex quadratic programme with a unique minimiser, solved exactly by a primal active-set
  method.

Every function works column by column on 2-D arrays (time first), vectorised over columns.
References: Oppenheim AV, Schafer RW (2010) Discrete-Time Signal Processing, 3rd ed.
(Butterworth design by the bilinear transform, direct form II transposed); Gustafsson F
(1996) Determining the initial states in forward-backward filtering, IEEE Trans Signal
Process 44:988-992; de Boor C (2001) A Practical Guide to Splines, rev. ed. (not-a-knot
condition); Nocedal J, Wright SJ (2006) Numerical Optimization, 2nd ed., ch. 16 (active-set
methods for convex quadratic programmes).
"""

from __future__ import annotations

import numpy as np

__all__ = ["butterworth", "filtfilt", "filter_padlen", "NotAKnotSpline", "box_least_squares"]


# --------------------------------------------------------------------------- Butterworth


def _poly(roots: np.ndarray) -> np.ndarray:
    """Coefficients (highest power first) of ``prod(x - r)``; real when the roots come in
    conjugate pairs."""
    c = np.ones(1, dtype=complex)
    for r in roots:
        c = np.convolve(c, np.array([1.0, -r]))
    if np.array_equal(np.sort(roots.imag), np.sort(-roots.imag)):
        return c.real.copy()
    return c


def butterworth(order: int, wn, btype: str = "lowpass") -> tuple[np.ndarray, np.ndarray]:
    """Digital Butterworth filter ``(b, a)`` of design order ``order`` (module docstring).

    ``wn`` is the cut-off as a fraction of the Nyquist frequency (``0 < wn < 1``), two
    increasing values for ``btype='bandpass'`` (whose polynomials then have degree
    ``2 order``). ``btype`` is ``'lowpass'``, ``'highpass'`` or ``'bandpass'``.
    """
    order = int(order)
    if order < 1:
        raise ValueError(f"the filter order must be a positive integer, not {order}")
    wn = np.atleast_1d(np.asarray(wn, dtype=float))
    if np.any(wn <= 0) or np.any(wn >= 1):
        raise ValueError(f"normalised cut-off {list(wn)} must lie strictly between 0 and 1")
    expected = 2 if btype == "bandpass" else 1
    if btype not in ("lowpass", "highpass", "bandpass") or wn.size != expected:
        raise ValueError(f"btype {btype!r} with {wn.size} cut-off(s): use 'lowpass'/'highpass' with one "
                         "cut-off or 'bandpass' with two")
    # Analog prototype: unit cut-off, poles on the left half of the unit circle.
    m = np.arange(-order + 1, order, 2, dtype=float)
    p = -np.exp(1j * np.pi * m / (2 * order))
    z = np.zeros(0, dtype=complex)
    k = 1.0
    warped = 4.0 * np.tan(np.pi * wn / 2.0)  # bilinear transform with sampling interval 1/2
    if btype == "lowpass":
        p = warped[0] * p
        k = k * warped[0] ** order
    elif btype == "highpass":
        k = k * float(np.real(1.0 / np.prod(-p)))
        p = warped[0] / p
        z = np.zeros(order, dtype=complex)
    else:
        bw = warped[1] - warped[0]
        w0 = np.sqrt(warped[0] * warped[1])
        half = p * bw / 2.0
        root = np.sqrt(half**2 - w0**2)
        p = np.concatenate([half + root, half - root])
        z = np.zeros(order, dtype=complex)
        k = k * bw**order
    degree = p.size - z.size
    zd = np.concatenate([(4.0 + z) / (4.0 - z), -np.ones(degree)])
    pd_ = (4.0 + p) / (4.0 - p)
    kd = k * float(np.real(np.prod(4.0 - z) / np.prod(4.0 - p)))
    return kd * _poly(zd), _poly(pd_)


# --------------------------------------------------------------------------- zero phase


def filter_padlen(b, a) -> int:
    """Samples of odd reflection at each end: ``3 (max(len(a), len(b)) - 1)`` (MATLAB's
    ``filtfilt``; 18 for a 6th-order low-pass)."""
    return 3 * (max(len(a), len(b)) - 1)


def _steady_state(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Delay-line state ``zi`` of the transposed direct form II after a unit step has settled.

    With ``a_0 = 1``, the states satisfy ``zi = C^T zi + (b_{1:} - a_{1:} b_0)`` where ``C``
    is the companion matrix of ``a`` (first row ``-a_{1:}``, ones below the diagonal).
    """
    n = b.size
    companion = np.zeros((n - 1, n - 1))
    companion[0] = -a[1:]
    companion[np.arange(1, n - 1), np.arange(n - 2)] = 1.0
    return np.linalg.solve(np.eye(n - 1) - companion.T, b[1:] - a[1:] * b[0])


def _df2t(b: np.ndarray, a: np.ndarray, x: np.ndarray, state: np.ndarray) -> np.ndarray:
    """Direct form II transposed along axis 0 of ``x`` ``(T, C)`` from ``state`` ``(n-1, C)``:
    ``y_t = b_0 x_t + z_0``, ``z_i = z_{i+1} + b_{i+1} x_t - a_{i+1} y_t`` (``z_{n-1} = 0``)."""
    z = state.copy()
    y = np.empty_like(x)
    bm, am = b[1:-1, None], a[1:-1, None]
    for t in range(x.shape[0]):
        xt = x[t]
        yt = z[0] + b[0] * xt
        y[t] = yt
        z[:-1] = z[1:] + xt * bm - yt * am
        z[-1] = xt * b[-1] - yt * a[-1]
    return y


def filtfilt(b, a, x, padlen: int | None = None) -> np.ndarray:
    """Zero-phase (forward-backward) filtering of ``x`` along axis 0 (module docstring).

    ``x`` is 1-D or 2-D (time first, columns filtered independently); ``padlen`` defaults to
    :func:`filter_padlen`. Raises ``ValueError`` when ``x`` has no more samples than ``padlen``.
    """
    b = np.atleast_1d(np.asarray(b, dtype=float))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    b, a = b / a[0], a / a[0]
    n = max(a.size, b.size)
    b = np.concatenate([b, np.zeros(n - b.size)])
    a = np.concatenate([a, np.zeros(n - a.size)])
    if padlen is None:
        padlen = filter_padlen(b, a)
    x = np.asarray(x, dtype=float)
    one_d = x.ndim == 1
    x2 = x.reshape(x.shape[0], -1)
    if x2.shape[0] <= padlen:
        raise ValueError(f"{x2.shape[0]} samples; zero-phase filtering with padding {padlen} needs more")
    if padlen > 0:
        left = 2.0 * x2[0] - x2[padlen:0:-1]
        right = 2.0 * x2[-1] - x2[-2:-padlen - 2:-1]
        ext = np.concatenate([left, x2, right])
    else:
        ext = x2
    if n == 1:
        y = b[0] * b[0] * ext
    else:
        zi = _steady_state(b, a)[:, None]
        y = _df2t(b, a, ext, zi * ext[0])
        y = _df2t(b, a, y[::-1], zi * y[-1])[::-1]
    if padlen > 0:
        y = y[padlen:-padlen]
    y = np.ascontiguousarray(y)
    return y.reshape(x.shape) if not one_d else y[:, 0]


# --------------------------------------------------------------------------- splines


class NotAKnotSpline:
    """Cubic spline through ``(x_i, y_i)`` with not-a-knot end conditions, along axis 0.

    ``y`` is ``(n,)`` or ``(n, ...)``. The knot slopes ``s_i`` solve, for interior knots,
    ``h_i s_{i-1} + 2 (h_{i-1} + h_i) s_i + h_{i-1} s_{i+1} = 3 (h_i d_{i-1} + h_{i-1} d_i)``
    (``h_i = x_{i+1} - x_i``, ``d_i`` the secant slopes), and at the ends the condition that
    the first two (last two) pieces are one cubic. Two points give the line, three the
    parabola through them. Outside ``[x_0, x_{n-1}]`` the end pieces are extrapolated.
    """

    def __init__(self, x, y):
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        if x.ndim != 1 or x.size < 2 or y.shape[0] != x.size:
            raise ValueError(f"a spline needs at least 2 knots and one value per knot ({x.shape} vs {y.shape})")
        h = np.diff(x)
        if np.any(h <= 0):
            raise ValueError("the spline knots must be strictly increasing")
        self._shape = y.shape[1:]
        yy = y.reshape(x.size, -1)
        hc = h[:, None]
        d = np.diff(yy, axis=0) / hc
        n = x.size
        if n == 2:
            s = np.vstack([d[0], d[0]])
        elif n == 3:
            # the parabola: s_0 + s_1 = 2 d_0, s_1 + s_2 = 2 d_1, and the interior equation
            A = np.array([[1.0, 1.0, 0.0], [h[1], 2 * (h[0] + h[1]), h[0]], [0.0, 1.0, 1.0]])
            rhs = np.vstack([2 * d[0], 3 * (h[1] * d[0] + h[0] * d[1]), 2 * d[1]])
            s = np.linalg.solve(A, rhs)
        else:
            lower = np.empty(n)  # lower[i] multiplies s_{i-1} in row i
            diag = np.empty(n)
            upper = np.empty(n)  # upper[i] multiplies s_{i+1} in row i
            rhs = np.empty((n, yy.shape[1]))
            lower[1:-1] = h[1:]
            diag[1:-1] = 2 * (h[:-1] + h[1:])
            upper[1:-1] = h[:-1]
            rhs[1:-1] = 3 * (hc[1:] * d[:-1] + hc[:-1] * d[1:])
            w0 = x[2] - x[0]
            diag[0], upper[0] = h[1], w0
            rhs[0] = ((h[0] + 2 * w0) * h[1] * d[0] + h[0] ** 2 * d[1]) / w0
            w1 = x[-1] - x[-3]
            lower[-1], diag[-1] = w1, h[-2]
            rhs[-1] = (h[-1] ** 2 * d[-2] + (2 * w1 + h[-1]) * h[-2] * d[-1]) / w1
            s = _tridiagonal_solve(lower, diag, upper, rhs)
        # Piecewise cubic in t = x - x_i: c3 t^3 + c2 t^2 + c1 t + c0.
        self.x = x
        self._c3 = (s[:-1] + s[1:] - 2 * d) / hc**2
        self._c2 = (3 * d - 2 * s[:-1] - s[1:]) / hc
        self._c1 = s[:-1]
        self._c0 = yy[:-1]

    def __call__(self, xq, nu: int = 0) -> np.ndarray:
        """Values (``nu=0``) or first derivative (``nu=1``) at ``xq``, shape ``xq.shape + y.shape[1:]``."""
        xq = np.asarray(xq, dtype=float)
        flat = xq.reshape(-1)
        i = np.clip(np.searchsorted(self.x, flat, side="right") - 1, 0, self.x.size - 2)
        t = (flat - self.x[i])[:, None]
        if nu == 0:
            out = ((self._c3[i] * t + self._c2[i]) * t + self._c1[i]) * t + self._c0[i]
        elif nu == 1:
            out = (3 * self._c3[i] * t + 2 * self._c2[i]) * t + self._c1[i]
        else:
            raise ValueError(f"derivative order {nu}: only values (0) and first derivatives (1) are offered")
        return out.reshape(xq.shape + self._shape)


def _tridiagonal_solve(lower, diag, upper, rhs):
    """Forward elimination and back substitution (no pivoting) for a tridiagonal system whose
    rows after the first are diagonally dominant; ``rhs`` ``(n, C)``."""
    n = diag.size
    c = np.empty(n)
    dd = np.empty_like(rhs)
    c[0] = upper[0] / diag[0]
    dd[0] = rhs[0] / diag[0]
    for i in range(1, n):
        denom = diag[i] - lower[i] * c[i - 1]
        c[i] = upper[i] / denom if i < n - 1 else 0.0
        dd[i] = (rhs[i] - lower[i] * dd[i - 1]) / denom
    s = np.empty_like(rhs)
    s[-1] = dd[-1]
    for i in range(n - 2, -1, -1):
        s[i] = dd[i] - c[i] * s[i + 1]
    return s


# --------------------------------------------------------------------------- box QP


def box_least_squares(A, b, weight: float, lo: float = 0.0, hi: float = 1.0, max_iter: int | None = None):
    """The unique minimiser of ``||a||^2 + weight ||b - A a||^2`` subject to ``lo <= a <= hi``.

    The objective is strictly convex (its Hessian ``2 (I + weight A^T A)`` is positive
    definite), so the box-constrained minimiser is unique. A primal active-set method: start
    from the box projection of the unconstrained minimiser, with the components on a bound
    held there; minimise over the free components (a linear least-squares problem on the
    stacked matrix ``[I; sqrt(weight) A_free]``, which is better conditioned than the normal
    equations); step towards that minimiser until a bound blocks (hold it) or reach it;
    there, release the held component whose multiplier, the gradient
    ``g_j = a_j - weight A_j^T (b - A a)``, has the wrong sign (largest violation beyond the
    rounding error of ``g_j``), or stop when none has. Each step lowers the objective, so no
    working set repeats and the method ends at the minimiser (to rounding) in finitely many
    steps. A released component whose new minimiser lies outside its bound at once had a
    multiplier of the wrong sign only by rounding: it is held again and not released before
    the point moves.
    """
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    n = A.shape[1]
    sw = np.sqrt(weight)
    eye = np.eye(n)

    def free_minimiser(free, a):
        F = np.flatnonzero(free)
        rest = b - A[:, ~free] @ a[~free]
        lhs = np.vstack([eye[np.ix_(F, F)], sw * A[:, F]])
        rhs = np.concatenate([np.zeros(F.size), sw * rest])
        target = a.copy()
        target[F] = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
        return target

    a = np.clip(free_minimiser(np.ones(n, bool), np.zeros(n)), lo, hi)
    at_lo = a <= lo
    at_hi = a >= hi
    absA = np.abs(A)
    eps = np.finfo(float).eps
    max_iter = max_iter if max_iter is not None else 10 * n + 20
    released = -1
    bounced = np.zeros(n, bool)  # released, then blocked at once: multiplier sign was rounding
    for _ in range(max_iter):
        free = ~(at_lo | at_hi)
        target = free_minimiser(free, a) if free.any() else a.copy()
        step = target - a
        # the largest fraction of the step that stays in the box, and the bound that blocks it
        frac, blocking = 1.0, -1
        for j in np.flatnonzero(free & ((target < lo) | (target > hi))):
            f = ((lo if target[j] < lo else hi) - a[j]) / step[j]
            if f < frac:
                frac, blocking = max(f, 0.0), j
        if blocking >= 0:
            if frac > 0.0:
                bounced[:] = False
            elif blocking == released:
                bounced[blocking] = True
            released = -1
            a = a + frac * step
            low = target[blocking] < lo
            a[blocking] = lo if low else hi
            at_lo[blocking], at_hi[blocking] = low, not low
            continue
        a = target
        residual = b - A @ a
        grad = a - weight * (A.T @ residual)
        rounding = 4 * eps * (np.abs(a) + weight * (absA.T @ (np.abs(b) + absA @ np.abs(a))))
        # at the lower bound the gradient must be >= 0, at the upper bound <= 0
        violation = np.where(at_lo, -grad, 0.0) + np.where(at_hi, grad, 0.0) - rounding
        violation[bounced] = 0.0
        j = int(np.argmax(violation))
        if violation[j] <= 0.0:
            return np.clip(a, lo, hi)
        at_lo[j] = at_hi[j] = False
        released = j
    raise RuntimeError(f"the bounded least-squares problem did not converge in {max_iter} active-set steps")

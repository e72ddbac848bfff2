"""The solve path's numerical steps against their equations: the zero-phase Butterworth
low-pass (cut-off, order, no phase, constants kept), the not-a-knot splines of the mesh
values (a cubic reproduced exactly, derivative included, which no natural spline does) and
the static optimisation's bounded least squares (one muscle worked by hand)."""

from __future__ import annotations

import types

import numpy as np
import pytest

from musclemetab.redundancy import inputs as I


def _butterworth_zero_phase_gain(f, fs, fc, order):
    """|H(f)|^2 of a digital Butterworth low-pass (bilinear transform) run forward and backward."""
    return 1.0 / (1.0 + (np.tan(np.pi * f / fs) / np.tan(np.pi * fc / fs)) ** (2 * order))


# --------------------------------------------------------------------------- filter
@pytest.mark.parametrize("order", [2, 4, 6])
@pytest.mark.parametrize("f", [1.0, 4.0, 6.0, 9.0, 15.0])
def test_lowpass_gain_cutoff_and_order(order, f):
    """A sine through ``lowpass_filtfilt`` (100 Hz, 6 Hz cut-off) comes out scaled by the
    zero-phase Butterworth gain, 0.5 at the cut-off, steeper with the order, with no phase
    shift: in the middle of the record the output is the gain times the input."""
    fs = 100.0
    t = np.arange(4000) / fs
    x = np.sin(2 * np.pi * f * t + 0.3)
    y = I.lowpass_filtfilt(x[:, None], fs, 6.0, order)[:, 0]
    gain = _butterworth_zero_phase_gain(f, fs, 6.0, order)
    mid = slice(1000, 3000)
    np.testing.assert_allclose(y[mid], gain * x[mid], rtol=0, atol=1e-9)
    if f == 6.0:
        assert gain == pytest.approx(0.5)


def test_lowpass_keeps_constants_and_filters_columns_alike():
    """DC gain 1 and steady-state initial conditions: a constant passes unchanged, from the
    first sample on; every column (and every trailing index) is filtered on its own."""
    const = np.tile([2.5, -7.0, 0.0], (60, 1))
    np.testing.assert_allclose(I.lowpass_filtfilt(const, 100.0), const, rtol=1e-12, atol=1e-12)
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(size=(80, 2, 3)), axis=0)
    y = I.lowpass_filtfilt(x.reshape(80, 6), 100.0).reshape(80, 2, 3)
    np.testing.assert_allclose(y[:, 1, 2], I.lowpass_filtfilt(x[:, 1, 2:3], 100.0)[:, 0], rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- splines
def test_mesh_splines_reproduce_a_cubic():
    """IK frames at 120 Hz, mesh at 100 Hz (nodes between frames). Lengths, moment arms and
    moments that are cubics of time come out exact on the mesh, and the length velocity at
    the frames is the cubic's derivative: the not-a-knot spline reproduces cubics. A natural
    spline (zero second derivative at the ends) would not: these cubics curve at both ends."""
    t = 0.4 + np.arange(61) / 120.0
    lmt = np.column_stack([0.30 + 0.02 * (t - 0.5) ** 3 - 0.01 * t, 0.25 + 0.05 * t**2 - 0.03 * t**3])
    r = np.stack([np.column_stack([0.04 + 0.01 * t**3, -0.02 + 0.005 * t**2])], axis=1)  # (F, 1 DOF, 2 muscles)
    mom = (10.0 + 30.0 * t**3 - 12.0 * t)[:, None]
    geo = types.SimpleNamespace(time=t, muscles=("m1_r", "m2_r"), dofs=("ankle_angle_r",), lmt_m=lmt,
                                moment_arms_m=r)
    inp = I.trial_inputs(geo, t, mom, ik_time_s=t, dofs=("ankle_angle_r",), filter_inputs=False)
    s = inp.mesh_time_s
    assert inp.n_intervals == 50 and not np.isin(s[1:-1], t).all()
    np.testing.assert_allclose(inp.lmt_m[:, 0], 0.30 + 0.02 * (s - 0.5) ** 3 - 0.01 * s, rtol=0, atol=1e-14)
    np.testing.assert_allclose(inp.lmt_m[:, 1], 0.25 + 0.05 * s**2 - 0.03 * s**3, rtol=0, atol=1e-14)
    np.testing.assert_allclose(inp.moment_arms_m[:, 0, 0], 0.04 + 0.01 * s**3, rtol=0, atol=1e-14)
    np.testing.assert_allclose(inp.moments_Nm[:, 0], 10.0 + 30.0 * s**3 - 12.0 * s, rtol=0, atol=1e-11)
    np.testing.assert_allclose(inp.lmt_velocity_frames_m_per_s[:, 0], 0.06 * (t - 0.5) ** 2 - 0.01, rtol=0,
                               atol=1e-11)
    np.testing.assert_allclose(inp.lmt_velocity_frames_m_per_s[:, 1], 0.1 * t - 0.09 * t**2, rtol=0, atol=1e-11)


# --------------------------------------------------------------------------- static optimisation
@pytest.mark.parametrize("moment_Nm", [5.0, 40.0, -3.0, 5000.0])
def test_static_optimisation_one_muscle_by_hand(moment_Nm):
    """One muscle, one DOF: the minimiser of ``a^2 + 1000 (b - A a)^2`` on ``0 <= a <= 1`` is
    ``1000 A b / (1 + 1000 A^2)`` clipped to the box, with ``A = r Fact`` and
    ``b = ID - r Fpas`` the rigid-tendon forces of the frame; the reserve is ``b - A a``."""
    from musclemetab.redundancy.static_opt import rigid_tendon_forces, static_optimisation
    from musclemetab.redundancy.workflows import workflow_parameters

    t = np.arange(30) / 100.0
    lmt = np.full((30, 1), 0.32)
    r = np.full((30, 1, 1), 0.05)
    mom = np.full((30, 1), moment_Nm)
    geo = types.SimpleNamespace(time=t, muscles=("soleus_r",), dofs=("ankle_angle_r",), lmt_m=lmt, moment_arms_m=r)
    inp = I.trial_inputs(geo, t, mom, ik_time_s=t, dofs=("ankle_angle_r",), filter_inputs=False)
    model = types.SimpleNamespace(names=["soleus_r"], max_isometric_force_N=np.array([3500.0]),
                                  optimal_fiber_length_m=np.array([0.05]), tendon_slack_length_m=np.array([0.26]),
                                  pennation_angle_at_optimal_rad=np.array([0.4]),
                                  max_contraction_velocity=np.array([10.0]))
    params, _ = workflow_parameters("effort-gen", model, ["soleus_r"])
    so = static_optimisation(inp, params)
    f_act, f_pas, _ = rigid_tendon_forces(inp.lmt_frames_m, inp.lmt_velocity_frames_m_per_s, params)
    A = 0.05 * f_act[:, 0]
    b = moment_Nm - 0.05 * f_pas[:, 0]
    expected = np.clip(1000.0 * A * b / (1.0 + 1000.0 * A**2), 0.0, 1.0)
    np.testing.assert_allclose(so.activation[:, 0], expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(so.reserve_Nm[:, 0], b - A * expected, rtol=1e-9, atol=1e-9)
    if moment_Nm < 0:
        assert np.all(so.activation == 0.0)
    if moment_Nm == 5000.0:
        assert np.all(so.activation == 1.0)

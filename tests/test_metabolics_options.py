"""Model options: each changes what it should and only that.

Against OpenSim 4.6's probes with the same flags (in the worker, on a soleus clone with the
study's mass and slow-twitch fraction, as tests/test_metabolics_opensim.py): the 1 W/kg
minimum heat rate (Umberger2010 and Bhargava2004 probes, ``enforce_minimum_heat_rate_per_muscle``)
and the effort scaling S (``aerobic_factor``). By hand: the recruited fiber fractions of
BH04 and HO06.
"""

from __future__ import annotations

import numpy as np
import pytest

from musclemetab.errors import OptionError
from musclemetab.metabolics import (
    ANAEROBIC_FACTOR,
    bhargava2004,
    houdijk2006,
    uchida2016,
    umberger2003,
    umberger2010,
)
from musclemetab.opensim_bridge import call
from test_metabolics_opensim import _inputs as _opensim_inputs

# all slow-twitch: with OpenSim's activation floor of 0.01 (e = 0: A = 0.005) the Umberger
# heat falls below 1 W/kg only for slow-twitch fibers far above optimal length
MASS, FST = 0.476, 1.0
SW = ("use_Bhargava_recruitment_model", "include_negative_mechanical_work", "forbid_negative_total_power")
UMB = {"UM10": (False, False, False), "UM03": (False, True, True), "UC16": (True, True, True)}
FUNCS = {"UM10": umberger2010, "UM03": umberger2003, "UC16": uchida2016}
BH = dict(probe="Bhargava2004", use_force_dependent_shortening_prop_constant=True,
          include_negative_mechanical_work=True, maintenance_length_dependence="identity")


def _states():
    """100 states of the lowest activation, no excitation, long fibers (heat near and below
    1 W/kg), slow lengthening and shortening; 50 random states."""
    rng = np.random.default_rng(23)
    lm = np.concatenate([rng.uniform(1.4, 1.9, 100), rng.uniform(0.6, 1.4, 50)])
    vb = np.concatenate([rng.uniform(-0.05, 0.05, 100), rng.uniform(-0.6, 0.6, 50)])
    a = np.concatenate([np.full(100, 0.01), rng.uniform(0.02, 1.0, 50)])
    e = np.concatenate([np.zeros(100), rng.uniform(0, 1, 50)])
    return lm, vb, a, e


@pytest.fixture(scope="module")
def probe_run(example):
    probes = []
    for name, flags in UMB.items():
        base = dict(probe="Umberger2010", **dict(zip(SW, flags)))
        probes.append(dict(base, name=f"{name}_min", enforce_minimum_heat_rate_per_muscle=True))
        probes.append(dict(base, name=f"{name}_S1", aerobic_factor=1.0))
    probes.append(dict(BH, name="BH04_min", forbid_negative_total_power=True, enforce_minimum_heat_rate_per_muscle=True))
    probes.append(dict(BH, name="BH04_raw_min", forbid_negative_total_power=False,
                       enforce_minimum_heat_rate_per_muscle=True))
    return call("probes:evaluate_probes", *_states(), probes=probes, slow_twitch_fraction=FST, muscle_mass_kg=MASS,
                model_path=str(example.model), muscle_name="soleus_r")


def _inputs(r):
    return {**_opensim_inputs(r), "slow_twitch_fraction": FST}


def _probe(r, name):
    return r[f"{name}/{name}_TOTAL"]


def _agree(ours, theirs):
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-9)


@pytest.mark.opensim
@pytest.mark.parametrize("name", list(UMB))
def test_umberger_minimum_heat_rate_as_opensim(probe_run, name):
    inp = _inputs(probe_run)
    f = FUNCS[name]
    clamped = f(**inp, slow_twitch_shortening_cap=True, basal=False, minimum_heat_rate_W_per_kg=1.0)
    _agree(clamped.total, _probe(probe_run, f"{name}_min"))
    plain = f(**inp, slow_twitch_shortening_cap=True, basal=False)
    changed = np.abs(clamped.total - plain.total) > 1e-9
    assert changed.sum() >= 20  # the clamp acts at these states, so the comparison can fail
    # where it acts, the heat is exactly 1 W/kg of muscle mass and the work is untouched
    heat = clamped.activation_maintenance + clamped.shortening_lengthening
    low = plain.activation_maintenance + plain.shortening_lengthening < MASS
    if name == "UM10":  # no non-negativity rule: the heat is the floor itself
        np.testing.assert_allclose(heat[low], MASS, rtol=1e-15)
    np.testing.assert_array_equal(clamped.work, plain.work)
    assert np.all(clamped.total >= plain.total - 1e-12)


@pytest.mark.opensim
def test_bhargava_minimum_heat_rate_as_opensim(probe_run):
    inp = _inputs(probe_run)
    for probe, non_negative in (("BH04_min", True), ("BH04_raw_min", False)):
        ours = bhargava2004(**inp, activation_heat_decay=False, basal=False, non_negative=non_negative,
                            minimum_heat_rate_W_per_kg=1.0)
        _agree(ours.total, _probe(probe_run, probe))
        plain = bhargava2004(**inp, activation_heat_decay=False, basal=False, non_negative=non_negative)
        assert np.sum(np.abs(ours.total - plain.total) > 1e-9) >= 20
        np.testing.assert_array_equal(ours.work, plain.work)


@pytest.mark.opensim
@pytest.mark.parametrize("name", list(UMB))
def test_effort_scaling_as_opensims_aerobic_factor(probe_run, name):
    inp = _inputs(probe_run)
    f = FUNCS[name]
    s1 = f(**inp, slow_twitch_shortening_cap=True, basal=False, effort_scaling=ANAEROBIC_FACTOR)
    _agree(s1.total, _probe(probe_run, f"{name}_S1"))


def test_effort_scaling_scales_both_heats_only():
    # hand-worked: S multiplies H_AM and H_SL, nothing else (UM10 has no clamp to interfere)
    s = dict(excitation=0.6, activation=0.5, normalized_fiber_length=0.9, normalized_fiber_velocity=-0.2,
             active_force_length_multiplier=0.8, force_velocity_multiplier=0.4, passive_fiber_force_N=20.0,
             max_isometric_force_N=1000.0, optimal_fiber_length_m=0.05, max_contraction_velocity=10.0,
             muscle_mass_kg=0.5, slow_twitch_fraction=0.6)
    r15 = umberger2010(**s)
    r10 = umberger2010(**s, effort_scaling=1.0)
    # h_AM = (128*0.4 + 25) * 0.6^0.6 * S * 0.5
    assert float(r10.activation_maintenance) == pytest.approx(76.2 * 0.6**0.6 * 0.5, rel=1e-13)
    # h_SL = (25*2*0.6 + 15.3*2*0.4) * 0.6^2 * S * 0.5  (VCE~ = -2 lMo/s)
    assert float(r10.shortening_lengthening) == pytest.approx((30.0 + 12.24) * 0.36 * 0.5, rel=1e-13)
    assert float(r15.activation_maintenance) == pytest.approx(1.5 * float(r10.activation_maintenance), rel=1e-14)
    assert float(r15.shortening_lengthening) == pytest.approx(1.5 * float(r10.shortening_lengthening), rel=1e-14)
    assert float(r15.work) == float(r10.work) == pytest.approx(16.0, rel=1e-14)
    assert float(r15.basal) == float(r10.basal) == pytest.approx(0.6, rel=1e-14)
    with pytest.raises(OptionError, match="effort_scaling"):
        umberger2003(**s, effort_scaling=-1.0)
    with pytest.raises(OptionError, match="minimum_heat_rate_W_per_kg"):
        uchida2016(**s, minimum_heat_rate_W_per_kg="one")


def _recruited(e, f_st):
    u_s, u_f = np.sin(np.pi * e / 2), 1 - np.cos(np.pi * e / 2)
    return f_st * u_s / (f_st * u_s + (1 - f_st) * u_f)


def test_recruited_fiber_fractions_in_bh04_and_ho06():
    # e = 0.5: u_s = sin(pi/4), u_f = 1 - cos(pi/4); f_ST' = 0.6 u_s / (0.6 u_s + 0.4 u_f)
    e, a, lm, fl, fv, fst, m, f0 = 0.5, 0.4, 1.1, 0.9, 0.5, 0.6, 0.5, 1000.0
    s = dict(excitation=e, activation=a, normalized_fiber_length=lm, normalized_fiber_velocity=-0.1,
             active_force_length_multiplier=fl, force_velocity_multiplier=fv, passive_fiber_force_N=0.0,
             max_isometric_force_N=f0, optimal_fiber_length_m=0.05, max_contraction_velocity=10.0,
             muscle_mass_kg=m, slow_twitch_fraction=fst)
    u_s, u_f = np.sin(np.pi / 4), 1 - np.cos(np.pi / 4)
    fr = _recruited(e, fst)
    assert fr == pytest.approx(0.6 * u_s / (0.6 * u_s + 0.4 * u_f))
    bh = bhargava2004(**s, activation_heat_decay=False, fiber_fractions="recruited", basal=False)
    bh0 = bhargava2004(**s, activation_heat_decay=False, basal=False)
    assert float(bh.extras["activation"]) == pytest.approx(m * (133 * (1 - fr) * u_f + 40 * fr * u_s), rel=1e-12)
    assert float(bh.extras["maintenance"]) == pytest.approx(lm * m * (111 * (1 - fr) * u_f + 74 * fr * u_s), rel=1e-12)
    assert float(bh.work) == float(bh0.work) and float(bh.shortening_lengthening) == float(bh0.shortening_lengthening)
    ho = houdijk2006(**s, fiber_fractions="recruited", basal=False)
    ho0 = houdijk2006(**s, basal=False)
    h_a, h_m = 52.5 * (1 - fr) + 10.98 * fr, 97.5 * (1 - fr) + 13.42 * fr
    k3, k4 = 12 * (1 - fr) + 6 * fr, 14 * (1 - fr) + 8 * fr
    nu_max, nu_rel = k3 + k4 * a, a * a
    ratio = (1 - np.exp(-0.25 - 18.2 / (nu_rel * nu_max))) / (1 - np.exp(-0.25 - 18.2 / nu_max))
    assert float(ho.extras["activation"]) == pytest.approx(m * h_a * nu_rel * ratio, rel=1e-12)
    assert float(ho.extras["maintenance"]) == pytest.approx(m * (h_a + h_m) * a * (fl - h_a / (h_a + h_m)), rel=1e-12)
    a_tilde = (0.28 * (1 - fr) + 0.16 * fr) * f0
    assert float(ho.shortening_lengthening) == pytest.approx(-a_tilde * a * fl * (-0.05), rel=1e-12)
    assert float(ho.work) == float(ho0.work)
    # the recruited fraction differs from the muscle's here, so the option changes the heats
    assert abs(fr - fst) > 0.1 and abs(float(ho.total) - float(ho0.total)) > 1.0
    with pytest.raises(OptionError, match="fiber_fractions"):
        houdijk2006(**s, fiber_fractions="uchida")


def test_basal_exponent_as_opensim_writes_it():
    from musclemetab.metabolics import whole_body_rate

    t = np.array([0.0, 0.5, 1.0])
    leg = np.array([[10.0, 20.0, 30.0]])  # one muscle, mean 20 W over the cycle
    m = 80.0
    default = whole_body_rate(leg, t, m)
    assert default.mean_W_per_kg == pytest.approx(2 * 20.0 / m + 1.2, rel=1e-14)
    # basal_coefficient * m^basal_exponent W: 1.2 * 80^0.75 W = 32.098... W, per kg of body mass
    k = whole_body_rate(leg, t, m, basal_exponent=0.75)
    assert k.mean_W_per_kg == pytest.approx(2 * 20.0 / m + 1.2 * 80.0**0.75 / 80.0, rel=1e-14)
    assert k.mean_W_per_kg_no_basal == default.mean_W_per_kg_no_basal  # only the basal term changes
    np.testing.assert_array_equal(k.one_leg_W, default.one_leg_W)
    # the exponent belongs to the body rule only
    assert whole_body_rate(leg, t, m, basal="none", basal_exponent=0.75).mean_W_per_kg == pytest.approx(0.5)
    with pytest.raises(OptionError, match="basal_exponent"):
        whole_body_rate(leg, t, m, basal_exponent=float("nan"))

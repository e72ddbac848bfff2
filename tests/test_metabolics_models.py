"""The six metabolic energy models against values worked by hand from the equations.

Every expected value below is written as the arithmetic of the model's equations
(docs/metabolics.md, the reference's metabolic_models.md) with the numbers of the state,
independently of the implementation. Shared muscle: F0 = 1000 N, lMo = 0.05 m,
vmax = 10 lMo/s, m = 0.5 kg, f_ST = 0.6 (f_FT = 0.4). States give fL and fV directly
(the models take the multipliers as inputs), so round numbers can be used.
"""

from __future__ import annotations

import inspect
import math
import sys

import numpy as np
import pytest

from musclemetab.errors import DataMismatchError, OptionError
from musclemetab.metabolics import (
    MODELS,
    STUDY_MODELS,
    bhargava2004,
    bhargava_stimulation_time_s,
    compute_models,
    get_model,
    houdijk2006,
    lichtwark2007,
    parse_models,
    uchida2016,
    umberger2003,
    umberger2010,
)

F0, LMO, VMAX, MASS, FST = 1000.0, 0.05, 10.0, 0.5, 0.6
FFT = 1.0 - FST
PARAMS = dict(
    max_isometric_force_N=F0,
    optimal_fiber_length_m=LMO,
    max_contraction_velocity=VMAX,
    muscle_mass_kg=MASS,
    slow_twitch_fraction=FST,
)
BASAL = 1.2 * 0.5  # 1.2 W/kg of muscle mass


def state(e, a, lm, vbar, fl, fv, fpe=0.0):
    return dict(
        excitation=e,
        activation=a,
        normalized_fiber_length=lm,
        normalized_fiber_velocity=vbar,
        active_force_length_multiplier=fl,
        force_velocity_multiplier=fv,
        passive_fiber_force_N=fpe,
        **PARAMS,
    )


# Shortening state used by several models: e = 0.6 > a = 0.5, l~M = 0.9, vbar = -0.2
# (VCE~ = -2 lMo/s, V_CE = -0.1 m/s), fL = 0.8, fV = 0.4, passive force 20 N.
SHORT = state(0.6, 0.5, 0.9, -0.2, 0.8, 0.4, 20.0)
# F_CE = 0.5 * 0.8 * 0.4 * 1000 = 160 N; W_CE = -160 * (-0.1) = 16 W
W_SHORT = 16.0


# ----------------------------------------------------------------------------- Umberger family
# h_AM = 128 f_FT + 25 = 128*0.4 + 25 = 76.2 W/kg; S m = 1.5 * 0.5 = 0.75 kg
# alpha_S_ST = 100 / (10/2.5) = 25, alpha_S_FT = 153/10 = 15.3, alpha_L = 100 (UM03) / 7.5 (UM10)


def test_um03_shortening_below_optimal_length():
    r = umberger2003(**SHORT)
    h_am = 76.2 * 0.6**0.6 * 0.75  # A = e = 0.6 (e > a)
    # h_SL = -(25*(-2)*0.6 + 15.3*(-2)*0.4) * A^2 = (30 + 12.24) * 0.36 = 15.2064 W/kg
    h_sl = 15.2064 * 0.75
    assert r.work == pytest.approx(16.0, rel=1e-12)
    assert r.activation_maintenance == pytest.approx(h_am, rel=1e-12)
    assert r.shortening_lengthening == pytest.approx(h_sl, rel=1e-12)
    assert r.basal == pytest.approx(0.6, rel=1e-12)
    assert r.total == pytest.approx(16.0 + h_am + h_sl + 0.6, rel=1e-12)


def test_um03_shortening_above_optimal_length():
    # l~M = 1.2 > 1: H_AM x (0.4 + 0.6 fL), H_SL x fL, with fL = 0.7; F_CE = 0.5*0.7*0.4*1000 = 140 N
    r = umberger2003(**state(0.6, 0.5, 1.2, -0.2, 0.7, 0.4))
    h_am = 76.2 * 0.6**0.6 * 0.75 * (0.4 + 0.6 * 0.7)
    h_sl = 15.2064 * 0.75 * 0.7
    assert r.activation_maintenance == pytest.approx(h_am, rel=1e-12)
    assert r.shortening_lengthening == pytest.approx(h_sl, rel=1e-12)
    assert r.total == pytest.approx(140 * 0.1 + h_am + h_sl + BASAL, rel=1e-12)


def test_um03_isometric_and_length_boundary():
    # vbar = 0: shortening branch with VCE~ = 0: no shortening heat, no work.
    # e = 0.3 < a = 0.5: A = (0.3 + 0.5)/2 = 0.4. At l~M = 1 exactly the l <= 1 branch
    # holds (no length factor even with fL = 0.5); just above 1 the factor applies.
    at_one = umberger2003(**state(0.3, 0.5, 1.0, 0.0, 0.5, 1.0))
    assert at_one.work == 0.0 and at_one.shortening_lengthening == 0.0
    assert at_one.activation_maintenance == pytest.approx(76.2 * 0.4**0.6 * 0.75, rel=1e-12)
    assert at_one.total == pytest.approx(76.2 * 0.4**0.6 * 0.75 + BASAL, rel=1e-12)
    above = umberger2003(**state(0.3, 0.5, 1.0 + 1e-9, 0.0, 0.5, 1.0))
    assert above.activation_maintenance == pytest.approx(76.2 * 0.4**0.6 * 0.75 * (0.4 + 0.6 * 0.5), rel=1e-12)


def test_um03_slow_lengthening_is_positive():
    # vbar = 0.1: VCE~ = 1 lMo/s, V = 0.05 m/s; e = 0.3 < a = 0.5 -> A = 0.4; fL = 1, fV = 1.3
    # h_SL = alpha_L VCE~ A = 100 * 1 * 0.4 = 40 W/kg -> 30 W; F_CE = 0.5*1*1.3*1000 = 650 N,
    # W = -650 * 0.05 = -32.5 W; H_AM = 76.2 * 0.4^0.6 * 0.75 = 32.98 W; sum 30.48 > 0: no clamp
    r = umberger2003(**state(0.3, 0.5, 1.0, 0.1, 1.0, 1.3))
    h_am = 76.2 * 0.4**0.6 * 0.75
    assert r.work == pytest.approx(-32.5, rel=1e-12)
    assert r.shortening_lengthening == pytest.approx(30.0, rel=1e-12)
    assert r.total == pytest.approx(-32.5 + h_am + 30.0 + BASAL, rel=1e-12)


def test_um03_fast_lengthening_is_clamped_to_zero():
    # vbar = 0.5: VCE~ = 5, V = 0.25 m/s; h_SL = 100*5*0.4 = 200 W/kg -> 150 W; F_CE = 750 N,
    # W = -187.5 W; W + H_AM + H_SL = -187.5 + 32.98 + 150 < 0 -> H_SL := 187.5 - H_AM
    r = umberger2003(**state(0.3, 0.5, 1.0, 0.5, 1.0, 1.5))
    h_am = 76.2 * 0.4**0.6 * 0.75
    assert -187.5 + h_am + 150.0 < 0
    assert r.shortening_lengthening == pytest.approx(187.5 - h_am, rel=1e-12)
    assert r.total == pytest.approx(BASAL, abs=1e-12)  # zero before the basal heat is added
    off = umberger2003(**state(0.3, 0.5, 1.0, 0.5, 1.0, 1.5), non_negative=False, basal=False)
    assert off.total == pytest.approx(-187.5 + h_am + 150.0, rel=1e-12)


def test_um10_differs_from_um03_in_lengthening_only():
    # same slow-lengthening state: alpha_L = 0.3*25 = 7.5 -> h_SL = 7.5*1*0.4 = 3 W/kg -> 2.25 W;
    # only concentric work counts: W = 0
    r = umberger2010(**state(0.3, 0.5, 1.0, 0.1, 1.0, 1.3))
    h_am = 76.2 * 0.4**0.6 * 0.75
    assert r.work == 0.0
    assert r.shortening_lengthening == pytest.approx(2.25, rel=1e-12)
    assert r.total == pytest.approx(h_am + 2.25 + BASAL, rel=1e-12)
    # fast lengthening: no non-negativity rule in UM10, the rate stays positive (heat only)
    fast = umberger2010(**state(0.3, 0.5, 1.0, 0.5, 1.0, 1.5), basal=False)
    assert fast.total == pytest.approx(h_am + 7.5 * 5 * 0.4 * 0.75, rel=1e-12)
    # shortening: identical to UM03
    a, b = umberger2010(**SHORT), umberger2003(**SHORT)
    assert a.total == pytest.approx(b.total, rel=1e-15)


def test_slow_twitch_cap_option():
    # vbar = -0.6: VCE~ = -6 < -vmax_ST = -4: the capped slow-twitch term uses -4.
    # e = a = 1 -> A = 1 (e <= a: (1+1)/2). fL = 1, fV = 0.2, l~M = 1.
    s = state(1.0, 1.0, 1.0, -0.6, 1.0, 0.2)
    h_sl_uncapped = (25 * 6 * 0.6 + 15.3 * 6 * 0.4) * 0.75  # (90 + 36.72) W/kg
    h_sl_capped = (25 * 4 * 0.6 + 15.3 * 6 * 0.4) * 0.75  # (60 + 36.72) W/kg
    assert umberger2003(**s).shortening_lengthening == pytest.approx(h_sl_uncapped, rel=1e-12)
    assert umberger2003(**s, slow_twitch_shortening_cap=True).shortening_lengthening == pytest.approx(
        h_sl_capped, rel=1e-12
    )
    # below the cap the option changes nothing
    assert umberger2003(**SHORT, slow_twitch_shortening_cap=True).total == umberger2003(**SHORT).total


def test_uc16_recruited_fractions():
    # e = 0.6: u_s = sin(0.3 pi), u_f = 1 - cos(0.3 pi); f_ST' = 0.6 u_s / (0.6 u_s + 0.4 u_f)
    u_s, u_f = math.sin(0.3 * math.pi), 1 - math.cos(0.3 * math.pi)
    fst = 0.6 * u_s / (0.6 * u_s + 0.4 * u_f)  # = 0.7464...
    assert fst == pytest.approx(0.74645, abs=1e-5)
    r = uchida2016(**SHORT)
    h_am = (128 * (1 - fst) + 25) * 0.6**0.6 * 0.75
    h_sl = (25 * 2 * fst + 15.3 * 2 * (1 - fst)) * 0.36 * 0.75
    assert r.activation_maintenance == pytest.approx(h_am, rel=1e-12)
    assert r.shortening_lengthening == pytest.approx(h_sl, rel=1e-12)
    assert r.total == pytest.approx(16 + h_am + h_sl + BASAL, rel=1e-12)


def test_uc16_zero_excitation_takes_all_slow_twitch():
    # e = 0: f_ST' = 1 -> h_AM = 25 W/kg; a = 0.4 > e -> A = 0.2; isometric
    r = uchida2016(**state(0.0, 0.4, 1.0, 0.0, 1.0, 1.0), basal=False)
    assert r.total == pytest.approx(25 * 0.2**0.6 * 0.75, rel=1e-12)


def test_uc16_uses_um03_lengthening_and_is_clamped():
    # fast lengthening as in the UM03 test, e = 0.3: f_ST' changes only H_AM here
    u_s, u_f = math.sin(0.15 * math.pi), 1 - math.cos(0.15 * math.pi)
    fst = 0.6 * u_s / (0.6 * u_s + 0.4 * u_f)
    h_am = (128 * (1 - fst) + 25) * 0.4**0.6 * 0.75
    r = uchida2016(**state(0.3, 0.5, 1.0, 0.5, 1.0, 1.5))
    assert -187.5 + h_am + 150 < 0
    assert r.shortening_lengthening == pytest.approx(187.5 - h_am, rel=1e-12)
    assert r.total == pytest.approx(BASAL, abs=1e-12)
    slow = uchida2016(**state(0.3, 0.5, 1.0, 0.1, 1.0, 1.3), basal=False)
    assert slow.total == pytest.approx(-32.5 + h_am + 30.0, rel=1e-12)


# ----------------------------------------------------------------------------- BH04
def _bh_terms(e):
    u_s, u_f = math.sin(math.pi * e / 2), 1 - math.cos(math.pi * e / 2)
    act = 0.5 * (133 * 0.4 * u_f + 40 * 0.6 * u_s)  # m (A_f f_FT u_f + A_s f_ST u_s)
    main = 0.5 * (111 * 0.4 * u_f + 74 * 0.6 * u_s)  # m (M_f f_FT u_f + M_s f_ST u_s)
    return act, main


def test_bh04_shortening():
    # t_stim = 0.05 s: phi = 0.06 + exp(-0.05*0.6/0.045)
    act, main = _bh_terms(0.6)
    phi = 0.06 + math.exp(-0.05 * 0.6 / 0.045)
    # F_iso = 1000*0.5*0.8 = 400 N; F_M = 400*0.4 + 20 = 180 N;
    # alpha = 0.16*400 + 0.18*180 = 96.4 N; H_SL = -96.4 * (-0.1) = 9.64 W
    r = bhargava2004(**SHORT, stimulation_time_s=0.05)
    assert r.extras["activation"] == pytest.approx(phi * act, rel=1e-12)
    assert r.extras["maintenance"] == pytest.approx(0.9 * main, rel=1e-12)  # g(l~M) = l~M = 0.9
    assert r.shortening_lengthening == pytest.approx(9.64, rel=1e-12)
    assert r.work == pytest.approx(16.0, rel=1e-12)
    assert r.total == pytest.approx(16 + phi * act + 0.9 * main + 9.64 + BASAL, rel=1e-12)


def test_bh04_lengthening_above_optimal_length():
    # l~M = 1.3 (maintenance x 1.3 in the study's code), vbar = 0.1 (V = 0.05 m/s), fL = 0.6,
    # fV = 1.3, F_pe = 100 N; e = 0.5, a = 0.8; F_CE = 0.8*0.6*1.3*1000 = 624 N;
    # F_M = 724 N; H_SL = -0.157*724*0.05 = -5.6834 W; W = -624*0.05 = -31.2 W; no decay
    act, main = _bh_terms(0.5)
    r = bhargava2004(**state(0.5, 0.8, 1.3, 0.1, 0.6, 1.3, 100.0), activation_heat_decay=False)
    assert r.shortening_lengthening == pytest.approx(-0.157 * 724 * 0.05, rel=1e-12)
    assert r.work == pytest.approx(-31.2, rel=1e-12)
    total = -31.2 + act + 1.3 * main - 5.6834
    assert total > 0
    assert r.total == pytest.approx(total + BASAL, rel=1e-12)
    pub = bhargava2004(
        **state(0.5, 0.8, 1.3, 0.1, 0.6, 1.3, 100.0), activation_heat_decay=False,
        maintenance_length_dependence="published",
    )
    assert pub.extras["maintenance"] == pytest.approx((-2 * 1.3 + 3) * main, rel=1e-12)  # 0.4 main


def test_bh04_published_length_factor_branches():
    _, main = _bh_terms(0.5)
    for lm, g in ((0.4, 0.5), (0.5, 0.5), (0.75, 0.75), (1.0, 1.0), (1.25, 0.5), (1.5, 0.0), (1.8, 0.0)):
        r = bhargava2004(**state(0.5, 0.5, lm, 0.0, 1.0, 1.0), activation_heat_decay=False,
                         maintenance_length_dependence="published")
        assert r.extras["maintenance"] == pytest.approx(g * main, rel=1e-12, abs=1e-15), lm


def test_bh04_non_negativity_at_fast_lengthening():
    # vbar = 0.8 (V = 0.4 m/s), a = e = 1, fL = 1, fV = 1.7: W = -1700*0.4 = -680 W dominates
    act, main = _bh_terms(1.0)
    r = bhargava2004(**state(1.0, 1.0, 1.0, 0.8, 1.0, 1.7), activation_heat_decay=False, basal=False)
    assert -680 + act + main - 0.157 * 1700 * 0.4 < 0
    assert r.total == pytest.approx(0.0, abs=1e-12)
    assert r.shortening_lengthening == pytest.approx(680 - act - main, rel=1e-12)


def test_bh04_stimulation_counter_and_threshold():
    # threshold 0.1 (strict): counts 0,1,2,0,1,2; dt_mean = 0.05/5 = 0.01 s
    e = np.array([0.05, 0.2, 0.3, 0.1, 0.5, 0.5])
    t = np.array([0.0, 0.01, 0.02, 0.03, 0.04, 0.05])
    np.testing.assert_allclose(bhargava_stimulation_time_s(e, t), [0, 0.01, 0.02, 0, 0.01, 0.02], rtol=1e-12)
    # non-uniform time: dt_mean = (0.04 - 0)/3
    np.testing.assert_allclose(
        bhargava_stimulation_time_s([0.5, 0.5, 0.5, 0.5], [0, 0.01, 0.03, 0.04]), np.arange(1, 5) * 0.04 / 3
    )
    # per-muscle rows count independently
    rows = bhargava_stimulation_time_s(np.array([[0.5, 0.5, 0.0], [0.0, 0.5, 0.5]]), [0, 1, 2])
    np.testing.assert_allclose(rows, [[1, 2, 0], [0, 1, 2]])
    # no activation heat at e <= 0.1 (t_stim = 0), even with time given
    s = {**state(0.1, 0.3, 1.0, 0.0, 1.0, 1.0), "excitation": np.array([0.1, 0.6])}
    r = bhargava2004(**s, time_s=[0.0, 0.01])
    act, _ = _bh_terms(0.6)
    assert r.extras["activation"][0] == 0.0
    assert r.extras["activation"][1] == pytest.approx(act * (0.06 + math.exp(-0.01 * 0.6 / 0.045)), rel=1e-12)


def test_bh04_needs_time():
    with pytest.raises(OptionError, match="time_s"):
        bhargava2004(**SHORT)
    with pytest.raises(DataMismatchError, match="time_s"):
        bhargava2004(**{**SHORT, "excitation": np.full(3, 0.5)}, time_s=[0.0, 0.1])


# ----------------------------------------------------------------------------- HO06
# h_A = 52.5*0.4 + 10.98*0.6 = 27.588 W/kg, h_M = 97.5*0.4 + 13.42*0.6 = 47.052 W/kg,
# k3 = 12*0.4 + 6*0.6 = 8.4, k4 = 14*0.4 + 8*0.6 = 10.4, a~ = (0.28*0.4 + 0.16*0.6)*1000 = 208 N
def _ho_activation(a):
    nu_max = 8.4 + 10.4 * a
    nu_rel = a * a
    return 0.5 * 27.588 * nu_rel * (1 - math.exp(-0.25 - 18.2 / (nu_rel * nu_max))) / (
        1 - math.exp(-0.25 - 18.2 / nu_max)
    )


def test_ho06_shortening():
    h_a = _ho_activation(0.5)
    h_m = 0.5 * (27.588 + 47.052) * 0.5 * (0.8 - 27.588 / (27.588 + 47.052))
    h_sl = -208 * 0.5 * 0.8 * (-0.1)  # 8.32 W
    r = houdijk2006(**SHORT)
    assert r.extras["activation"] == pytest.approx(h_a, rel=1e-12)
    assert r.extras["maintenance"] == pytest.approx(h_m, rel=1e-12)
    assert r.shortening_lengthening == pytest.approx(8.32, rel=1e-12)
    assert r.total == pytest.approx(16 + h_a + h_m + h_sl + BASAL, rel=1e-12)


def test_ho06_negative_maintenance_far_from_optimum():
    # fL = 0.2 < h_A/(h_A + h_M) = 0.3696: maintenance heat negative; isometric, l~M = 1.5
    r = houdijk2006(**state(0.6, 0.5, 1.5, 0.0, 0.2, 1.0), non_negative=False)
    h_m = 0.5 * 74.64 * 0.5 * (0.2 - 27.588 / 74.64)
    assert h_m < 0
    assert r.extras["maintenance"] == pytest.approx(h_m, rel=1e-12)


def test_ho06_lengthening_has_no_heat_and_is_clamped():
    # vbar = 0.1: H_SL = 0 before the rule; W = -(0.5*1*1.3*1000)*0.05 = -32.5 W
    h_a = _ho_activation(0.5)
    h_m = 0.5 * 74.64 * 0.5 * (1.0 - 27.588 / 74.64)
    r_off = houdijk2006(**state(0.3, 0.5, 1.0, 0.1, 1.0, 1.3), non_negative=False, basal=False)
    assert r_off.shortening_lengthening == 0.0
    assert r_off.total == pytest.approx(-32.5 + h_a + h_m, rel=1e-12)
    assert -32.5 + h_a + h_m < 0
    r = houdijk2006(**state(0.3, 0.5, 1.0, 0.1, 1.0, 1.3), basal=False)
    assert r.total == pytest.approx(0.0, abs=1e-12)


def test_ho06_zero_activation():
    r = houdijk2006(**state(0.3, 0.0, 1.0, -0.2, 1.0, 0.5), basal=False)
    assert r.extras["activation"] == 0.0 and r.total == 0.0
    assert np.isfinite(r.total)


# ----------------------------------------------------------------------------- LW07
# N0 = F0 lMo = 50 N m; gamma vmax / G^2 = 1.5*10/16 = 0.9375 1/s; X = a fL


def test_lw07_shortening():
    # fV = 0.4 < 1: h_M = 0.9375; H_M = (0.3*0.5 + 0.7*0.4)*0.9375*50 = 0.43*46.875
    # H_SL = -VCE~/G X N0 = 2/4 * 0.4 * 50 = 10 W
    r = lichtwark2007(**SHORT)
    assert r.activation_maintenance == pytest.approx(0.43 * 46.875, rel=1e-12)
    assert r.shortening_lengthening == pytest.approx(10.0, rel=1e-12)
    assert r.total == pytest.approx(16 + 20.15625 + 10 + BASAL, rel=1e-12)


def test_lw07_lengthening_returns_half_the_work():
    # vbar = 0.1 (VCE~ = 1), a = 0.5, fL = 0.8 (X = 0.4), fV = 1.3:
    # h_M = 0.9375*(0.3 + 0.7*exp(-7*10*0.3)); H_SL = 0.5*1.3*1*0.4*50 = 13 W;
    # W = -(0.4*1.3*1000)*0.05 = -26 W = -2 H_SL
    r = lichtwark2007(**state(0.6, 0.5, 1.2, 0.1, 0.8, 1.3))
    h_m = 0.43 * 0.9375 * (0.3 + 0.7 * math.exp(-21.0)) * 50
    assert r.work == pytest.approx(-26.0, rel=1e-12)
    assert r.shortening_lengthening == pytest.approx(13.0, rel=1e-12)
    assert r.activation_maintenance == pytest.approx(h_m, rel=1e-12)
    assert r.total == pytest.approx(-26 + 13 + h_m + BASAL, rel=1e-12)  # negative: no clamp
    assert r.total < 0


def test_lw07_branch_on_force_velocity_multiplier():
    # isometric with fV(0) = 1.0021: the fV >= 1 branch, h_M = 0.9375 (0.3 + 0.7 exp(-70*0.0021))
    iso = lichtwark2007(**state(0.5, 0.5, 1.0, 0.0, 1.0, 1.0021), basal=False)
    h_m = (0.3 * 0.5 + 0.7 * 0.5) * 0.9375 * (0.3 + 0.7 * math.exp(-70 * 0.0021)) * 50
    assert iso.total == pytest.approx(h_m, rel=1e-12)
    assert iso.total / (0.5 * 0.9375 * 50) == pytest.approx(0.904, abs=1e-3)  # about 10 % lower
    # fV = 1 exactly is in the lengthening branch (exp(0) = 1: continuous); just below, the other
    at_one = lichtwark2007(**state(0.5, 0.5, 1.0, 0.0, 1.0, 1.0), basal=False)
    below = lichtwark2007(**state(0.5, 0.5, 1.0, 0.0, 1.0, 1.0 - 1e-12), basal=False)
    assert at_one.total == pytest.approx(0.5 * 0.9375 * 50, rel=1e-12)
    assert below.total == pytest.approx(0.5 * 0.9375 * 50, rel=1e-12)


# ----------------------------------------------------------------------------- shared rules
def test_branch_boundary_velocity_zero_is_shortening_everywhere():
    # V_CE = 0 belongs to the shortening branch (<= 0): A_S = A^2 but VCE~ = 0 -> no heat;
    # BH04 alpha uses the shortening coefficient but V = 0 -> 0; no work anywhere
    s = state(0.6, 0.5, 1.0, 0.0, 1.0, 1.0)
    for name, f in MODELS.items():
        r = f(**s, stimulation_time_s=0.1) if name == "BH04" else f(**s)
        assert r.work == 0.0, name
        assert r.shortening_lengthening == 0.0, name


def test_shared_signature_and_registry():
    first = None
    for name, f in MODELS.items():
        params = list(inspect.signature(f).parameters)[:12]
        first = first or params
        assert params == first, name
        assert f.model_name == name
        assert "Reference" in f.__doc__ and "excitation" in f.__doc__
    assert list(MODELS) == list(STUDY_MODELS) == ["UM03", "BH04", "HO06", "LW07", "UM10", "UC16"]
    assert parse_models("all") == list(STUDY_MODELS)
    assert parse_models("um10, BH04,UM10") == ["UM10", "BH04"]
    with pytest.raises(OptionError, match="known models: UM03, BH04, HO06, LW07, UM10, UC16"):
        get_model("UM11")
    # the additional models are known by name but never in the study's default set
    assert parse_models("LW05,all,MA68") == ["LW05", *STUDY_MODELS, "MA68"]
    assert get_model("lw05").model_name == "LW05" and get_model("MA68").model_name == "MA68"


def test_arrays_muscles_by_time_match_scalar_evaluation():
    rng = np.random.default_rng(7)
    m, t = 3, 50
    s = dict(
        excitation=rng.uniform(0, 1, (m, t)),
        activation=rng.uniform(0, 1, (m, t)),
        normalized_fiber_length=rng.uniform(0.5, 1.5, (m, t)),
        normalized_fiber_velocity=rng.uniform(-1, 1, (m, t)),
        active_force_length_multiplier=rng.uniform(0, 1, (m, t)),
        force_velocity_multiplier=rng.uniform(0, 1.8, (m, t)),
        passive_fiber_force_N=rng.uniform(0, 50, (m, t)),
        max_isometric_force_N=np.array([1000.0, 2000.0, 3000.0]),
        optimal_fiber_length_m=np.array([0.05, 0.1, 0.08]),
        max_contraction_velocity=np.full(3, 10.0),
        muscle_mass_kg=np.array([0.5, 0.2, 0.3]),
        slow_twitch_fraction=np.array([0.6, 0.5, 0.8]),
    )
    time = np.linspace(0, 0.49, t)
    rates = compute_models("all", s, time_s=time)
    t_stim = bhargava_stimulation_time_s(s["excitation"], time)
    for name, r in rates.items():
        assert r.total.shape == (m, t)
        for i, k in ((0, 0), (1, 17), (2, 49)):
            one = {key: (v[i, k] if np.ndim(v) == 2 else v[i]) for key, v in s.items()}
            extra = {"stimulation_time_s": t_stim[i, k]} if name == "BH04" else {}
            single = MODELS[name](**one, **extra)
            for c in ("work", "activation_maintenance", "shortening_lengthening", "basal", "total"):
                assert getattr(r, c)[i, k] == pytest.approx(float(getattr(single, c)), rel=1e-12, abs=1e-12), (name, c)
        np.testing.assert_allclose(
            r.total, r.work + r.activation_maintenance + r.shortening_lengthening + r.basal, rtol=1e-12, atol=1e-9
        )


def test_bad_input_errors():
    with pytest.raises(DataMismatchError, match="compatible shapes"):
        umberger2003(**{**SHORT, "activation": np.ones(3), "excitation": np.ones(4)})
    with pytest.raises(DataMismatchError, match="max_isometric_force_N"):
        umberger2003(**{**SHORT, "activation": np.ones((2, 5)), "max_isometric_force_N": np.ones(3)})
    with pytest.raises(OptionError, match="normalized_fiber_velocity.*NaN"):
        houdijk2006(**{**SHORT, "normalized_fiber_velocity": np.array([0.1, np.nan])})
    with pytest.raises(OptionError, match="slow_twitch_fraction"):
        lichtwark2007(**{**SHORT, "slow_twitch_fraction": 1.5})
    with pytest.raises(OptionError, match="muscle_mass_kg"):
        umberger2010(**{**SHORT, "muscle_mass_kg": -1.0})
    with pytest.raises(OptionError, match="maintenance_length_dependence"):
        bhargava2004(**SHORT, stimulation_time_s=0.1, maintenance_length_dependence="piecewise")
    with pytest.raises(OptionError, match="non_negative"):
        umberger2003(**SHORT, non_negative="yes")
    with pytest.raises(OptionError, match="UC16.*invalid option"):
        compute_models("UC16", SHORT, options={"UC16": {"activation_heat_decay": False}})


def test_parameters_align_with_leading_axes():
    # (M,) parameters against (M, T) states with M == T: never matched to the time axis
    s = {k: np.full((2, 2), v) if k in ("excitation", "activation") else v for k, v in SHORT.items()}
    s["muscle_mass_kg"] = np.array([0.5, 1.0])
    r = umberger2003(**s)
    np.testing.assert_allclose(r.basal, [[0.6, 0.6], [1.2, 1.2]])


def test_import_does_not_load_opensim_or_casadi():
    import subprocess

    code = "import sys, musclemetab.metabolics; print('opensim' in sys.modules, 'casadi' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]

"""LW05 (Lichtwark & Wilson 2005, as docs/metabolics.md makes it definite) and MA68
(Margaria 1968) against values worked by hand from their equations, and their place beside
the study's six models (registry, CLI, Figure 2).

Shared muscle: F0 = 1000 N, lMo = 0.05 m, vmax = 10 lMo/s (N0 = F0 lMo = 50 N m,
vmax/G^2 N0 = 10/16 * 50 = 31.25 W), m = 0.5 kg, f_ST = 0.6.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from musclemetab.errors import OptionError
from musclemetab.metabolics import STUDY_MODELS, compute_models, lichtwark2005, margaria1968
from musclemetab.metabolics.lichtwark import loess_smooth

F0, LMO, VMAX, MASS = 1000.0, 0.05, 10.0, 0.5
N0 = F0 * LMO
H_ISO = VMAX / 16.0 * N0  # 31.25 W at a = 1


def state(e, a, vbar, fl=1.0, fv=1.0, lm=1.0):
    return dict(excitation=e, activation=a, normalized_fiber_length=lm, normalized_fiber_velocity=vbar,
                active_force_length_multiplier=fl, force_velocity_multiplier=fv, passive_fiber_force_N=0.0,
                max_isometric_force_N=F0, optimal_fiber_length_m=LMO, max_contraction_velocity=VMAX,
                muscle_mass_kg=MASS, slow_twitch_fraction=0.6)


def lw05(s, t_stim, rate=0.0, **kw):
    return lichtwark2005(**s, stimulation_time_s=t_stim, fiber_force_rate_N_per_s=rate, **kw)


# ----------------------------------------------------------------------------- LW05
def test_lw05_isometric_at_stimulation_onset_is_1975_vmax_over_g2():
    r = lw05(state(1.0, 1.0, 0.0), 0.0, basal=False)
    # h_M + h_L = h_M (1 + 0.8 + 0.175) with h_M = a vmax/G^2 N0
    assert float(r.total) == pytest.approx(1.975 * VMAX / 4.0**2 * F0 * LMO, rel=1e-14)
    assert float(r.total) == pytest.approx(61.71875, rel=1e-14)
    assert float(r.work) == 0.0 and float(r.extras["labile"]) == pytest.approx(0.975 * H_ISO, rel=1e-14)


def test_lw05_after_long_stimulation_only_stable_maintenance():
    r = lw05(state(1.0, 1.0, 0.0), 1e4, basal=False)
    assert float(r.total) == pytest.approx(H_ISO, rel=1e-12)
    # labile heat at t_stim = 2 s: 0.8 e^-1.44 + 0.175 e^-0.044 of h_M, times a = 0.4
    r2 = lw05(state(1.0, 0.4, 0.0), 2.0, basal=False)
    assert float(r2.extras["labile"]) == pytest.approx(0.4 * H_ISO * (0.8 * math.exp(-1.44) + 0.175 * math.exp(-0.044)))


def test_lw05_lengthening_at_fv_one_is_stable_maintenance():
    # lengthening (vbar = +0.2, V = -0.1 m/s) with fV = 1: heat h_M (0.3 + 0.7), no labile or shortening heat
    r = lw05(state(1.0, 0.5, 0.2, fv=1.0), 0.3, basal=False)
    assert float(r.activation_maintenance) == pytest.approx(0.5 * H_ISO, rel=1e-14)
    assert float(r.shortening_lengthening) == 0.0 and float(r.extras["labile"]) == 0.0
    # the work is counted once: W_CE = F_CE V = 0.5 * 1000 * (-0.1) = -50 W
    assert float(r.work) == pytest.approx(-50.0, rel=1e-14)
    assert float(r.total) == pytest.approx(0.5 * H_ISO - 50.0, rel=1e-14)
    # fV = 1.3: heat h_M (0.3 + 0.7 exp(-8 * 0.3)); W_CE = -0.5 * 1.3 * 1000 * 0.1 = -65 W
    r = lw05(state(1.0, 0.5, 0.2, fv=1.3), 0.3, basal=False)
    heat = 0.5 * H_ISO * (0.3 + 0.7 * math.exp(-2.4))
    assert float(r.total) == pytest.approx(heat - 65.0, rel=1e-14)


def test_lw05_shortening_with_thermoelastic_heat():
    # a = 0.5, vbar = -0.2: V = 0.1 m/s; fL = 0.8, fV = 0.4: F_CE = 160 N, W_CE = 16 W
    s = state(0.6, 0.5, -0.2, fl=0.8, fv=0.4, lm=0.9)
    r = lw05(s, 0.1, rate=100.0)
    h_m = 0.5 * H_ISO  # 15.625 W (no length dependence)
    h_l = h_m * (0.8 * math.exp(-0.072) + 0.175 * math.exp(-0.0022))
    h_s = 0.5 * (0.1 / 0.05) / 4.0 * N0  # 12.5 W
    h_t = -0.014 * 100.0 * 0.05  # -0.07 W
    assert float(r.work) == pytest.approx(16.0, rel=1e-14)
    assert float(r.activation_maintenance) == pytest.approx(h_m + h_l, rel=1e-14)
    assert float(r.shortening_lengthening) == pytest.approx(h_s + h_t, rel=1e-14)
    assert float(r.extras["thermoelastic"]) == pytest.approx(h_t, rel=1e-14)
    assert float(r.total) == pytest.approx(16.0 + h_m + h_l + h_s + h_t + 1.2 * MASS, rel=1e-14)


def test_lw05_counts_stimulation_and_force_rate_from_time():
    # e above 0.1 at samples 1, 2, 4 (counter 0, 1, 2, 0, 1 times dt = 0.01 s);
    # F_CE = a F0 with a = 0.2 + 5 t: dF/dt = 5000 N/s everywhere (central differences of a line)
    t = 0.5 + 0.01 * np.arange(5)
    e = np.array([0.05, 0.2, 0.3, 0.1, 0.5])
    a = 0.2 + 5.0 * (t - 0.5)
    r = lichtwark2005(**state(e, a, 0.0), time_s=t, basal=False)
    t_stim = np.array([0, 1, 2, 0, 1]) * 0.01
    np.testing.assert_allclose(r.extras["thermoelastic"], -0.014 * 5000.0 * 0.05, rtol=1e-12)
    h_m = a * H_ISO
    np.testing.assert_allclose(r.extras["labile"], h_m * (0.8 * np.exp(-0.72 * t_stim) + 0.175 * np.exp(-0.022 * t_stim)),
                               rtol=1e-14)
    with pytest.raises(OptionError, match="time_s.*stimulation_time_s"):
        lichtwark2005(**state(e, a, 0.0))
    with pytest.raises(OptionError, match="time_s.*fiber_force_rate_N_per_s"):
        lichtwark2005(**state(e, a, 0.0), stimulation_time_s=0.0)
    with pytest.raises(OptionError, match="force_smoothing_span"):
        lichtwark2005(**state(e, a, 0.0), time_s=t, force_smoothing_span=2.0)


def test_loess_smoothing_is_exact_on_quadratics_and_reduces_noise():
    x = np.linspace(0.0, 1.0, 101)
    y = 3.0 - 2.0 * x + 5.0 * x**2
    np.testing.assert_allclose(loess_smooth(x, y, 0.1), y, rtol=0, atol=1e-10)
    rng = np.random.default_rng(2)
    truth = np.sin(2 * np.pi * x)
    noisy = truth + rng.normal(0, 0.05, x.size)
    smooth = loess_smooth(x, noisy, 0.1)
    assert np.sqrt(np.mean((smooth - truth) ** 2)) < 0.6 * np.sqrt(np.mean((noisy - truth) ** 2))
    # the option smooths F_CE before differentiating: on a quadratic force the rate is unchanged
    t = 0.01 * np.arange(40)
    a = 0.3 + 0.4 * t**2
    s = state(np.full(40, 0.5), a, 0.0)
    plain = lichtwark2005(**s, time_s=t)
    smoothed = lichtwark2005(**s, time_s=t, force_smoothing_span=0.2)
    np.testing.assert_allclose(smoothed.extras["thermoelastic"], plain.extras["thermoelastic"], rtol=1e-8, atol=1e-12)


# ----------------------------------------------------------------------------- MA68
def test_ma68_efficiencies_of_margaria_1968():
    # Margaria (1968): positive work at an efficiency W/E of 25 %, negative work at -120 %
    # shortening: a = 1, vbar = -0.2 -> V_CE = -0.1 m/s, F_CE = 1000 N, W_CE = +100 W -> 100 / 0.25 = 400 W
    r = margaria1968(**state(0.3, 1.0, -0.2), basal=False)
    assert float(r.work) == pytest.approx(100.0, rel=1e-14)
    assert float(r.total) == pytest.approx(400.0, rel=1e-14)
    assert float(r.shortening_lengthening) == pytest.approx(300.0, rel=1e-14)  # Edot - W_CE
    # lengthening: a = 1, fV = 1, vbar = +0.2 -> W_CE = -100 W -> -100 / -1.2 = 83.33 W (not 120 W)
    r = margaria1968(**state(0.3, 1.0, 0.2), basal=False)
    assert float(r.work) == pytest.approx(-100.0, rel=1e-14)
    assert float(r.total) == pytest.approx(250.0 / 3.0, rel=1e-14)  # 83.333 W
    assert float(r.work) / float(r.total) == pytest.approx(-1.2, rel=1e-14)  # the efficiency of negative work
    assert float(r.shortening_lengthening) == pytest.approx(100.0 + 250.0 / 3.0, rel=1e-14)
    assert float(r.activation_maintenance) == 0.0
    # with the basal heat (1.2 W/kg of the 0.5 kg muscle = 0.6 W) added to the same state
    r = margaria1968(**state(0.3, 1.0, 0.2))
    assert float(r.basal) == pytest.approx(0.6, rel=1e-14)
    assert float(r.total) == pytest.approx(250.0 / 3.0 + 0.6, rel=1e-14)
    # lengthening at fV = 1.5, a = 0.4: F_CE = 600 N, V_CE = +0.1 m/s, W_CE = -60 W -> 50 W
    r = margaria1968(**state(0.3, 0.4, 0.2, fv=1.5), basal=False)
    assert float(r.work) == pytest.approx(-60.0, rel=1e-14)
    assert float(r.total) == pytest.approx(50.0, rel=1e-14)
    # isometric: nothing but the basal heat
    r = margaria1968(**state(1.0, 1.0, 0.0))
    assert float(r.total) == pytest.approx(1.2 * MASS, rel=1e-14)


# ----------------------------------------------------------------------------- beside the study's six
def test_additional_models_only_when_named():
    s = state(np.full(4, 0.5), np.full(4, 0.4), np.array([-0.2, -0.1, 0.0, 0.1]))
    t = 0.01 * np.arange(4)
    assert list(compute_models("all", s, time_s=t)) == list(STUDY_MODELS)
    rates = compute_models("all,LW05,MA68", s, time_s=t)
    assert list(rates) == [*STUDY_MODELS, "LW05", "MA68"]
    for r in rates.values():
        np.testing.assert_allclose(r.total, r.work + r.activation_maintenance + r.shortening_lengthening + r.basal,
                                   rtol=1e-12, atol=1e-12)


def test_cli_models_option(tmp_path, capsys):
    from test_metabolics_solution import make_solution

    from musclemetab.commands import main
    from musclemetab.io import read_storage

    sol = make_solution(tmp_path / "sol")
    out = tmp_path / "out"
    code = main(["metabolics", "--solution", str(sol), "--mass", "72.6", "--height", "1.743",
                 "--models", "UM10,LW05,MA68", "--out", str(out)])
    assert code == 0
    assert "LW05" in capsys.readouterr().out
    sto = read_storage(out / "metabolics.sto")
    assert "LW05/soleus_r/total_no_basal" in sto.columns and "MA68/soleus_r/total_no_basal" in sto.columns
    default = tmp_path / "default"
    assert main(["metabolics", "--solution", str(sol), "--mass", "72.6", "--height", "1.743", "--out", str(default)]) == 0
    cols = read_storage(default / "metabolics.sto").columns
    assert not any(c.startswith(("LW05/", "MA68/")) for c in cols)


def test_figure2_panels(tmp_path):
    from musclemetab.metabolics.figure2 import FIGURE2_MODELS, figure2_data, save_figure2

    assert FIGURE2_MODELS == (*STUDY_MODELS, "LW05", "MA68")
    d = figure2_data(models=["LW05", "MA68"], n_velocity=21, n_length=11)
    v = d["velocity"]
    iso = int(np.argmin(np.abs(v["vbar"])))
    assert v["vbar"][iso] == 0.0
    # steady state at l~M = 1: no labile heat (t_stim = inf) above e = 0.1, stable maintenance only
    # (F0 = the example soleus, lMo = 0.045 m); MA68 costs nothing isometric
    f0 = d["config"]["max_isometric_force_N"]
    expected = np.array(d["activations"]) * VMAX / 16.0 * f0 * 0.045
    expected[0] *= 1.975  # a = 0.01 <= 0.1: t_stim = 0, the full labile heat
    np.testing.assert_allclose(v["rate_W"]["LW05"][:, iso], expected, rtol=1e-12)
    np.testing.assert_allclose(v["rate_W"]["MA68"][:, iso], 0.0, atol=1e-12)
    # MA68's efficiency in shortening is exactly 0.25
    eff = v["efficiency"]["MA68"]
    np.testing.assert_allclose(eff[np.isfinite(eff)], 0.25, rtol=1e-12)
    assert np.isfinite(eff).sum() > 10
    p = save_figure2(tmp_path / "fig2.png", n_velocity=21, n_length=11)
    assert p.stat().st_size > 10_000

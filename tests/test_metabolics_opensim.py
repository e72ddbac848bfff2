"""Cross-check against OpenSim 4.6's own metabolic probes on identical muscle states.

OpenSim runs in the worker process (musclemetab.opensim_bridge.probes). The muscle is a
clone of the example model's soleus on a slider (rigid tendon): fiber length and velocity
are set exactly; the muscle quantities OpenSim used (activation, excitation, fL, fV,
forces) are read back and fed to this package's models, so that the comparison is of the
formulas alone. Basal heat and the 1 W/kg minimum heat rate are off on both sides; both
sides get the study's soleus mass and slow-twitch fraction.

Settings (docs/metabolics.md):
  Umberger2010 probe, Bhargava recruitment / negative work / forbid negative power:
    UM10 off/off/off, UM03 off/on/on, UC16 on/on/on
  Bhargava2004 probe: force-dependent shortening constant on, maintenance length
    dependence = identity, negative work on, negative power forbidden.
"""

from __future__ import annotations

import numpy as np
import pytest

from musclemetab.metabolics import bhargava2004, uchida2016, umberger2003, umberger2010
from musclemetab.opensim_bridge import call

pytestmark = pytest.mark.opensim

MASS, FST = 0.476, 0.803
UMB = dict(probe="Umberger2010")
SW = ("use_Bhargava_recruitment_model", "include_negative_mechanical_work", "forbid_negative_total_power")
PROBES = [
    dict(UMB, name="UM10", **dict(zip(SW, (False, False, False)))),
    dict(UMB, name="UM03", **dict(zip(SW, (False, True, True)))),
    dict(UMB, name="UC16", **dict(zip(SW, (True, True, True)))),
]
_UM10_PARTS = ("activation_maintenance_rate_on", "shortening_rate_on", "mechanical_work_rate_on")
for _part in _UM10_PARTS:
    PROBES.append(dict(PROBES[0], name=f"UM10_{_part.split('_rate')[0]}", **{p: p == _part for p in _UM10_PARTS}))
BH = dict(probe="Bhargava2004", use_force_dependent_shortening_prop_constant=True,
          include_negative_mechanical_work=True, maintenance_length_dependence="identity")
PROBES.append(dict(BH, name="BH04", forbid_negative_total_power=True))
_BH_PARTS = ("activation_rate_on", "maintenance_rate_on", "shortening_rate_on", "mechanical_work_rate_on")
for _part in _BH_PARTS:
    PROBES.append(dict(BH, name=f"BH_{_part.split('_rate')[0]}", forbid_negative_total_power=False,
                       **{p: p == _part for p in _BH_PARTS}))


def _states():
    """Grid over the branch boundaries plus random states (228 in all)."""
    grid = []
    for lm in (0.7, 1.0, 1.3):
        for vb in (-0.9, -0.5, -0.41, -0.39, -0.1, 0.0, 0.05, 0.4):
            for e, a in ((0.6, 0.4), (0.3, 0.7), (0.0, 0.5), (1.0, 1.0)):
                grid.append((lm, vb, a, e))
    rng = np.random.default_rng(11)
    n = 228 - len(grid)
    rand = np.column_stack([rng.uniform(0.55, 1.6, n), rng.uniform(-1, 1, n), rng.uniform(0.02, 1, n),
                            rng.uniform(0, 1, n)])
    return np.vstack([np.array(grid), rand])


@pytest.fixture(scope="module")
def probe_run(example):
    s = _states()
    return call("probes:evaluate_probes", s[:, 0], s[:, 1], s[:, 2], s[:, 3], probes=PROBES,
                slow_twitch_fraction=FST, muscle_mass_kg=MASS, model_path=str(example.model),
                muscle_name="soleus_r")


def _inputs(r):
    mp = r["muscle"]
    return dict(
        excitation=r["excitation"], activation=r["activation"],
        normalized_fiber_length=r["normalized_fiber_length"],
        normalized_fiber_velocity=r["normalized_fiber_velocity"],
        active_force_length_multiplier=r["active_force_length_multiplier"],
        force_velocity_multiplier=r["force_velocity_multiplier"],
        passive_fiber_force_N=r["passive_fiber_force_N"],
        max_isometric_force_N=mp["max_isometric_force_N"], optimal_fiber_length_m=mp["optimal_fiber_length_m"],
        max_contraction_velocity=mp["max_contraction_velocity"], muscle_mass_kg=MASS, slow_twitch_fraction=FST,
    )


def _probe(r, name):
    return r[f"{name}/{name}_TOTAL"]


def _agree(ours, theirs):
    # 1e-6 relative; an absolute floor of 1e-9 W where the clamped rates are zero
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-9)


def test_states_are_the_ones_asked_for(probe_run):
    s = _states()
    np.testing.assert_allclose(probe_run["normalized_fiber_length"], s[:, 0], rtol=1e-12)
    np.testing.assert_allclose(probe_run["normalized_fiber_velocity"], s[:, 1], atol=1e-12)
    np.testing.assert_allclose(probe_run["excitation"], s[:, 3], atol=0)
    np.testing.assert_allclose(probe_run["activation"], s[:, 2], atol=0)
    # the work term's force is the active fiber force a fL fV F0, no passive force
    f0 = probe_run["muscle"]["max_isometric_force_N"]
    np.testing.assert_allclose(
        probe_run["active_fiber_force_N"],
        s[:, 2] * probe_run["active_force_length_multiplier"] * probe_run["force_velocity_multiplier"] * f0,
        rtol=1e-12,
    )


def test_umberger_family_agrees_with_the_slow_twitch_cap(probe_run):
    inp = _inputs(probe_run)
    _agree(umberger2010(**inp, slow_twitch_shortening_cap=True, basal=False).total, _probe(probe_run, "UM10"))
    _agree(umberger2003(**inp, slow_twitch_shortening_cap=True, basal=False).total, _probe(probe_run, "UM03"))
    _agree(uchida2016(**inp, slow_twitch_shortening_cap=True, basal=False).total, _probe(probe_run, "UC16"))
    um10 = umberger2010(**inp, slow_twitch_shortening_cap=True, basal=False)
    _agree(um10.activation_maintenance, _probe(probe_run, "UM10_activation_maintenance"))
    _agree(um10.shortening_lengthening, _probe(probe_run, "UM10_shortening"))
    _agree(um10.work, _probe(probe_run, "UM10_mechanical_work"))
    # the slow-lengthening states are not all clamped: the lengthening coefficient is checked
    vb = probe_run["normalized_fiber_velocity"]
    assert np.sum((vb > 0) & (_probe(probe_run, "UM03") > 1.0)) >= 10


def test_without_the_cap_the_study_differs_at_fast_shortening(probe_run):
    inp = _inputs(probe_run)
    ours = umberger2010(**inp, basal=False).total  # the study's setting: no cap
    diff = ours - _probe(probe_run, "UM10")
    fast = probe_run["normalized_fiber_velocity"] * 10.0 < -10.0 / 2.5  # VCE~ < -vmax_ST
    assert fast.sum() >= 30
    # differs exactly where the slow-twitch shortening term exceeds 100 W/kg; more heat without the cap
    assert np.all(diff[fast & (probe_run["activation"] > 0.05)] > 1e-3)
    np.testing.assert_allclose(diff[~fast], 0.0, atol=1e-9)
    assert diff.max() > 20.0


def test_bhargava_agrees_without_the_activation_heat_decay(probe_run):
    inp = _inputs(probe_run)
    ours = bhargava2004(**inp, activation_heat_decay=False, basal=False)
    _agree(ours.total, _probe(probe_run, "BH04"))
    _agree(ours.extras["activation"], _probe(probe_run, "BH_activation"))
    _agree(ours.extras["maintenance"], _probe(probe_run, "BH_maintenance"))
    _agree(ours.work, _probe(probe_run, "BH_mechanical_work"))
    raw = bhargava2004(**inp, activation_heat_decay=False, basal=False, non_negative=False)
    _agree(raw.shortening_lengthening, _probe(probe_run, "BH_shortening"))


def test_bhargava_decay_is_the_difference(probe_run):
    # the study's phi = 0.06 + exp(-t_stim e / 0.045) (0 while e <= 0.1) against OpenSim's phi = 1:
    # with the non-negativity rule off, the rates differ by exactly (phi - 1) * H_A(OpenSim)
    inp = _inputs(probe_run)
    e = probe_run["excitation"]
    t_stim = np.where(e > 0.1, 0.1, 0.0)
    ours = bhargava2004(**inp, stimulation_time_s=t_stim, basal=False, non_negative=False).total
    theirs = sum(_probe(probe_run, f"BH_{p}") for p in ("activation", "maintenance", "shortening", "mechanical_work"))
    phi = np.where(e > 0.1, 0.06 + np.exp(-0.1 * e / 0.045), 0.0)
    h_a = _probe(probe_run, "BH_activation")
    np.testing.assert_allclose(ours - theirs, (phi - 1.0) * h_a, rtol=1e-6, atol=1e-9)
    assert np.max(np.abs(ours - theirs)) > 10.0


def test_fiber_damping_does_not_enter_opensims_fiber_force(example):
    # Millard fiber damping with a compliant tendon: it changes the fiber velocity OpenSim
    # solves for, but OpenSim 4.6 reports a fiber force without a damping term
    # (getFiberForce = active + passive), and the Bhargava probe then agrees with BH04 fed
    # the reported state.
    rng = np.random.default_rng(5)
    n = 30
    r = call("probes:evaluate_probes", rng.uniform(0.8, 1.2, n), rng.uniform(-0.3, 0.3, n),
             rng.uniform(0.2, 1, n), rng.uniform(0, 1, n), probes=[p for p in PROBES if p["name"] == "BH04"], slow_twitch_fraction=FST,
             muscle_mass_kg=MASS, model_path=str(example.model), muscle_name="soleus_r",
             fiber_damping=0.1, tendon_strain=0.03)
    assert r["muscle"]["fiber_damping"] == 0.1
    assert np.any(np.abs(r["normalized_fiber_velocity"]) > 1e-3)
    np.testing.assert_allclose(r["fiber_force_N"], r["active_fiber_force_N"] + r["passive_fiber_force_N"],
                               rtol=1e-12, atol=1e-9)
    _agree(bhargava2004(**_inputs(r), activation_heat_decay=False, basal=False).total, _probe(r, "BH04"))

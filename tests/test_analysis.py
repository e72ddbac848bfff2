"""Gait events, phase and group shares, statistics: each against an independent value.

Synthetic cases are worked by hand in the comments; the example subject checks the
inverse-dynamics toe-off and the §4.1 membership table of ``analysis.md``; the
statistics are checked against Bland & Altman's (1995) published example as shipped with
pingouin, and against pingouin itself.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from musclemetab.analysis import (
    GROUPS,
    GROUPS_WITH_OTHER,
    GaitCycle,
    analyse_metabolics,
    analyse_solution_folder,
    bland_altman,
    cycle_from_grf,
    cycle_from_id_file,
    cycle_from_inverse_dynamics,
    gait_events_from_grf,
    group_rates,
    group_shares,
    group_weights,
    membership_table,
    muscle_membership,
    phase_shares,
    read_grf,
    rmcorr,
)
from musclemetab.errors import DataMismatchError, MissingColumnError, OptionError
from musclemetab.io import read_storage, storage_from_arrays, write_storage

DOFS = ["ankle_angle_r", "knee_angle_r", "hip_flexion_r", "hip_adduction_r", "hip_rotation_r"]


# ------------------------------------------------------------------------------ GaitCycle
def test_gait_cycle_properties_and_validation():
    c = GaitCycle.from_times(1.0, 1.6, duration_s=1.0)
    assert c.end_s == 2.0 and c.duration_s == 1.0
    assert c.stance_fraction == pytest.approx(0.6) and c.swing_fraction == pytest.approx(0.4)
    assert c.toe_off_pct == pytest.approx(60.0)
    np.testing.assert_allclose(c.percent([1.0, 1.5, 2.0]), [0.0, 50.0, 100.0])
    assert GaitCycle.from_times(1.0, 1.6, 2.0) == c
    with pytest.raises(DataMismatchError, match="toe-off"):
        GaitCycle(0.0, 1.2, 1.0)
    with pytest.raises(DataMismatchError, match="precede"):
        GaitCycle(1.0, 0.5, 0.2)
    with pytest.raises(OptionError, match="toe_off_s"):
        GaitCycle(0.0, float("nan"), 1.0)
    with pytest.raises(OptionError, match="exactly one"):
        GaitCycle.from_times(0.0, 0.5)


# ------------------------------------------------------------------------------ GRF events
def _half_sine_grf(t, contacts, peak=800.0):
    f = np.zeros_like(t)
    for hs, to in contacts:
        inside = (t >= hs) & (t <= to)
        f[inside] = peak * np.sin(np.pi * (t[inside] - hs) / (to - hs))
    return f


CONTACTS = [(0.20, 0.82), (1.30, 1.92), (2.40, 3.02)]


def _true_crossings(threshold, peak=800.0):
    # F = peak sin(pi x), x = (t - hs)/(to - hs): F = threshold at x0 = arcsin(threshold/peak)/pi
    # and at 1 - x0, so HS_true = hs + x0 (to - hs), TO_true = to - x0 (to - hs).
    x0 = np.arcsin(threshold / peak) / np.pi
    hs = np.array([a + x0 * (b - a) for a, b in CONTACTS])
    to = np.array([b - x0 * (b - a) for a, b in CONTACTS])
    return hs, to


def test_gait_events_clean_signal_at_known_crossings():
    t = np.arange(0.0, 3.2, 0.001)
    f = _half_sine_grf(t, CONTACTS)
    ev = gait_events_from_grf(t, f, threshold_N=20.0)
    hs, to = _true_crossings(20.0)
    # linear interpolation of a sine over 1 ms: error far below 0.1 ms
    np.testing.assert_allclose(ev.heel_strikes_s, hs, atol=1e-4)
    np.testing.assert_allclose(ev.toe_offs_s, to, atol=1e-4)


def test_gait_events_with_noise():
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 3.2, 0.001)
    # noise of SD 6 N against a 10 N threshold: the swing baseline exceeds the threshold in
    # about 5 % of its samples (1.7 SD), i.e. dozens of 1-ms spikes, and the true crossings
    # chatter for a millisecond or two
    f = _half_sine_grf(t, CONTACTS) + rng.normal(0.0, 6.0, t.size)
    spurious = gait_events_from_grf(t, f, threshold_N=10.0, min_duration_s=0.0)
    assert spurious.heel_strikes_s.size > 3  # without the duration rule the noise makes events
    ev = gait_events_from_grf(t, f, threshold_N=10.0, min_duration_s=0.05)
    hs, to = _true_crossings(10.0)
    assert ev.heel_strikes_s.size == 3 and ev.toe_offs_s.size == 3
    # slope at the crossing ~ 800 pi / 0.62 = 4 kN/s: 3 SD of noise (18 N) shifts a crossing
    # by at most ~5 ms
    np.testing.assert_allclose(ev.heel_strikes_s, hs, atol=0.006)
    np.testing.assert_allclose(ev.toe_offs_s, to, atol=0.006)

    first = cycle_from_grf(t, f, threshold_N=10.0)
    assert first.start_s == ev.heel_strikes_s[0] and first.end_s == ev.heel_strikes_s[1]
    assert first.toe_off_s == ev.toe_offs_s[0]
    second = cycle_from_grf(t, f, threshold_N=10.0, at_time_s=2.0)
    assert second.start_s == ev.heel_strikes_s[1] and second.toe_off_s == ev.toe_offs_s[1]
    with pytest.raises(DataMismatchError, match="containing 2.9"):
        cycle_from_grf(t, f, threshold_N=10.0, at_time_s=2.9)


def test_gait_events_record_starting_in_stance_and_too_short():
    t = np.arange(0.5, 2.0, 0.001)  # starts in the first stance: its heel strike is not seen
    f = _half_sine_grf(t, CONTACTS)
    ev = gait_events_from_grf(t, f)
    hs, to = _true_crossings(20.0)
    np.testing.assert_allclose(ev.toe_offs_s, to[:2], atol=1e-4)
    np.testing.assert_allclose(ev.heel_strikes_s, hs[1:2], atol=1e-4)
    with pytest.raises(DataMismatchError, match="two heel strikes"):
        cycle_from_grf(t, f)
    with pytest.raises(DataMismatchError, match="samples"):
        gait_events_from_grf(t, f[:-1])
    with pytest.raises(OptionError, match="NaN"):
        gait_events_from_grf(t, np.where(t > 1, np.nan, f))


def test_read_grf_column_choice(tmp_path):
    t = np.arange(0.0, 1.0, 0.01)
    cols = {"ground_force_vx": 0 * t, "ground_force_vy": 1 + t, "1_ground_force_vy": 2 + t}
    path = tmp_path / "grf.mot"
    write_storage(path, storage_from_arrays(t, cols), in_degrees=False)
    s = read_grf(path)
    assert s.name == "ground_force_vy"
    np.testing.assert_allclose(s.to_numpy(), 1 + t)
    assert read_grf(path, side="l").name == "1_ground_force_vy"
    assert read_grf(path, column="1_ground_force_vy").name == "1_ground_force_vy"
    other = tmp_path / "plates.mot"
    write_storage(other, storage_from_arrays(t, {"plate1_force_vy": t, "plate2_force_vy": t}), in_degrees=False)
    with pytest.raises(MissingColumnError, match="plate1_force_vy, plate2_force_vy.*column="):
        read_grf(other)
    with pytest.raises(MissingColumnError, match="nothere"):
        read_grf(path, column="nothere")


# ------------------------------------------------------------------------------ ID fallback
def test_cycle_from_inverse_dynamics_synthetic():
    # window 0..1.1 s, padding 0.05 -> cycle 0.05..1.05 s. Plantarflexion moment (negative
    # in OpenSim) M = -100 sin(pi (t - 0.1)/0.5) on 0.1..0.6 s, 0 elsewhere; peak at 0.35 s.
    # With fraction 0.1: sin(pi x) = 0.1 after the peak at x = 1 - arcsin(0.1)/pi,
    # t = 0.1 + 0.5 x = 0.58405... s (interpolation over 1 ms: error < 1e-5 s).
    t = np.arange(0.0, 1.1005, 0.001)
    m = np.where((t > 0.1) & (t < 0.6), -100 * np.sin(np.pi * (t - 0.1) / 0.5), 0.0)
    c = cycle_from_inverse_dynamics(t, m, toe_off_fraction=0.1)
    assert c.start_s == pytest.approx(0.05) and c.end_s == pytest.approx(1.05)
    assert c.toe_off_s == pytest.approx(0.1 + 0.5 * (1 - np.arcsin(0.1) / np.pi), abs=1e-5)
    c2 = cycle_from_inverse_dynamics(t, -m, plantarflexion_sign=+1, toe_off_fraction=0.1)
    assert c2.toe_off_s == pytest.approx(c.toe_off_s)
    with pytest.raises(DataMismatchError, match="no plantarflexion moment"):
        cycle_from_inverse_dynamics(t, np.abs(m))
    with pytest.raises(DataMismatchError, match="leaves no cycle"):
        cycle_from_inverse_dynamics(t, m, window_s=(0.0, 0.08))
    with pytest.raises(DataMismatchError, match="span"):
        cycle_from_inverse_dynamics(t, m, window_s=(0.0, 2.0))
    with pytest.raises(OptionError, match="toe_off_fraction"):
        cycle_from_inverse_dynamics(t, m, toe_off_fraction=1.5)
    with pytest.raises(OptionError, match="plantarflexion_sign"):
        cycle_from_inverse_dynamics(t, m, plantarflexion_sign=2)


def test_cycle_from_inverse_dynamics_example_normal_trial(example):
    # analysis.md §3: cycle 0.62-1.70 s, the ankle ID moment returns to ~0 near 1.28-1.30 s,
    # toe-off around 62 % of the cycle.
    c = cycle_from_id_file(example.id["normal"])
    assert c.start_s == pytest.approx(0.62) and c.end_s == pytest.approx(1.70)
    assert 1.28 <= c.toe_off_s <= 1.30
    assert 61.0 <= c.toe_off_pct <= 63.0
    df = read_storage(example.id["normal"])
    same = cycle_from_inverse_dynamics(df.index.to_numpy(), df["ankle_angle_r_moment"].to_numpy(), (0.57, 1.75))
    assert same == c
    with pytest.raises(MissingColumnError, match="ankle_angle_x_moment"):
        cycle_from_id_file(example.id["normal"], column="ankle_angle_x_moment")


# ------------------------------------------------------------------------------ phases
def test_phase_shares_worked_by_hand():
    t = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    rate = np.array([2.0, 2.0, 6.0, 6.0, 2.0])
    # cycle 0..1 s, TO 0.6 s (rate there 6 W, inside the flat 0.5-0.75 segment):
    # stance = 0.25*(2+2)/2 + 0.25*(2+6)/2 + 0.1*6 = 0.5 + 1.0 + 0.6 = 2.1 J
    # swing  = 0.15*6 + 0.25*(6+2)/2 = 0.9 + 1.0 = 1.9 J; whole 4.0 J -> 52.5 % / 47.5 %
    out = phase_shares(t, rate, GaitCycle(0.0, 0.6, 1.0))
    assert out["stance_pct"] == pytest.approx(52.5) and out["swing_pct"] == pytest.approx(47.5)
    assert out["stance_J"] == pytest.approx(2.1) and out["cycle_J"] == pytest.approx(4.0)
    # TO 0.3 s, on the slope: rate(0.3) = 2 + 4*0.05/0.25 = 2.8 W;
    # stance = 0.5 + 0.05*(2+2.8)/2 = 0.62 J -> 15.5 %
    assert phase_shares(t, rate, GaitCycle(0.0, 0.3, 1.0))["stance_pct"] == pytest.approx(15.5)
    # a constant 1 W of basal heat: stance 2.1 + 0.6 = 2.7 J of 5.0 J -> 54 %
    assert phase_shares(t, rate + 1.0, GaitCycle(0.0, 0.6, 1.0))["stance_pct"] == pytest.approx(54.0)
    # (muscles, time) input is summed over muscles: halves give the same shares
    two = phase_shares(t, np.vstack([rate / 2, rate / 2]), GaitCycle(0.0, 0.6, 1.0))
    assert two["stance_pct"] == pytest.approx(52.5)
    # samples ending one interval (0.25 s) short of the cycle end: the part covered is used
    short = phase_shares(t[:-1], rate[:-1], GaitCycle(0.0, 0.6, 1.0))
    assert short["end_s"] == 0.75 and short["stance_pct"] == pytest.approx(2.1 / 3.0 * 100)
    with pytest.raises(DataMismatchError, match="gait cycle spans"):
        phase_shares(t[:-1], rate[:-1], GaitCycle(0.0, 0.6, 1.0), coverage_tolerance_s=0.1)
    with pytest.raises(DataMismatchError, match="samples"):
        phase_shares(t, rate[:-1], GaitCycle(0.0, 0.6, 1.0))
    with pytest.raises(OptionError, match="increasing"):
        phase_shares(t[::-1], rate, GaitCycle(0.0, 0.6, 1.0))
    with pytest.raises(DataMismatchError, match="0 J|undefined"):
        phase_shares(t, 0 * rate, GaitCycle(0.0, 0.6, 1.0))


# ------------------------------------------------------------------------------ groups
# Hand case: three muscles, DOFs ankle and knee, times 0, 0.5, 1.0 s.
#   A: ankle r = -0.03 m (PF); knee r = +0.01 (KF) at 0 and 0.5 s, -0.01 (KE) at 1.0 s
#      -> weights 0.03/0.04 = 0.75 to PF, 0.25 to KF then KE.
#   B: ankle -0.04 m, knee +0.0005 m (below 1 mm, ignored) -> 100 % PF.
#   C: ankle +0.0002 m, knee 0 -> no moment arm above 1 mm -> "other".
# Rates A = 4, 4, 8 W; B = 2 W; C = 1 W.
#   PF = 0.75 A + B = 5, 5, 8;  KF = 1, 1, 0;  KE = 0, 0, 2;  other = 1, 1, 1; total 7, 7, 11.
# Trapezoid (dt 0.5): PF 2.5 + 3.25 = 5.75 J; KF 0.5 + 0.25 = 0.75; KE 0.5; other 1.0;
# total 3.5 + 4.5 = 8.0 J -> PF 71.875 %, KF 9.375 %, KE 6.25 %, other 12.5 %.
HAND_T = np.array([0.0, 0.5, 1.0])
HAND_DOFS = ["ankle_angle_r", "knee_angle_r"]
HAND_MUSCLES = ["A", "B", "C"]
HAND_RATES = np.array([[4.0, 4.0, 8.0], [2.0, 2.0, 2.0], [1.0, 1.0, 1.0]])


def _hand_moment_arms():
    r = np.zeros((3, 2, 3))
    r[:, 0, 0] = -0.03
    r[:, 1, 0] = [0.01, 0.01, -0.01]
    r[:, 0, 1] = -0.04
    r[:, 1, 1] = 0.0005
    r[:, 0, 2] = 0.0002
    return r


HAND_SHARES = {"PF": 71.875, "KF": 9.375, "KE": 6.25, "other": 12.5}


def test_group_weights_rates_and_shares_worked_by_hand():
    w = group_weights(_hand_moment_arms(), HAND_DOFS)
    assert w.shape == (3, len(GROUPS_WITH_OTHER), 3)
    g = {name: k for k, name in enumerate(GROUPS_WITH_OTHER)}
    np.testing.assert_allclose(w[:, g["PF"], 0], 0.75)
    np.testing.assert_allclose(w[:, g["KF"], 0], [0.25, 0.25, 0.0])
    np.testing.assert_allclose(w[:, g["KE"], 0], [0.0, 0.0, 0.25])
    np.testing.assert_allclose(w[:, g["PF"], 1], 1.0)
    np.testing.assert_allclose(w[:, g["other"], 2], 1.0)
    rates = group_rates(HAND_RATES, w)
    np.testing.assert_allclose(rates[g["PF"]], [5, 5, 8])
    np.testing.assert_allclose(rates[g["KE"]], [0, 0, 2])
    shares = group_shares(HAND_T, rates, HAND_RATES.sum(axis=0))
    for name in GROUPS_WITH_OTHER:
        assert shares[name] == pytest.approx(HAND_SHARES.get(name, 0.0)), name
    assert sum(shares.values()) == pytest.approx(100.0)
    # over a cycle 0.25..1.0 s: PF(0.25) = 5 -> PF 1.25 + 3.25 = 4.5 J; total(0.25) = 7 ->
    # 1.75 + 4.5 = 6.25 J -> PF 72 %
    part = group_shares(HAND_T, rates, HAND_RATES, cycle=GaitCycle(0.25, 0.5, 1.0))
    assert part["PF"] == pytest.approx(72.0)
    # a threshold of 0.1 mm lets B's knee moment arm count: 0.0005/0.0405 of B to KF
    w2 = group_weights(_hand_moment_arms(), HAND_DOFS, threshold_m=1e-4)
    np.testing.assert_allclose(w2[:, g["KF"], 1], 0.0005 / 0.0405)


def test_groups_and_other_sum_to_the_whole():
    rng = np.random.default_rng(3)
    r = rng.normal(0.0, 0.02, size=(50, 5, 12))
    r[:, :, 0] = rng.uniform(-1e-3, 1e-3, size=(50, 5))  # never above the threshold -> other
    rate = rng.uniform(0.0, 50.0, size=(12, 50))
    w = group_weights(r, DOFS)
    assert np.all(w >= 0)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(w[:, -1, 0], 1.0)
    g = group_rates(rate, w)
    np.testing.assert_allclose(g.sum(axis=0), rate.sum(axis=0), rtol=1e-12)
    t = np.linspace(0.0, 1.0, 50)
    assert sum(group_shares(t, g, rate).values()) == pytest.approx(100.0)
    # hip rotation: positive moment arm -> internal rotators
    only = np.zeros((1, 5, 1))
    only[0, 4, 0] = 0.01
    assert group_weights(only, DOFS)[0, GROUPS.index("HIR"), 0] == 1.0
    only[0, 4, 0] = -0.01
    assert group_weights(only, DOFS)[0, GROUPS.index("HER"), 0] == 1.0


def test_group_errors():
    r = _hand_moment_arms()
    with pytest.raises(OptionError, match="lumbar_extension.*dof_groups"):
        group_weights(r, ["ankle_angle_r", "lumbar_extension"])
    custom = group_weights(r, ["ankle_angle_r", "lumbar_extension"], dof_groups={"lumbar_extension": ("HE", "HF")})
    assert custom[0, GROUPS.index("HE"), 0] == pytest.approx(0.25)
    with pytest.raises(DataMismatchError, match="2 DOFs"):
        group_weights(r, ["ankle_angle_r"])
    with pytest.raises(DataMismatchError, match="time, dofs, muscles"):
        group_weights(r[0], HAND_DOFS)
    with pytest.raises(OptionError, match="NaN"):
        group_weights(np.where(r == 0.0005, np.nan, r), HAND_DOFS)
    with pytest.raises(OptionError, match="threshold_m"):
        group_weights(r, HAND_DOFS, threshold_m=-1)
    w = group_weights(r, HAND_DOFS)
    with pytest.raises(DataMismatchError, match="interpolate"):
        group_rates(HAND_RATES[:, :2], w)
    with pytest.raises(DataMismatchError, match="expected"):
        group_shares(HAND_T, group_rates(HAND_RATES, w)[:3], HAND_RATES.sum(0))


# The analysis.md §4.1 table, transcribed (names without "_r"; ranges written out).
TABLE_41 = {
    "ankle_angle_r": (
        "edl ehl tibant",
        "fdl fhl gaslat gasmed perbrev perlong soleus tibpost",
        "",
    ),
    "knee_angle_r": (
        "bflh bfsh gaslat gasmed grac sart semimem semiten",
        "recfem tfl vasint vaslat vasmed",
        "",
    ),
    "hip_flexion_r": (
        "addbrev addlong addmagProx glmin1 iliacus psoas recfem sart tfl",
        "addmagDist addmagIsch bflh glmax1 glmax2 glmax3 glmed1 glmed2 glmed3 glmin3 piri semimem semiten",
        "addmagMid grac glmin2",
    ),
    "hip_adduction_r": (
        "addbrev addlong addmagDist addmagIsch addmagMid addmagProx bflh glmax3 grac psoas semimem semiten",
        "glmax1 glmax2 glmed1 glmed2 glmed3 glmin1 glmin2 glmin3 piri recfem sart tfl",
        "iliacus",
    ),
    "hip_rotation_r": (
        "addbrev addlong addmagIsch glmin1 iliacus semimem psoas",
        "bflh glmax1 glmax2 glmax3 grac piri recfem sart",
        "addmagDist addmagMid addmagProx glmed1 glmed2 glmed3 glmin2 glmin3 semiten tfl",
    ),
}


@pytest.mark.opensim
def test_membership_table_matches_analysis_md(example, geometry_cache):
    from musclemetab.geometry import compute_geometry

    geoms = [compute_geometry(example.model, example.ik[s], dofs=DOFS, cache_dir=geometry_cache)
             for s in ("slow", "normal", "fast")]
    muscles = geoms[0].muscles
    assert all(g.muscles == muscles for g in geoms)
    # the table is derived over the three example cycles
    table = membership_table([g.moment_arms_m for g in geoms], DOFS, muscles)
    strip = lambda names: {n[:-2] for n in names}  # noqa: E731
    groups = {"ankle_angle_r": ("DF", "PF"), "knee_angle_r": ("KF", "KE"), "hip_flexion_r": ("HF", "HE"),
              "hip_adduction_r": ("HAD", "HAB"), "hip_rotation_r": ("HIR", "HER")}
    for dof, (pos, neg, changing) in TABLE_41.items():
        row = table.loc[dof]
        assert (row.positive_group, row.negative_group) == groups[dof]
        assert strip(row.positive) == set(pos.split()), dof
        assert strip(row.negative) == set(neg.split()), dof
        assert strip(row.sign_changing) == set(changing.split()), dof
    # the notes on the sign-changing hip-flexion muscles: addmagMid and grac negative on
    # average, glmin2 about zero; iliacus about zero for adduction
    long = muscle_membership([g.moment_arms_m for g in geoms], DOFS, muscles).set_index(["dof", "muscle"])
    assert long.loc[("hip_flexion_r", "addmagMid_r"), "mean_m"] < -1e-3
    assert long.loc[("hip_flexion_r", "grac_r"), "mean_m"] < -1e-3
    assert abs(long.loc[("hip_flexion_r", "glmin2_r"), "mean_m"]) < 1e-3
    assert abs(long.loc[("hip_adduction_r", "iliacus_r"), "mean_m"]) < 1e-3
    # every muscle spans some DOF beyond 1 mm at every frame: nothing goes to "other"
    for g in geoms:
        assert group_weights(g.moment_arms_m, DOFS)[:, -1, :].max() == 0.0


# ------------------------------------------------------------------------------ unit
def _hand_result():
    from musclemetab.metabolics import MetabolicRates
    from musclemetab.metabolics.solution import SolutionMetabolics

    basal = np.array([[0.5] * 3, [0.5] * 3, [0.0] * 3])
    zero = np.zeros((3, 3))
    rates = MetabolicRates("UM10", work=HAND_RATES, activation_maintenance=zero, shortening_lengthening=zero,
                           basal=basal, total=HAND_RATES + basal)
    return SolutionMetabolics(
        time_s=HAND_T, muscles=tuple(HAND_MUSCLES), models=("UM10",), rates={"UM10": rates}, whole_body={},
        muscle_mass_kg=np.ones(3), slow_twitch_fraction=np.full(3, 0.5), parameters={}, body_mass_kg=70.0,
        height_m=1.7, basal_rule="muscle",
    )


def test_analyse_metabolics_worked_by_hand():
    # geometry on a finer grid (0, 0.25, ... 1 s), linear in time so that interpolation
    # to the nodes 0, 0.5, 1 s returns the hand case; muscles in another order plus one
    # extra muscle.
    tg = np.linspace(0.0, 1.0, 5)
    hand = _hand_moment_arms()  # (3 nodes, 2 DOFs, 3 muscles)
    fine = np.stack([np.interp(tg, HAND_T, hand[:, d, m]) for d in range(2) for m in range(3)], axis=-1)
    fine = fine.reshape(5, 2, 3)
    geo_muscles = ["C", "extra", "A", "B"]
    r = np.zeros((5, 2, 4))
    r[:, :, 0], r[:, :, 2], r[:, :, 3] = fine[:, :, 2], fine[:, :, 0], fine[:, :, 1]
    r[:, 0, 1] = 0.05
    cycle = GaitCycle(0.0, 0.5, 1.0)
    summary, series = analyse_metabolics(_hand_result(), tg, r, HAND_DOFS, geo_muscles, cycle)
    row = summary.iloc[0]
    assert row.model == "UM10" and row.toe_off_pct == pytest.approx(50.0)
    # leg without basal 7, 7, 11 W: stance 0.5*7 = 3.5 J, swing 0.5*(7+11)/2 = 4.5 J -> 43.75 %
    assert row.stance_energy_share_pct == pytest.approx(43.75) and row.swing_energy_share_pct == pytest.approx(56.25)
    assert row.leg_energy_J == pytest.approx(8.0)
    # with the basal heat (+1 W): 8, 8, 12 W -> stance 4 J of 9 J
    assert row.stance_energy_share_with_basal_pct == pytest.approx(400 / 9)
    for name in GROUPS:
        assert row[f"share_{name}_pct"] == pytest.approx(HAND_SHARES.get(name, 0.0)), name
    assert row.share_other_pct == pytest.approx(12.5)
    wide = series.pivot(index="time_s", columns="series", values="value_W")
    np.testing.assert_allclose(wide["leg_muscles"], [7, 7, 11])
    groups = wide[[c for c in wide.columns if c.startswith("group/")]]
    np.testing.assert_allclose(groups.sum(axis=1), wide["leg_muscles"])
    np.testing.assert_allclose(wide["group/PF"], [5, 5, 8])
    np.testing.assert_allclose(series.loc[series.series == "leg_muscles", "cycle_pct"], [0, 50, 100])
    with pytest.raises(DataMismatchError, match="B"):
        analyse_metabolics(_hand_result(), tg, r[:, :, :3], HAND_DOFS, geo_muscles[:3], cycle)
    with pytest.raises(DataMismatchError, match="moment arms only"):
        analyse_metabolics(_hand_result(), tg[1:], r[1:], HAND_DOFS, geo_muscles, cycle)
    with pytest.raises(OptionError, match="BH04"):
        analyse_metabolics(_hand_result(), tg, r, HAND_DOFS, geo_muscles, cycle, models=["BH04"])


def _solution_folder(folder):
    """A two-muscle solution folder in the solver's format (solution.sto + summary.json)."""
    folder.mkdir(parents=True, exist_ok=True)
    t = 0.57 + 0.01 * np.arange(31)
    cols = {}
    for i, m in enumerate(("soleus_r", "tibant_r")):
        a = 0.3 + 0.2 * np.sin(2 * np.pi * t + i)
        cols.update({
            f"/forceset/{m}/excitation": a, f"/forceset/{m}/activation": a,
            f"/forceset/{m}/normalized_fiber_length": 1.0 + 0.1 * np.sin(4 * np.pi * t),
            f"/forceset/{m}/normalized_fiber_velocity": 0.2 * np.cos(4 * np.pi * t),
            f"/forceset/{m}/active_force_length_multiplier": np.full_like(t, 0.9),
            f"/forceset/{m}/force_velocity_multiplier": np.full_like(t, 1.0),
            f"/forceset/{m}/passive_fiber_force": np.zeros_like(t),
        })
    write_storage(folder / "solution.sto", storage_from_arrays(t, cols))
    params = {m: dict(F0_N=3000.0, lMo_m=0.05, vmax_lMo_per_s=10.0) for m in ("soleus_r", "tibant_r")}
    (folder / "summary.json").write_text(json.dumps(dict(success=True, status="Solve_Succeeded",
                                                         muscles=["soleus_r", "tibant_r"], parameters=params)))
    return folder


def test_analyse_solution_folder(tmp_path):
    from musclemetab.geometry import Geometry
    from musclemetab.metabolics.solution import metabolics_from_solution

    folder = _solution_folder(tmp_path / "sol")
    tg = 0.57 + 0.01 * np.arange(31)
    r = np.zeros((31, 5, 2))
    r[:, 0, 0], r[:, 0, 1] = -0.05, 0.04  # soleus only PF, tibialis anterior only DF
    geom = Geometry(tg, ("soleus_r", "tibant_r"), tuple(DOFS), np.zeros((31, 2)), r, {})
    cycle = GaitCycle(0.62, 0.70, 0.77)
    summary, _ = analyse_solution_folder(folder, geom, cycle, 72.6, 1.743, models="UM10,BH04")
    res = metabolics_from_solution(folder, 72.6, 1.743, models="UM10,BH04")
    t = res.time_s
    keep = (t >= 0.62 - 1e-9) & (t <= 0.77 + 1e-9)  # the cycle falls on nodes here
    for _, row in summary.iterrows():
        e = res.rates[row.model].total_without_basal()[:, keep]
        sol, tib = (np.trapezoid(x, t[keep]) for x in e)
        assert row.share_PF_pct == pytest.approx(100 * sol / (sol + tib))
        assert row.share_DF_pct == pytest.approx(100 * tib / (sol + tib))
        st = t[keep] <= 0.70 + 1e-9
        stance = np.trapezoid(e.sum(0)[st], t[keep][st])
        assert row.stance_energy_share_pct == pytest.approx(100 * stance / (sol + tib))
    assert list(summary.model) == ["UM10", "BH04"]


@pytest.mark.opensim
def test_analyse_basal_options_give_the_whole_body_rate_worked_by_hand(example, tmp_path, capsys):
    """``analyse --basal-coefficient/--basal-exponent`` (the options of ``metabolics``): under the
    body rule the basal heat is COEFFICIENT * m^EXPONENT W over m kg, added to the muscles' rate
    without basal heat; under the muscle rule the basal part is linear in the coefficient."""
    import pandas as pd

    from musclemetab.commands import main

    mass, speed = 72.6, 1.3
    folder = _solution_folder(tmp_path / "sol")
    base = ["analyse", "--solution", str(folder), "--model", str(example.model), "--ik", str(example.ik["normal"]),
            "--cycle", "0.62,0.70,0.77", "--mass", str(mass), "--height", "1.743", "--models", "UM10,BH04",
            "--speed", str(speed)]

    def whole_body(name, *options):
        assert main([*base, *options, "--out", str(tmp_path / name)]) == 0
        return pd.read_csv(tmp_path / name / "whole_body.csv").set_index("model")

    default = whole_body("default")  # whole_body.csv holds 10 significant digits
    kleiber = whole_body("kleiber", "--basal-coefficient", "1.5", "--basal-exponent", "0.75")
    basal = 1.5 * mass ** 0.75 / mass  # W/kg: 72.6^0.25 = sqrt(8.5206) = 2.9190, 1.5 / 2.9190 = 0.51387
    assert basal == pytest.approx(0.51387, abs=1e-5)
    np.testing.assert_allclose(default["basal_W_per_kg"], 1.2, rtol=1e-9)
    np.testing.assert_allclose(kleiber["basal_W_per_kg"], basal, rtol=1e-9)
    np.testing.assert_allclose(kleiber["whole_body_no_basal_W_per_kg"], default["whole_body_no_basal_W_per_kg"], rtol=1e-9)
    np.testing.assert_allclose(kleiber["whole_body_W_per_kg"], default["whole_body_W_per_kg"] - 1.2 + basal, rtol=1e-9)
    np.testing.assert_allclose(kleiber["gross_cost_of_transport_J_per_kg_per_m"], kleiber["whole_body_W_per_kg"] / speed,
                               rtol=1e-9)
    # the muscle rule: 1.2 W per kg of each muscle's mass; twice the coefficient, twice the basal part
    muscle = whole_body("muscle", "--basal", "muscle")
    double = whole_body("double", "--basal", "muscle", "--basal-coefficient", "2.4")
    part = muscle["whole_body_W_per_kg"] - muscle["whole_body_no_basal_W_per_kg"]
    assert (part > 0).all()
    np.testing.assert_allclose(double["whole_body_W_per_kg"] - double["whole_body_no_basal_W_per_kg"], 2 * part, rtol=0,
                               atol=1e-8)  # differences of rates near 3 W/kg written to 10 digits
    # without basal options, analyse takes those 'metabolics' recorded in its metabolics.sto
    assert main(["metabolics", "--solution", str(folder), "--model", str(example.model), "--mass", str(mass),
                 "--height", "1.743", "--models", "UM10,BH04", "--basal-coefficient", "1.5", "--basal-exponent",
                 "0.75", "--out", str(tmp_path / "met")]) == 0
    recorded = whole_body("recorded", "--metabolics", str(tmp_path / "met"))
    np.testing.assert_allclose(recorded["whole_body_W_per_kg"], kleiber["whole_body_W_per_kg"], rtol=1e-12)
    capsys.readouterr()
    # the exponent belongs to the body rule: refused in one line, nothing written
    assert main([*base, "--basal", "muscle", "--basal-exponent", "0.75", "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err.strip()
    assert "--basal-exponent applies to --basal body only" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "bad").exists()


# ------------------------------------------------------------------------------ statistics
@pytest.mark.filterwarnings("ignore:The inplace keyword")
def test_rmcorr_bland_altman_1995_example():
    pg = pytest.importorskip("pingouin")
    df = pg.read_dataset("rm_corr")  # Bland & Altman (1995): 8 subjects, 47 pairs of pH, PaCO2
    res = rmcorr(df["PacO2"], df["pH"], df["Subject"])
    # published: r = -0.507, df = 38 (Bland & Altman 1995; Bakdash & Marusich 2017)
    assert res.r == pytest.approx(-0.507, abs=5e-4)
    assert res.df == 38 and res.n == 47 and res.n_subjects == 8
    ref = pg.rm_corr(data=df, x="PacO2", y="pH", subject="Subject")
    assert res.r == pytest.approx(float(ref["r"].iloc[0]), rel=1e-9)
    assert res.p == pytest.approx(float(ref["pval"].iloc[0]), rel=1e-6)
    assert res.df == int(ref["dof"].iloc[0])
    # slope and intercepts: ordinary least squares on subject dummies + x (the ANCOVA)
    subjects = sorted(df["Subject"].unique())
    X = np.column_stack([(df["Subject"] == s).to_numpy(float) for s in subjects] + [df["PacO2"].to_numpy()])
    coef, *_ = np.linalg.lstsq(X, df["pH"].to_numpy(), rcond=None)
    assert res.slope == pytest.approx(coef[-1], rel=1e-9)
    for s, a in zip(subjects, coef[:-1]):
        assert res.intercepts[s] == pytest.approx(a, rel=1e-9)
    # r is symmetric in x and y
    assert rmcorr(df["pH"], df["PacO2"], df["Subject"]).r == pytest.approx(res.r)


def test_rmcorr_worked_by_hand_and_errors():
    # two subjects, y = subject offset + 2 x exactly (+ one deviation):
    # s1: x 0,1,2  y 0,2,4 ; s2: x 0,1,2  y 10,12,15.
    # centred: x~ = -1,0,1 twice; y~ s1 = -2,0,2; s2 = 12.333.. mean -> -2.333,-0.333,2.667
    # sum x~y~ = 4 + 5 = 9; sum x~^2 = 4 -> slope 2.25
    x = [0, 1, 2, 0, 1, 2]
    y = [0, 2, 4, 10, 12, 15]
    res = rmcorr(x, y, ["a"] * 3 + ["b"] * 3)
    assert res.slope == pytest.approx(2.25) and res.df == 3
    # SS_model = 2.25^2*4 = 20.25; sum y~^2 = 8 + (5.444+0.111+7.111) = 20.6667
    # SS_error = 20.6667 - 20.25 = 0.41667; r = sqrt(20.25/20.6667)
    assert res.r == pytest.approx(np.sqrt(20.25 / (20.25 + 0.25 / 0.6)))
    assert res.intercepts["a"] == pytest.approx(2.0 - 2.25 * 1.0)
    with pytest.raises(DataMismatchError, match="same length"):
        rmcorr(x, y[:-1], ["a"] * 6)
    with pytest.raises(DataMismatchError, match="two subjects"):
        rmcorr(x, y, ["a"] * 6)
    with pytest.raises(DataMismatchError, match="degrees of freedom"):
        rmcorr([0, 1, 0], [1, 2, 3], ["a", "a", "b"])
    with pytest.raises(OptionError, match="NaN"):
        rmcorr([0, 1, np.nan, 0, 1, 2], y, ["a"] * 3 + ["b"] * 3)
    with pytest.raises(DataMismatchError, match="x does not vary"):
        rmcorr([1, 1, 1, 2, 2, 2], y, ["a"] * 3 + ["b"] * 3)


def test_bland_altman_worked_by_hand():
    # d = estimated - measured = 1, 2, 3, 6: bias 3; deviations -2,-1,0,3 -> SS 14,
    # SD = sqrt(14/3) = 2.1602; limits 3 -+ 1.96*2.1602 = -1.2340 .. 7.2340
    est = [5.0, 6.0, 8.0, 12.0]
    meas = [4.0, 4.0, 5.0, 6.0]
    ba = bland_altman(est, meas)
    assert ba.bias == pytest.approx(3.0) and ba.n == 4
    assert ba.sd == pytest.approx(np.sqrt(14 / 3))
    assert ba.lower == pytest.approx(3 - 1.96 * np.sqrt(14 / 3))
    assert ba.upper == pytest.approx(3 + 1.96 * np.sqrt(14 / 3))
    with pytest.raises(DataMismatchError, match="same length"):
        bland_altman(est, meas[:3])
    with pytest.raises(DataMismatchError, match="two pairs"):
        bland_altman([1.0], [2.0])
    with pytest.raises(OptionError, match="NaN"):
        bland_altman([1.0, np.nan], [2.0, 3.0])

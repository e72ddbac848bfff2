"""The chunked, multi-threaded evaluation of the metabolic models gives the results of a
single-chunk evaluation, bit for bit.

The models evaluate large arrays in cache-sized chunks on several threads
(``musclemetab.metabolics._common``: ``CHUNK_SIZE``, ``THREADS``, ``PARALLEL_MIN_SIZE``).
Here the chunks are made small (many chunks, pieces of rows, blocks of rows, sizes that are
not multiples of the chunk) and threads are forced on small arrays, and every model is
compared, component by component, with one chunk on the calling thread, on random states
that reach every branch of every model and option.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from musclemetab.errors import OptionError
from musclemetab.metabolics import MODELS, _common, bhargava_stimulation_time_s, umberger2003
from musclemetab.metabolics._common import STATE_ARGUMENTS
from musclemetab.metabolics.bhargava import _stimulation_count

CHUNK = 64  # small chunks: many of them even on small arrays

# the options of each model that select branches (all combinations are evaluated)
FLAGS = {
    "UM03": ("non_negative", "include_negative_work", "slow_twitch_shortening_cap", "basal"),
    "UM10": ("non_negative", "include_negative_work", "slow_twitch_shortening_cap", "basal"),
    "UC16": ("non_negative", "include_negative_work", "slow_twitch_shortening_cap", "basal"),
    "BH04": ("non_negative", "basal"),
    "HO06": ("non_negative", "basal"),
    "LW07": ("non_negative", "basal"),
}

# (state shape, parameter shape): pieces of rows with a remainder, blocks of short rows,
# 1-D with scalar and with per-sample parameters, 3-D, a scalar state, an empty array
SHAPES = [
    ((3, 5 * CHUNK + 17), (3,)),
    ((2, CHUNK - 5), (2, 1)),
    ((9, 11), (9,)),
    ((7 * CHUNK + 3,), ()),
    ((3 * CHUNK + 1,), (3 * CHUNK + 1,)),
    ((2, 3, 2 * CHUNK + 9), (2,)),
    ((4, 3, 5), (4,)),
    ((), ()),
    ((0, 7), (0,)),
]


def _states(rng, shape, pshape):
    """Random states reaching every branch: excitation above and below activation, 0,
    negative and beyond 1; fibres shorter, longer and exactly at optimal
    length; shortening, lengthening and isometric; fV below, at and above 1; runs of
    excitation above and below BH04's threshold; totals below zero (non-negativity)."""
    e = rng.uniform(-0.05, 1.0, shape)
    e[rng.random(shape) < 0.05] = 0.0
    e[rng.random(shape) < 0.03] = 1.2
    e[rng.random(shape) < 0.03] = -1.1
    if e.ndim and e.shape[-1] > 10:  # long runs above the threshold, across chunks
        e[..., 3 : e.shape[-1] // 2] = np.maximum(e[..., 3 : e.shape[-1] // 2], 0.5)
    a = rng.uniform(0.0, 1.0, shape)
    same = rng.random(shape) < 0.05
    a[same] = e[same]
    a[rng.random(shape) < 0.03] = 0.0
    lm = rng.uniform(0.4, 1.6, shape)
    lm[rng.random(shape) < 0.05] = 1.0
    vb = rng.uniform(-1.0, 1.0, shape)
    vb[rng.random(shape) < 0.05] = 0.0
    fv = rng.uniform(0.0, 1.8, shape)
    fv[rng.random(shape) < 0.05] = 1.0
    return dict(
        excitation=e,
        activation=a,
        normalized_fiber_length=lm,
        normalized_fiber_velocity=vb,
        active_force_length_multiplier=rng.uniform(0.0, 1.0, shape),
        force_velocity_multiplier=fv,
        passive_fiber_force_N=rng.uniform(0.0, 50.0, shape),
        max_isometric_force_N=rng.uniform(300.0, 6000.0, pshape),
        optimal_fiber_length_m=rng.uniform(0.03, 0.2, pshape),
        max_contraction_velocity=rng.uniform(8.0, 12.0, pshape),
        muscle_mass_kg=rng.uniform(0.05, 1.0, pshape),
        slow_twitch_fraction=rng.choice([0.0, 0.5, 0.8, 1.0], pshape) if pshape else 0.6,
    )


def _options(name, shape, rng):
    for values in itertools.product([False, True], repeat=len(FLAGS[name])):
        opts = dict(zip(FLAGS[name], values))
        if name != "BH04":
            yield opts
            continue
        yield {**opts, "activation_heat_decay": False}
        yield {**opts, "activation_heat_decay": False, "maintenance_length_dependence": "published"}
        t_stim = rng.uniform(0.0, 0.3, shape)
        t_stim[rng.random(shape) < 0.2] = 0.0
        t_stim[rng.random(shape) < 0.2] = np.inf
        yield {**opts, "stimulation_time_s": t_stim}
        if len(shape) and shape[-1] >= 2:
            yield {**opts, "time_s": np.cumsum(rng.uniform(0.005, 0.015, shape[-1]))}


def _single_chunk(monkeypatch):
    monkeypatch.setattr(_common, "CHUNK_SIZE", 1 << 40)
    monkeypatch.setattr(_common, "THREADS", 1)


def _many_chunks(monkeypatch, threads):
    monkeypatch.setattr(_common, "CHUNK_SIZE", CHUNK)
    monkeypatch.setattr(_common, "THREADS", threads)
    monkeypatch.setattr(_common, "PARALLEL_MIN_SIZE", 0)


def _same_bits(x, y):
    x, y = np.asarray(x), np.asarray(y)
    return x.shape == y.shape and x.dtype == y.dtype and x.tobytes() == y.tobytes()


@pytest.mark.parametrize("name", list(MODELS))
def test_chunked_threaded_evaluation_equals_single_chunk(name, monkeypatch):
    rng = np.random.default_rng(sum(map(ord, name)))
    model = MODELS[name]
    for shape, pshape in SHAPES:
        s = _states(rng, shape, pshape)
        for opts in _options(name, shape, rng):
            with monkeypatch.context() as m, np.errstate(all="ignore"):
                _single_chunk(m)
                ref = model(**s, **opts).components()
            for threads in (1, 3):
                with monkeypatch.context() as m, np.errstate(all="ignore"):
                    _many_chunks(m, threads)
                    got = model(**s, **opts).components()
                assert list(got) == list(ref)
                for key in ref:
                    assert _same_bits(got[key], ref[key]), (name, shape, opts.keys(), threads, key)


def test_default_settings_on_a_large_array_equal_single_chunk(monkeypatch):
    # the settings as shipped (several chunks and threads) on arrays larger than a chunk
    rng = np.random.default_rng(11)
    shape = (3, 2 * _common.CHUNK_SIZE + 1001)
    s = _states(rng, shape, (3,))
    time = np.cumsum(rng.uniform(0.005, 0.015, shape[-1]))
    for name, model in MODELS.items():
        with np.errstate(all="ignore"):
            got = model(**s, time_s=time).components()
            with monkeypatch.context() as m:
                _single_chunk(m)
                ref = model(**s, time_s=time).components()
        for key in ref:
            assert _same_bits(got[key], ref[key]), (name, key)


@pytest.mark.parametrize("threads", [1, 3])
def test_stimulation_time_in_pieces_equals_direct_count(threads, monkeypatch):
    # runs of supra-threshold excitation crossing piece boundaries, rows all above and all
    # below the threshold, and a row of pieces that is not a multiple of the chunk
    rng = np.random.default_rng(5)
    e = np.where(rng.random((6, 11 * CHUNK + 7)) < 0.93, 0.8, 0.05)
    e[1] = 0.9
    e[2] = 0.0
    e[3, : 5 * CHUNK] = 0.5
    e[4, ::CHUNK] = 0.0
    time = np.cumsum(rng.uniform(0.001, 0.002, e.shape[-1]))
    dt = (time[-1] - time[0]) / (time.size - 1)
    _many_chunks(monkeypatch, threads)
    for x in (e, e[0], e[1], e[2], e.reshape(2, 3, -1)):
        assert _same_bits(bhargava_stimulation_time_s(x, time), _stimulation_count(x, 0.1) * dt)


def test_non_finite_state_reported_first_in_argument_order(monkeypatch):
    _many_chunks(monkeypatch, 3)
    rng = np.random.default_rng(2)
    s = _states(rng, (3, 5 * CHUNK + 17), (3,))
    s["normalized_fiber_velocity"] = s["normalized_fiber_velocity"].copy()
    s["normalized_fiber_velocity"][2, 300] = np.nan
    s["activation"] = s["activation"].copy()
    s["activation"][1, 7] = np.inf
    # (the states hold negative excitation: A^0.6 of the chunks evaluated before the
    # non-finite one is found is NaN there)
    with np.errstate(invalid="ignore"), pytest.raises(
        OptionError, match=r"'activation' holds infinite values \(1 of 1011, first at index \(1, 7\)\)"
    ):
        umberger2003(**s)
    s["excitation"] = "not numeric"  # an earlier non-finite state is reported before a later conversion error
    s["activation"][1, 7] = 0.5
    with pytest.raises(OptionError, match="'excitation' must be numeric"):
        umberger2003(**s)
    s["excitation"] = np.zeros(s["activation"].shape)
    s["force_velocity_multiplier"] = "not numeric"
    with pytest.raises(OptionError, match="'normalized_fiber_velocity' holds NaN values"):
        umberger2003(**s)


@pytest.mark.parametrize("name", ["BH04", "UC16", "HO06", "LW07"])
def test_non_finite_large_state_found_during_evaluation(monkeypatch, name):
    # large states are checked chunk by chunk while the model is evaluated: every state, the
    # ones a model does not use included, gives the same error as the check before evaluation
    _many_chunks(monkeypatch, 2)
    rng = np.random.default_rng(3)
    base = _states(rng, (3, 5 * CHUNK + 17), (3,))
    base["excitation"] = np.abs(base["excitation"])  # no NaN of the model's own making
    base["activation"] = np.maximum(base["activation"], base["excitation"])
    extra = {"time_s": np.arange(base["excitation"].shape[-1]) * 0.01} if name == "BH04" else {}
    for state in STATE_ARGUMENTS:
        for value, kind in ((np.nan, "NaN"), (-np.inf, "infinite")):
            s = dict(base)
            s[state] = s[state].copy()
            s[state][2, 4 * CHUNK + 5] = value
            with pytest.raises(OptionError, match=rf"'{state}' holds {kind} values \(1 of .*index \(2, {4 * CHUNK + 5}\)"):
                MODELS[name](**s, **extra)
            with np.errstate(all="raise"), pytest.raises(OptionError, match=f"'{state}' holds {kind}"):
                MODELS[name](**s, **extra)


def test_callers_floating_point_settings_apply_in_threads(monkeypatch):
    # negative excitation below activation gives a negative blend and NaN from A^0.6
    _many_chunks(monkeypatch, 3)
    rng = np.random.default_rng(3)
    s = _states(rng, (2, 4 * CHUNK + 1), (2,))
    s["excitation"] = np.full(s["excitation"].shape, -0.5)
    s["activation"] = np.full(s["activation"].shape, 0.1)
    with np.errstate(invalid="raise"), pytest.raises(FloatingPointError):
        umberger2003(**s)
    with np.errstate(invalid="ignore"):
        r = umberger2003(**s)
    assert np.isnan(r.activation_maintenance).all()


def test_recruitment_terms_are_the_sine_and_one_minus_cosine():
    # the half-angle forms against math.sin and 1 - cos = 2 sin^2(x/2) (no cancellation),
    # including excitation outside [-1, 1]; the in-place form gives the same bits
    e = np.concatenate([np.linspace(-1.5, 1.5, 3001), [0.0, -0.0, 1.0, -1.0, 1e-9, 0.1, 0.999999]])
    u_s, u_f = _common.recruitment_terms(e)
    x = [0.5 * math.pi * v for v in e]
    np.testing.assert_allclose(u_s, [math.sin(v) for v in x], rtol=2e-15, atol=0)
    np.testing.assert_allclose(u_f, [2.0 * math.sin(0.5 * v) ** 2 for v in x], rtol=2e-15, atol=0)
    e = np.append(e, np.nan)
    u_s, u_f = _common.recruitment_terms(e)
    t, got_s, tmp = np.empty_like(e), np.empty_like(e), np.empty_like(e)
    _common.recruitment_terms_into(e, t, got_s, tmp)
    assert _same_bits(got_s, u_s) and _same_bits(t * got_s, u_f)


def test_in_place_recruited_fraction_equals_the_array_formula():
    from musclemetab.metabolics.umberger import _recruited_slow_twitch_fraction, _recruited_slow_twitch_fraction_into

    e = np.concatenate([np.linspace(-1.5, 1.5, 3001), [0.0, -0.0, 1.0, 2.0, -2.0]])
    for f_st in (np.array(0.0), np.array(0.6), np.array(1.0)):
        expected = _recruited_slow_twitch_fraction(e, f_st)
        got, tmp, mask = np.empty_like(e), np.empty_like(e), np.empty(e.shape, np.int64)
        _recruited_slow_twitch_fraction_into(e, f_st, got, tmp, mask)
        assert _same_bits(got, expected), float(f_st)

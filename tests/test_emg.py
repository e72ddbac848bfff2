"""EMG processing: filter responses against the Butterworth formulas and SciPy's
frequency response, zero lag, rectification/normalisation, channel mapping on the
example data, and input errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.signal import freqz

from musclemetab.emg import (
    AUTHORS_EMG_MAPPING,
    DEFAULT_EMG_MAPPING,
    butterworth,
    emg_at,
    lowpass,
    bandpass,
    map_channels,
    normalise,
    process_raw_emg,
    read_processed_emg,
    rectify,
    require_window,
    sample_rate_hz,
    shift_time,
    zero_lag_gain,
)
from musclemetab.errors import DataMismatchError, MissingColumnError, OptionError


def _table(t, **cols):
    return pd.DataFrame(cols, index=pd.Index(t, name="time"))


def _measured_gain(filter_fn, f, fs, **kw):
    """Steady-state amplitude ratio of a sine through a zero-lag filter (middle of a 10 s record)."""
    t = np.arange(0, 10, 1 / fs)
    x = np.sin(2 * np.pi * f * t)
    y = filter_fn(_table(t, x=x), fs_hz=fs, **kw)["x"].to_numpy()
    mid = slice(len(t) // 4, 3 * len(t) // 4)
    return np.sqrt(2 * np.mean(y[mid] ** 2))


@pytest.mark.parametrize("f, expected", [(1.0, 1.0), (6.0, 0.5), (24.0, 1 / 257)])
def test_lowpass_gain_matches_butterworth(f, expected):
    # effective 4th order: |H|^2 of a 2nd-order Butterworth: 1/(1 + (f/fc)^4) (analogue values)
    fs = 1000.0
    g = _measured_gain(lowpass, f, fs)
    assert g == pytest.approx(zero_lag_gain(f, fs, 6.0, "lowpass"), abs=2e-3)
    assert g == pytest.approx(expected, rel=0.02, abs=2e-3)


def test_analytic_gain_equals_scipy_frequency_response():
    fs = 2000.0
    f = np.array([5.0, 10.0, 20.0, 60.0, 200.0, 400.0, 600.0, 900.0])
    for order, means in ((4, "effective"), (4, "design"), (2, "effective")):
        b, a = butterworth((20, 400), fs, "bandpass", order, means)
        _, h = freqz(b, a, worN=f, fs=fs)
        np.testing.assert_allclose(np.abs(h) ** 2, zero_lag_gain(f, fs, (20, 400), "bandpass", order, means),
                                   rtol=1e-6, atol=1e-12)
        b, a = butterworth(6.0, 1000.0, "lowpass", order, means)
        _, h = freqz(b, a, worN=f / 20, fs=1000.0)
        np.testing.assert_allclose(np.abs(h) ** 2, zero_lag_gain(f / 20, 1000.0, 6.0, "lowpass", order, means),
                                   rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("f", [5.0, 20.0, 90.0, 400.0, 700.0])
def test_bandpass_gain(f):
    fs = 2000.0
    g = _measured_gain(bandpass, f, fs)
    expected = zero_lag_gain(f, fs, (20, 400), "bandpass")
    assert g == pytest.approx(expected, abs=3e-3)
    if f in (20.0, 400.0):
        assert g == pytest.approx(0.5, abs=3e-3)  # -6 dB at both edges
    if f == 90.0:
        assert g > 0.99
    if f in (5.0, 700.0):
        assert g < 0.07


def test_design_order_reading_is_steeper():
    fs = 1000.0
    g_eff = _measured_gain(lowpass, 12.0, fs)
    g_des = _measured_gain(lowpass, 12.0, fs, order_means="design")
    assert g_eff == pytest.approx(1 / 17, rel=0.03)  # 1/(1+2^4)
    assert g_des == pytest.approx(1 / 257, rel=0.05)  # 1/(1+2^8)
    with pytest.raises(OptionError, match="even"):
        lowpass(_table(np.arange(0, 1, 1e-3), x=np.zeros(1000)), order=3)


def test_zero_phase_lag():
    fs = 1000.0
    rng = np.random.default_rng(1)
    t = np.arange(0, 5, 1 / fs)
    x = rng.standard_normal(t.size)
    for fn in (lowpass, bandpass):
        y = fn(_table(t, x=x), fs_hz=fs)["x"].to_numpy()
        lags = np.arange(-50, 51)
        xc = [np.dot(y[100 + k: -100 + k], x[100:-100]) for k in lags]
        assert lags[int(np.argmax(xc))] == 0
    # a symmetric pulse stays centred
    pulse = np.exp(-0.5 * ((t - 2.5) / 0.1) ** 2)
    y = lowpass(_table(t, x=pulse))["x"].to_numpy()
    assert t[np.argmax(y)] == pytest.approx(2.5, abs=1 / fs)


def test_rectification_and_peak_normalisation_recover_envelope():
    fs = 2000.0
    t = np.arange(0, 6, 1 / fs)
    ramp = np.clip(np.minimum(t, t[-1] - t) / 0.5, 0, 1) ** 2  # smooth start and end: no edge ringing
    amplitude = 1.0 + 0.5 * np.sin(2 * np.pi * 0.5 * t)  # slow envelope, well below 6 Hz
    raw = _table(t, ch=ramp * amplitude * np.sin(2 * np.pi * 100 * t), flat=ramp * 0.3 * np.sin(2 * np.pi * 150 * t))
    r = rectify(raw)
    np.testing.assert_array_equal(r.to_numpy(), np.abs(raw.to_numpy()))
    env = process_raw_emg(raw)
    assert env.max().to_numpy() == pytest.approx([1.0, 1.0])
    mid = (t > 1) & (t < 5)
    assert env["ch"].to_numpy()[mid].max() == pytest.approx(1.0, abs=0.005)  # the peak is the envelope's
    # mean of |A sin| is 2A/pi; normalised by the peak it is A / max(A) = A / 1.5
    np.testing.assert_allclose(env["ch"].to_numpy()[mid], amplitude[mid] / 1.5, atol=0.01)
    np.testing.assert_allclose(env["flat"].to_numpy()[mid], 1.0, atol=0.01)


def test_normalisation_to_given_maximum_and_range_errors():
    fs = 2000.0
    t = np.arange(0, 3, 1 / fs)
    raw = _table(t, A=np.sin(2 * np.pi * 100 * t), B=2 * np.sin(2 * np.pi * 100 * t))
    env = process_raw_emg(raw, maximum={"A": 2 / np.pi * 2, "B": 2 / np.pi * 2})
    mid = (t > 0.5) & (t < 2.5)
    np.testing.assert_allclose(env["A"].to_numpy()[mid], 0.5, atol=0.005)
    np.testing.assert_allclose(env["B"].to_numpy()[mid], 1.0, atol=0.01)
    with pytest.raises(DataMismatchError, match=r"channel B .*outside \[0, 1\]"):
        process_raw_emg(raw, maximum={"A": 1.27, "B": 1.0})  # B's envelope is 1.27 > 1.1
    with pytest.raises(OptionError, match="channel B"):
        normalise(raw, {"A": 1.0})
    with pytest.raises(OptionError, match="positive"):
        normalise(raw, {"A": 1.0, "B": 0.0})
    with pytest.raises(DataMismatchError, match="never rise above zero"):
        normalise(_table(t, Z=np.zeros_like(t)))


def test_nyquist_and_sampling_errors():
    t = np.arange(0, 2, 1 / 500.0)
    raw = _table(t, TA=np.sin(2 * np.pi * 50 * t))
    with pytest.raises(DataMismatchError, match=r"above 800 Hz \(Nyquist\).*500 Hz"):
        process_raw_emg(raw)
    t2 = np.sort(np.r_[np.arange(0, 1, 1e-3), 0.5005])
    with pytest.raises(DataMismatchError, match="not evenly spaced"):
        process_raw_emg(_table(t2, TA=np.sin(t2)))
    # 1500 Hz written with four decimals (steps of 0.6 and 0.7 ms): the rounded stamps of that rate
    t3 = np.round(np.arange(0, 2, 1 / 1500.0), 4)
    assert set(np.round(np.diff(t3), 6)) == {0.0006, 0.0007}
    assert sample_rate_hz(_table(t3, TA=np.sin(t3))) == pytest.approx(1500.0, rel=1e-5)
    bad = _table(np.arange(0, 1, 1e-3), TA=np.r_[np.nan, np.zeros(999)])
    with pytest.raises(DataMismatchError, match="TA hold NaN"):
        process_raw_emg(bad)
    with pytest.raises(MissingColumnError, match="XX"):
        process_raw_emg(raw, channels=["TA", "XX"])


def test_processed_envelopes_given_as_raw_emg_are_refused():
    """A slow envelope (1 Hz and 2 Hz) keeps almost nothing of its variation above 10 Hz (the
    zero-lag 4th-order high-pass passes about (2/10)^8 = 3e-6 of it at 2 Hz); a 100 Hz carrier under
    the same envelope (raw EMG) keeps most of it: the first is refused naming the channel and the
    remedy, the second is processed."""
    fs = 1000.0
    t = np.arange(0, 3, 1 / fs)
    envelope = 0.5 + 0.3 * np.sin(2 * np.pi * 1.0 * t) + 0.1 * np.sin(2 * np.pi * 2.0 * t)
    with pytest.raises(DataMismatchError, match=r"EMG channel ENV keep little of their variation above 10 Hz "
                                                r"\(ENV 0\.\d %; .*look like processed envelopes.*"
                                                r"--emg-processing envelope"):
        process_raw_emg(_table(t, ENV=envelope))
    env = process_raw_emg(_table(t, RAW=envelope * np.sin(2 * np.pi * 100 * t)))
    assert env["RAW"].max() == pytest.approx(1.0)


def test_electromechanical_delay_shifts_time():
    t = np.arange(0, 2, 1 / 2000.0)
    raw = _table(t, TA=np.sin(2 * np.pi * 100 * t))
    a = process_raw_emg(raw)
    b = process_raw_emg(raw, delay_s=0.04)
    np.testing.assert_allclose(b.index.to_numpy(), a.index.to_numpy() + 0.04)
    np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())
    with pytest.raises(OptionError):
        shift_time(a, -0.01)


def test_example_vastus_intermedius_is_mean_of_vasti(example):
    emg = read_processed_emg(example.emg["normal"])
    vi_default = map_channels(emg, DEFAULT_EMG_MAPPING)["vasint_r"].to_numpy()
    vi_mean = map_channels(emg, {"vasint_r": ["VL", "VM"]})["vasint_r"].to_numpy()
    np.testing.assert_allclose(vi_default, vi_mean, atol=1e-9)
    np.testing.assert_allclose(vi_default, 0.5 * (emg["VL"] + emg["VM"]).to_numpy(), atol=1e-9)
    authors = map_channels(emg, AUTHORS_EMG_MAPPING)
    np.testing.assert_array_equal(authors["vasint_r"].to_numpy(), emg["ES"].to_numpy())
    assert list(authors.columns) == list(DEFAULT_EMG_MAPPING)
    for m in ("bflh_r", "soleus_r", "tibant_r"):
        np.testing.assert_array_equal(authors[m].to_numpy(), emg[DEFAULT_EMG_MAPPING[m][0]].to_numpy())
    # the processed file is read as stored, 1000 Hz from 0.040 s
    assert emg.index[0] == pytest.approx(0.040)
    assert 1 / np.mean(np.diff(emg.index)) == pytest.approx(1000.0, rel=1e-6)


def test_mapping_errors_name_channels(example):
    emg = read_processed_emg(example.emg["normal"])
    with pytest.raises(MissingColumnError) as err:
        map_channels(emg, {"vasint_r": ["VL", "VX"], "soleus_r": "SOL"})
    msg = str(err.value)
    assert "VX" in msg and "SOL" in msg and "vasint_r" in msg and "EMG_sub1_normal.mot" in msg
    with pytest.raises(OptionError, match="soleus_r"):
        map_channels(emg, {"soleus_r": []})


def test_time_window(example):
    emg = read_processed_emg(example.emg["normal"])
    require_window(emg, 0.5, 2.0)
    with pytest.raises(DataMismatchError, match=r"covers 0.04-2.499 s, not the requested window 0-1 s"):
        require_window(emg, 0.0, 1.0)
    with pytest.raises(DataMismatchError):
        emg_at(emg, [1.0, 3.0])
    at = emg_at(emg, emg.index[[10, 20]])
    np.testing.assert_allclose(at.to_numpy(), emg.iloc[[10, 20]].to_numpy())


def test_signed_raw_emg_with_offset_and_drift_gives_its_envelope():
    """Raw EMG is signed, and recordings start and end anywhere: a 100 Hz carrier whose amplitude
    A(t) is known by construction, on a DC offset three times its amplitude and a 0.5 Hz drift
    (movement artefact). The mean of |A sin| is 2A/pi, so the normalised envelope is A / max(A):
    recovered to 0.1 % away from the ends and 6 % at the ends (the low-pass of a signal sloping at
    the edge of the record), at 1 and 2 kHz; values stay within [0, 1]. Amplitude-modulated noise
    gives an envelope following A too (its own fluctuation aside)."""
    for fs in (1000.0, 2000.0):
        t = np.arange(0, 3, 1 / fs)
        amplitude = 0.5 + 0.4 * np.sin(2 * np.pi * t + 0.3)
        raw = amplitude * np.sin(2 * np.pi * 100 * t + 0.7) - 3.0 + 0.5 * np.sin(2 * np.pi * 0.5 * t)
        assert raw.min() < 0 < raw.max() + 3.0
        env = process_raw_emg(_table(t, TA=raw))["TA"].to_numpy()
        expected = amplitude / amplitude.max()
        inner = (t > 0.2) & (t < t[-1] - 0.2)
        np.testing.assert_allclose(env[inner], expected[inner], atol=1e-3)
        np.testing.assert_allclose(env, expected, atol=0.06)
        assert 0 <= env.min() and env.max() == pytest.approx(1.0)
        noise = amplitude * np.random.default_rng(7).standard_normal(t.size) - 2.0
        env = process_raw_emg(_table(t, TA=noise))["TA"].to_numpy()
        assert np.corrcoef(env[inner], amplitude[inner])[0, 1] > 0.8


def test_every_raw_processing_step_is_an_option(example, tmp_path, capsys):
    """Raw EMG processed with other settings than the defaults, by the command line and in a study,
    against answers worked from the filter formulas: two channels, a 100 Hz and a 30 Hz carrier of
    known amplitude A(t) on a DC offset. The envelope of |A sin| is 2A/pi times the band-pass gain
    at the carrier's frequency; normalised to a given maximum (a CSV file) it keeps that scale, and
    a 50-400 Hz band-pass passes the 100 Hz channel (gain ~1) and cuts the 30 Hz one (gain
    :func:`zero_lag_gain` at 30 Hz). The delay shifts the time axis by itself."""
    import json
    import pickle

    from musclemetab.commands import main
    from musclemetab.emg import EmgProcessing, RawEmgPath, emg_source, processing_record
    from musclemetab.io import read_storage, write_storage
    from musclemetab.study.spec import study_from_dict

    fs = 2000.0
    t = np.arange(0, 3, 1 / fs)
    amplitude = 0.5 + 0.4 * np.sin(2 * np.pi * t + 0.3)
    raw = _table(t, FAST=amplitude * np.sin(2 * np.pi * 100 * t) + 1.0, SLOW=amplitude * np.sin(2 * np.pi * 30 * t) - 2.0)
    write_storage(tmp_path / "raw.sto", raw)
    (tmp_path / "max.csv").write_text("channel,maximum\nFAST,1.0\nSLOW,1.0\n")
    argv = ["emg", str(tmp_path / "raw.sto"), "--emg-band", "50:400", "--emg-maximum", str(tmp_path / "max.csv"),
            "--emg-delay", "0.05", "--emg-lowpass", "5", "--out", str(tmp_path / "out")]
    assert main(argv) == 0
    env = read_storage(tmp_path / "out" / "raw_envelopes.sto")
    np.testing.assert_allclose(env.index.to_numpy(), t + 0.05, atol=1e-9)
    inner = (t > 0.3) & (t < t[-1] - 0.3)
    envelope = 2 * amplitude / np.pi
    # to 6e-3 (0.6 % of the channel's scale; the default band and low-pass give the same 5e-3 with a
    # given maximum: the envelope of a rectified modulated carrier)
    np.testing.assert_allclose(env["FAST"].to_numpy()[inner], envelope[inner] * zero_lag_gain(100, fs, (50, 400),
                                                                                                "bandpass"), atol=6e-3)
    cut = float(zero_lag_gain(30, fs, (50, 400), "bandpass"))
    assert 0.05 < cut < 0.5
    np.testing.assert_allclose(env["SLOW"].to_numpy()[inner], envelope[inner] * cut, atol=6e-3 * cut)
    record = json.loads((tmp_path / "out" / "raw_envelopes.json").read_text())
    assert record["processing"]["band_hz"] == [50.0, 400.0] and record["processing"]["maximum"] == {"FAST": 1.0,
                                                                                                      "SLOW": 1.0}
    # the same settings on solve's --emg give the same envelopes: the settings ride with the path
    settings = EmgProcessing(band_hz=(50, 400), lowpass_hz=5.0, maximum={"FAST": 1.0, "SLOW": 1.0}, delay_s=0.05)
    marked = emg_source(tmp_path / "raw.sto", settings)
    assert isinstance(marked, RawEmgPath) and pickle.loads(pickle.dumps(marked)).processing == settings
    from musclemetab.emg import read_emg

    np.testing.assert_allclose(read_emg(marked).to_numpy(), env.to_numpy(), atol=1e-9)
    assert processing_record(marked) == {"band_hz": [50.0, 400.0], "lowpass_hz": 5.0,
                                         "maximum": {"FAST": 1.0, "SLOW": 1.0}, "delay_s": 0.05}
    assert processing_record(emg_source(tmp_path / "raw.sto", "raw")) == "raw"  # the defaults: earlier records
    assert EmgProcessing.from_record(processing_record(marked)) == settings
    # a study's emg_processing table
    data = {"name": "s", "workflows": ["effort-gen"], "models": ["UM10"],
            "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": 72.6,
                          "emg_processing": {"band_hz": [50, 400], "lowpass_hz": 5},
                          "trials": [{"name": "normal", "ik": str(example.ik["normal"]), "id": str(example.id["normal"]),
                                      "emg": str(tmp_path / "raw.sto")}]}]}
    trial = study_from_dict(data, base=tmp_path, output=tmp_path / "study").subjects[0].trials[0]
    assert trial.emg.processing == EmgProcessing(band_hz=(50, 400), lowpass_hz=5.0)
    data["subjects"][0]["emg_processing"] = {"bandpass": [50, 400]}
    with pytest.raises(OptionError, match="unknown raw-EMG setting.*bandpass"):
        study_from_dict(data, base=tmp_path, output=tmp_path / "study")
    # settings of raw EMG given for envelopes: one line, nothing solved
    capsys.readouterr()
    assert main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                 str(example.id["normal"]), "--emg", str(example.emg["normal"]), "--emg-band", "10:450",
                 "--out", str(tmp_path / "solve")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--emg-band" in err[0] and "--emg-processing raw" in err[0]
    with pytest.raises(OptionError, match="LOW < HIGH"):
        EmgProcessing(band_hz=(400, 20))

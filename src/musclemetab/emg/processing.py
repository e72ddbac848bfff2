"""EMG processing: raw EMG to normalised envelopes, and channels to model muscles.

Raw EMG (one column per channel, volts or any unit, time-indexed DataFrame as returned by
:func:`musclemetab.io.read_storage`) becomes a normalised envelope by

1. zero-lag Butterworth band-pass 20-400 Hz (removes movement artefact and
   high-frequency noise),
2. full-wave rectification ``|x|``,
3. zero-lag Butterworth low-pass 6 Hz (linear envelope),
4. normalisation ``e = x / x_max`` per channel, ``x_max`` a given maximum (e.g. the
   envelope peak of a maximal voluntary contraction, in the same processing) or the
   trial's own peak,
5. optionally an electromechanical delay: the time axis is shifted by ``+delay_s``, so
   the EMG sampled at ``t`` drives the muscle at ``t + delay_s``.

**Filter order convention.** "4th-order zero-lag" is read as the *effective* order after
forward-backward filtering (the usual convention in biomechanics): a 2nd-order Butterworth
is designed and run forward and backward (``scipy.signal.filtfilt``), so the amplitude
response is the square of the design's,

    |H_ff(f)| = |H(f)|^2 = 1 / (1 + (W(f)/W(fc))^(2 n)),   W(f) = tan(pi f / fs),

``n`` = design order = effective order / 2 (digital Butterworth by bilinear transform),
giving -6 dB (gain 0.5) at the cut-off and no phase lag. For the band-pass, ``n`` is the
order of each edge (``scipy.signal.butter(n, [f1, f2], 'bandpass')``, a polynomial of
order ``2 n``) and ``W(f)/W(fc)`` becomes ``(W^2 - W1 W2) / (W (W2 - W1))``.
``order_means='design'`` selects the other reading (a 4th-order design run
forward-backward, effective 8th order).

Padding at the ends follows MATLAB's ``filtfilt``: odd reflection of
``3 (max(len(a), len(b)) - 1)`` samples with steady-state initial conditions. The envelope's
low-pass (step 3) is the exception: the rectified signal is not odd about its end values (an
odd reflection of ``|x|`` about a small end value is negative, and drove the envelope of a
signed raw record below zero at its ends), so it is extended by its mirror image (even
reflection) over one period of the cut-off, ``round(fs / 6 Hz)`` samples. On a 100 Hz carrier
of known amplitude, on a DC offset and a drift, the normalised envelope is the amplitude's to
0.1 % away from the ends and 6 % at them (``tests/test_emg.py``).

**Defaults and sources.** Band-pass 20-400 Hz, full-wave rectification and a 6 Hz low-pass
(effective 4th order, zero lag) are the processing of the reference study's EMG (Luis et al.
2024, ``docs/method.md``); 20 Hz removes movement artefact and 400 Hz lies below the Nyquist
frequency of the usual 1-2 kHz recordings, as the SENIAM recommendations (Hermens et al. 2000,
J Electromyogr Kinesiol 10:361-374) and De Luca (1997, J Appl Biomech 13:135-163) advise; the
6 Hz linear envelope is the usual gait envelope (Winter 2009, Biomechanics and Motor Control
of Human Movement, 4th ed.). The normalisation defaults to the trial's own peak; give
``maximum`` (the envelope peak of a maximal voluntary contraction) when one was recorded.

**Files.** :func:`read_emg` reads an EMG file (a ``.sto``/``.mot`` table, or a C3D file's analog
channels other than the force plates') as processed envelopes (``"envelope"``, the
default: used as stored) or as raw EMG processed here with these defaults (``"raw"``), the
``--emg-processing`` option of ``musclemetab solve`` and ``estimate`` and the study file's
``emg_processing`` key. :func:`emg_source` marks a path with its processing
(:class:`RawEmgPath` for raw EMG), so that every reader of the trial's EMG processes it alike.

**Range check.** A low-pass filtered rectified signal rings: Butterworth step responses
overshoot, so an envelope under- or overshoots by a fraction of any abrupt change of
amplitude (for a unit step: 3.4 % with the effective 4th order, 6.8 % with a 4th-order
design run forward-backward), plus end effects of the padding. After normalisation every
value must therefore lie in ``[-tol, 1 + tol]`` with
``tol = EMG_RANGE_TOLERANCE = 0.10`` (10 % of the normalising amplitude, above both
overshoots); otherwise :class:`~musclemetab.errors.DataMismatchError` names the channel, the
value and its time (a larger excess means a wrong maximum, a wrong unit or a broken
channel). Processed envelopes read from file (:func:`read_processed_emg`) are used as
stored and not range-checked: the example subject's files hold values down to about -0.2.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataMismatchError, InputFileError, MissingColumnError, OptionError
from ..messages import name_list

__all__ = [
    "BANDPASS_HZ",
    "LOWPASS_HZ",
    "FILTER_ORDER",
    "EMG_RANGE_TOLERANCE",
    "DEFAULT_EMG_MAPPING",
    "AUTHORS_EMG_MAPPING",
    "EMG_TRACKED_MUSCLES",
    "sample_rate_hz",
    "butterworth",
    "zero_lag_filter",
    "bandpass",
    "lowpass",
    "rectify",
    "normalise",
    "shift_time",
    "process_raw_emg",
    "read_processed_emg",
    "EMG_PROCESSING",
    "EmgProcessing",
    "RawEmgPath",
    "emg_source",
    "processing_record",
    "read_emg",
    "read_emg_signals",
    "map_channels",
    "require_window",
    "emg_at",
    "zero_lag_gain",
]

BANDPASS_HZ = (20.0, 400.0)
LOWPASS_HZ = 6.0
FILTER_ORDER = 4  # effective order of each zero-lag filter (see module docstring)
EMG_RANGE_TOLERANCE = 0.10
_ORDER_MEANINGS = ("effective", "design")

#: Muscles whose EMG is tracked in the study (right leg).
EMG_TRACKED_MUSCLES = (
    "bflh_r", "semiten_r", "vaslat_r", "vasmed_r", "tibant_r", "gaslat_r", "gasmed_r", "soleus_r", "vasint_r",
)

#: Channel mapping of the example data as intended by the study: vastus intermedius is
#: the mean of vastus lateralis and medialis, stored as channel ``VI_a``.
DEFAULT_EMG_MAPPING: dict[str, list[str]] = {
    "bflh_r": ["BF"],
    "semiten_r": ["ST"],
    "vaslat_r": ["VL"],
    "vasmed_r": ["VM"],
    "tibant_r": ["TA"],
    "gaslat_r": ["GL"],
    "gasmed_r": ["GM"],
    "soleus_r": ["SO"],
    "vasint_r": ["VI_a"],
}

#: The mapping the published example results were computed with: the reference code
#: renames columns by position, which assigns channel ``ES`` to the vastus intermedius.
AUTHORS_EMG_MAPPING: dict[str, list[str]] = {**DEFAULT_EMG_MAPPING, "vasint_r": ["ES"]}


def _source(df: pd.DataFrame) -> str:
    return str(df.attrs.get("path", "<EMG table>"))


def sample_rate_hz(df: pd.DataFrame) -> float:
    """Sampling rate (Hz) of a time-indexed table, which must be sampled at a constant rate;
    time stamps rounded from one (e.g. to the millisecond) are accepted
    (:func:`musclemetab.io.constant_rate`: the rate is their least-squares fit)."""
    from ..io import constant_rate

    return constant_rate(df.index, f"{_source(df)}: EMG")[1]


def _design_order(order: int, order_means: str) -> int:
    if order_means not in _ORDER_MEANINGS:
        raise OptionError(f"order_means must be 'effective' or 'design', not {order_means!r}")
    if not isinstance(order, (int, np.integer)) or order < 1:
        raise OptionError(f"filter order must be a positive integer, not {order!r}")
    if order_means == "effective":
        if order % 2:
            raise OptionError(
                f"an effective zero-lag order of {order} is impossible: forward-backward filtering doubles "
                "the design order, so give an even order (or order_means='design')"
            )
        return order // 2
    return int(order)


def butterworth(cutoff_hz, fs_hz: float, btype: str, order: int = FILTER_ORDER, order_means: str = "effective"):
    """Coefficients ``(b, a)`` of the Butterworth design behind a zero-lag filter.

    Raises :class:`DataMismatchError` when a cut-off is not below the Nyquist frequency
    ``fs/2`` and :class:`OptionError` for impossible cut-offs or orders.
    """
    from scipy.signal import butter

    n = _design_order(order, order_means)
    fc = np.atleast_1d(np.asarray(cutoff_hz, dtype=float))
    if np.any(fc <= 0) or (fc.size == 2 and not fc[0] < fc[1]):
        raise OptionError(f"cut-off frequencies {list(fc)} Hz must be positive and increasing")
    nyq = fs_hz / 2.0
    if np.any(fc >= nyq):
        raise DataMismatchError(
            f"a {btype} filter with cut-off {'-'.join(f'{f:g}' for f in fc)} Hz needs a sampling rate above "
            f"{2 * fc.max():g} Hz (Nyquist); the signal is sampled at {fs_hz:g} Hz. Record or export the raw "
            "EMG at a higher rate, or lower the cut-off"
        )
    wn = fc / nyq
    return butter(n, wn if wn.size == 2 else float(wn[0]), btype=btype)


def zero_lag_filter(x: np.ndarray, b, a, what: str = "signal", padtype: str = "odd",
                    padlen: int | None = None) -> np.ndarray:
    """Forward-backward filtering along axis 0 with end padding: MATLAB-style by default
    (odd reflection of ``3 (max(len(a), len(b)) - 1)`` samples), else ``padtype`` and
    ``padlen`` as ``scipy.signal.filtfilt`` takes them."""
    from scipy.signal import filtfilt

    x = np.asarray(x, dtype=float)
    padlen = 3 * (max(len(a), len(b)) - 1) if padlen is None else int(padlen)
    if x.shape[0] <= padlen:
        raise DataMismatchError(
            f"{what} has {x.shape[0]} samples, too short for the zero-lag filter (needs more than {padlen})"
        )
    return filtfilt(b, a, x, axis=0, padtype=padtype, padlen=padlen)


def zero_lag_gain(f_hz, fs_hz: float, cutoff_hz, btype: str, order: int = FILTER_ORDER,
                  order_means: str = "effective") -> np.ndarray:
    """Analytic amplitude response of the zero-lag Butterworth filter (module docstring)."""
    n = _design_order(order, order_means)
    W = np.tan(np.pi * np.asarray(f_hz, dtype=float) / fs_hz)
    fc = np.atleast_1d(np.asarray(cutoff_hz, dtype=float))
    Wc = np.tan(np.pi * fc / fs_hz)
    if btype == "lowpass":
        ratio = W / Wc[0]
    elif btype == "highpass":
        ratio = Wc[0] / W
    elif btype == "bandpass":
        ratio = (W**2 - Wc[0] * Wc[1]) / (W * (Wc[1] - Wc[0]))
    else:
        raise OptionError(f"btype must be lowpass, highpass or bandpass, not {btype!r}")
    return 1.0 / (1.0 + ratio ** (2 * n))


def _filter_df(df: pd.DataFrame, cutoff, btype: str, order: int, order_means: str, fs_hz: float | None,
               **padding):
    fs = sample_rate_hz(df) if fs_hz is None else float(fs_hz)
    b, a = butterworth(cutoff, fs, btype, order, order_means)
    y = zero_lag_filter(df.to_numpy(dtype=float), b, a, what=f"{_source(df)}: EMG", **padding)
    out = pd.DataFrame(y, index=df.index, columns=df.columns)
    out.attrs.update(df.attrs)
    return out


def bandpass(df: pd.DataFrame, band_hz=BANDPASS_HZ, order: int = FILTER_ORDER, order_means: str = "effective",
             fs_hz: float | None = None) -> pd.DataFrame:
    """Zero-lag Butterworth band-pass of every column."""
    return _filter_df(df, band_hz, "bandpass", order, order_means, fs_hz)


def lowpass(df: pd.DataFrame, cutoff_hz: float = LOWPASS_HZ, order: int = FILTER_ORDER,
            order_means: str = "effective", fs_hz: float | None = None) -> pd.DataFrame:
    """Zero-lag Butterworth low-pass of every column."""
    return _filter_df(df, cutoff_hz, "lowpass", order, order_means, fs_hz)


def rectify(df: pd.DataFrame) -> pd.DataFrame:
    """Full-wave rectification ``|x|``."""
    out = df.abs()
    out.attrs.update(df.attrs)
    return out


def normalise(df: pd.DataFrame, maximum: str | Mapping[str, float] = "peak") -> pd.DataFrame:
    """Divide each channel by its maximum: ``'peak'`` (the trial's own peak) or a mapping
    channel -> maximum (e.g. the MVC envelope peak, same units and processing)."""
    if isinstance(maximum, str):
        if maximum != "peak":
            raise OptionError(f"normalisation must be 'peak' or a mapping channel -> maximum, not {maximum!r}")
        peak = df.max(axis=0)
        bad = [c for c in df.columns if not peak[c] > 0]
        if bad:
            raise DataMismatchError(
                f"{_source(df)}: EMG channel{'s' if len(bad) > 1 else ''} {name_list(bad)} "
                "never rise above zero; cannot normalise to the trial's peak (check the channel)"
            )
        scale = peak
    else:
        missing = [c for c in df.columns if c not in maximum]
        if missing:
            raise OptionError(
                f"no normalisation maximum for EMG channel{'s' if len(missing) > 1 else ''} "
                f"{name_list(missing)}; give one per channel (or use 'peak')"
            )
        bad = [c for c in df.columns if not (np.isfinite(float(maximum[c])) and float(maximum[c]) > 0)]
        if bad:
            raise OptionError(
                f"normalisation maximum must be positive; it is not for channel{'s' if len(bad) > 1 else ''} "
                f"{name_list(bad)}"
            )
        scale = pd.Series({c: float(maximum[c]) for c in df.columns})
    out = df / scale
    out.attrs.update(df.attrs)
    return out


def shift_time(df: pd.DataFrame, delay_s: float) -> pd.DataFrame:
    """Electromechanical delay: new time = old time + ``delay_s`` (s, >= 0)."""
    if not (np.isfinite(delay_s) and delay_s >= 0):
        raise OptionError(f"electromechanical delay must be a non-negative number of seconds, not {delay_s!r}")
    out = df.copy()
    out.index = pd.Index(np.asarray(df.index, dtype=float) + float(delay_s), name=df.index.name or "time")
    out.attrs.update(df.attrs)
    return out


def _check_range(df: pd.DataFrame, tol: float) -> None:
    x = df.to_numpy(dtype=float)
    lo, hi = -tol, 1.0 + tol
    for j, c in enumerate(df.columns):
        col = x[:, j]
        bad = np.flatnonzero((col < lo) | (col > hi))
        if bad.size:
            k = bad[np.argmax(np.abs(col[bad] - 0.5))]
            raise DataMismatchError(
                f"{_source(df)}: processed EMG channel {c} is {col[k]:.3g} at t = {df.index[k]:.4g} s, outside "
                f"[0, 1] by more than the tolerance {tol:g}; check the normalisation maximum (units, same "
                "processing) and the channel's signal"
            )


def _select(df: pd.DataFrame, channels: Sequence[str] | None) -> pd.DataFrame:
    if channels is None:
        return df
    channels = list(channels)
    missing = [c for c in channels if c not in df.columns]
    if missing:
        raise MissingColumnError(
            f"{_source(df)}: missing EMG channel{'s' if len(missing) > 1 else ''} {name_list(missing)}; "
            f"the file has {name_list(df.columns)}"
        )
    out = df[channels]
    out.attrs.update(df.attrs)
    return out


#: A raw EMG channel keeps at least this share of its variation (RMS about its mean) above
#: :data:`RAW_CHECK_HZ`, whatever band it is then processed with: raw EMG lives at tens to hundreds
#: of hertz, a processed envelope below a few (the example subject's envelopes keep 3-15 % of
#: theirs, their noise), a channel without EMG (a flat line, a drift) nothing.
RAW_BAND_SHARE = 0.25
#: The high-pass (Hz, zero-lag, the package's order) of that check
RAW_CHECK_HZ = 10.0


def _check_raw(df: pd.DataFrame, fs: float) -> None:
    """:class:`DataMismatchError` naming the channels that keep less than :data:`RAW_BAND_SHARE`
    of their variation above :data:`RAW_CHECK_HZ`: processed envelopes (or no EMG), not raw EMG."""
    spread = (df - df.mean()).pow(2).mean().pow(0.5)
    fast = _filter_df(df, RAW_CHECK_HZ, "highpass", FILTER_ORDER, "effective", fs)
    kept = fast.pow(2).mean().pow(0.5) / spread.where(spread > 0)
    low = kept[kept < RAW_BAND_SHARE]
    if len(low):
        shares = ", ".join(f"{c} {100 * v:.1f} %" for c, v in list(low.items())[:3]) + (", ..." if len(low) > 3 else "")
        raise DataMismatchError(
            f"{_source(df)}: EMG channel{'s' if len(low) > 1 else ''} {name_list([str(c) for c in low.index])} keep "
            f"little of their variation above {RAW_CHECK_HZ:g} Hz ({shares}; raw EMG keeps most of it): they look "
            "like processed envelopes (or a channel without EMG), not raw EMG; use envelopes as they are (solve "
            "--emg-processing envelope, the default; a study's emg_processing = \"envelope\"), or give the raw "
            "recording")


def process_raw_emg(
    raw: pd.DataFrame,
    *,
    channels: Sequence[str] | None = None,
    band_hz: tuple[float, float] = BANDPASS_HZ,
    lowpass_hz: float = LOWPASS_HZ,
    order: int = FILTER_ORDER,
    order_means: str = "effective",
    maximum: str | Mapping[str, float] = "peak",
    delay_s: float = 0.0,
    range_tolerance: float = EMG_RANGE_TOLERANCE,
) -> pd.DataFrame:
    """Raw EMG -> normalised envelopes (band-pass, rectify, low-pass, normalise, delay).

    Parameters
    ----------
    raw
        Time-indexed table (s), one column per channel, uniformly sampled.
    channels
        Channels to process (default all); missing ones raise
        :class:`MissingColumnError` naming them.
    maximum
        ``'peak'`` or ``{channel: maximum}`` in the envelope's units.
    delay_s
        Electromechanical delay added to the time axis.
    range_tolerance
        Allowed excursion outside [0, 1] after normalisation.

    Raises
    ------
    DataMismatchError
        Sampling rate at or below twice the upper band-pass edge (Nyquist), non-uniform
        sampling, NaN values, or a result outside ``[-tol, 1 + tol]``.
    """
    df = _select(raw, channels)
    vals = df.to_numpy(dtype=float)
    if np.isnan(vals).any():
        bad = [str(c) for c in df.columns[np.isnan(vals).any(axis=0)]]
        raise DataMismatchError(f"{_source(df)}: EMG channel{'s' if len(bad) > 1 else ''} {name_list(bad)} hold NaN; "
                                "fill or remove the gaps before processing")
    fs = sample_rate_hz(df)
    _check_raw(df, fs)
    y = bandpass(df, band_hz, order, order_means, fs)
    y = rectify(y)
    # the rectified signal is not odd about its end values: mirrored (even reflection) over one
    # period of the cut-off, so that the padding is a rectified signal too (module docstring)
    y = _filter_df(y, lowpass_hz, "lowpass", order, order_means, fs, padtype="even",
                   padlen=min(len(y) - 1, int(round(fs / lowpass_hz))))
    y = normalise(y, maximum)
    _check_range(y, float(range_tolerance))
    if delay_s:
        y = shift_time(y, delay_s)
    y.attrs["processing"] = dict(
        band_hz=list(band_hz), lowpass_hz=lowpass_hz, order=order, order_means=order_means,
        maximum="peak" if isinstance(maximum, str) else {k: float(v) for k, v in maximum.items()},
        delay_s=float(delay_s), fs_hz=fs,
    )
    return y


#: How an EMG file is read (:func:`read_emg`): processed envelopes as stored, or raw EMG
EMG_PROCESSING = ("envelope", "raw")


@dataclass(frozen=True)
class EmgProcessing:
    """The settings of :func:`process_raw_emg` a raw EMG file is processed with, every step an
    option: the band-pass edges (Hz), the envelope's low-pass cut-off (Hz), the filters' order
    and what it means (``"effective"`` or ``"design"``, module docstring), the normalisation
    (``"peak"``: each channel's own peak; or ``{channel: maximum}`` in the envelope's units, e.g.
    the envelope peaks of maximal voluntary contractions) and the electromechanical delay (s).
    The defaults are the module's (band-pass 20-400 Hz, low-pass 6 Hz, 4th order, peak, no delay).

    :meth:`record` is ``"raw"`` for the defaults and the changed settings otherwise;
    :meth:`from_record` reads either back (``"raw"``, a mapping of these names)."""

    band_hz: tuple[float, float] = BANDPASS_HZ
    lowpass_hz: float = LOWPASS_HZ
    order: int = FILTER_ORDER
    order_means: str = "effective"
    maximum: object = "peak"
    delay_s: float = 0.0

    def __post_init__(self):
        band = tuple(float(x) for x in self.band_hz) if isinstance(self.band_hz, (list, tuple)) else ()
        if len(band) != 2 or not 0 < band[0] < band[1]:
            raise OptionError(f"the EMG band-pass (--emg-band, band_hz) must be two frequencies LOW:HIGH in Hz with "
                              f"0 < LOW < HIGH, not {self.band_hz!r}")
        object.__setattr__(self, "band_hz", band)
        if not (isinstance(self.lowpass_hz, (int, float)) and self.lowpass_hz > 0):
            raise OptionError(f"the EMG envelope's low-pass (--emg-lowpass, lowpass_hz) must be a frequency above 0 Hz, "
                              f"not {self.lowpass_hz!r}")
        if not (isinstance(self.order, int) and self.order >= 1) or (self.order_means == "effective" and self.order % 2):
            raise OptionError(f"the EMG filters' order (--emg-order, order) must be a positive whole number, even for "
                              f"the effective order of a zero-lag filter, not {self.order!r}")
        if self.order_means not in _ORDER_MEANINGS:
            raise OptionError(f"order_means must be {' or '.join(_ORDER_MEANINGS)}, not {self.order_means!r}")
        if isinstance(self.maximum, Mapping):
            bad = {k: v for k, v in self.maximum.items() if not (isinstance(v, (int, float)) and v > 0)}
            if bad:
                raise OptionError(f"the EMG maxima (--emg-maximum) must be positive numbers per channel, not {bad!r}")
            object.__setattr__(self, "maximum", {str(k): float(v) for k, v in self.maximum.items()})
        elif self.maximum != "peak":
            raise OptionError(f"the EMG normalisation (--emg-maximum, maximum) must be 'peak' or a maximum per channel "
                              f"(a CSV file of channel,maximum), not {self.maximum!r}")
        if not isinstance(self.delay_s, (int, float)) or not 0 <= self.delay_s < 1:
            raise OptionError(f"the electromechanical delay (--emg-delay, delay_s) must be from 0 to 1 s, "
                              f"not {self.delay_s!r}")

    def settings(self) -> dict:
        """The keyword arguments of :func:`process_raw_emg`."""
        return dict(band_hz=self.band_hz, lowpass_hz=float(self.lowpass_hz), order=self.order,
                    order_means=self.order_means, maximum=self.maximum, delay_s=float(self.delay_s))

    def record(self):
        """``"raw"`` for the defaults, else ``{setting: value}`` of the settings that differ."""
        default = EmgProcessing().settings()
        changed = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.settings().items() if v != default[k]}
        return changed or "raw"

    @classmethod
    def from_record(cls, value, where: str = "EMG processing") -> "EmgProcessing":
        if isinstance(value, cls):
            return value
        if value == "raw":
            return cls()
        if not isinstance(value, Mapping):
            raise OptionError(f"{where} must be 'envelope', 'raw' or a table of raw-EMG settings, not {value!r}")
        fields = {f for f in cls.__dataclass_fields__}
        unknown = [k for k in value if k not in fields]
        if unknown:
            raise OptionError(f"{where}: unknown raw-EMG setting(s) {name_list(unknown)}; the settings are "
                              f"{', '.join(sorted(fields))}")
        return cls(**dict(value))


class RawEmgPath(type(Path())):
    """The path of a raw EMG file: :func:`read_emg` processes it into normalised envelopes
    (:func:`process_raw_emg` with :attr:`processing`, an :class:`EmgProcessing`; default its
    defaults). A path otherwise; pickles as itself with its settings."""

    processing: EmgProcessing = EmgProcessing()

    def with_processing(self, processing: EmgProcessing) -> "RawEmgPath":
        new = RawEmgPath(self)
        if processing != EmgProcessing():
            new.processing = processing
        return new

    def __reduce__(self):
        return (_raw_emg_path, (str(self), self.processing))


def _raw_emg_path(path: str, processing: EmgProcessing) -> RawEmgPath:
    return RawEmgPath(path).with_processing(processing)


def emg_source(path, processing="envelope"):
    """``path`` marked with how it is read: the path itself for ``"envelope"``, a
    :class:`RawEmgPath` for raw EMG (``"raw"``, an :class:`EmgProcessing` or its
    :meth:`~EmgProcessing.record`); :class:`OptionError` for another word."""
    if isinstance(processing, str) and processing not in EMG_PROCESSING:
        raise OptionError(f"EMG processing must be {' or '.join(EMG_PROCESSING)}, not {processing!r}")
    if path is None or processing == "envelope":
        return path
    return RawEmgPath(path).with_processing(EmgProcessing.from_record(processing))


def processing_record(path):
    """How an EMG file is read, as records hold it: ``"envelope"``, ``"raw"`` or the changed
    raw-EMG settings (:meth:`EmgProcessing.record`)."""
    return path.processing.record() if isinstance(path, RawEmgPath) else "envelope"


def read_emg(path: str | os.PathLike, processing: str | None = None) -> pd.DataFrame:
    """An EMG file as normalised envelopes: raw EMG (``processing="raw"``, or a
    :class:`RawEmgPath`) through :func:`process_raw_emg` with its defaults, processed
    envelopes (``"envelope"``, the default for a plain path) as stored
    (:func:`read_processed_emg`). The table's ``attrs["processing"]`` says which."""
    if processing is None:
        processing = "raw" if isinstance(path, RawEmgPath) else "envelope"
    if processing not in EMG_PROCESSING:
        raise OptionError(f"EMG processing must be {' or '.join(EMG_PROCESSING)}, not {processing!r}")
    if processing == "envelope":
        return read_processed_emg(path)
    df = read_emg_signals(path)
    settings = path.processing if isinstance(path, RawEmgPath) else EmgProcessing()
    env = process_raw_emg(df, **settings.settings())
    env.attrs.update(path=str(path))
    return env


def read_emg_signals(path) -> pd.DataFrame:
    """The channels of an EMG file: a storage file's columns, or a C3D file's analog channels
    other than the force plates' (:func:`musclemetab.mocap.c3d.read_c3d_analogs`)."""
    from ..io import read_storage

    path = Path(path)
    if path.suffix.lower() == ".c3d":
        from ..mocap.c3d import read_c3d_analogs

        return read_c3d_analogs(path)
    return read_storage(path)


def read_processed_emg(path: str | os.PathLike) -> pd.DataFrame:
    """Processed, normalised EMG envelopes from a storage file, used as stored.

    Only structure is checked (readable, numeric, no NaN); see the module docstring for
    why values slightly outside [0, 1] are kept.
    """
    path = Path(path)
    df = read_emg_signals(path)
    vals = df.to_numpy(dtype=float)
    if np.isnan(vals).any():
        bad = [str(c) for c in df.columns[np.isnan(vals).any(axis=0)]]
        raise InputFileError(f"{path}: EMG channel{'s' if len(bad) > 1 else ''} {name_list(bad)} hold NaN")
    return df


def map_channels(emg_df: pd.DataFrame, mapping: Mapping[str, Sequence[str]]) -> pd.DataFrame:
    """EMG per model muscle: ``e_muscle(t) = mean_c e_c(t)`` over the muscle's channels.

    ``mapping`` is ``{muscle: [channel, ...]}`` (a single channel may be given as a string).
    Raises :class:`MissingColumnError` naming every channel absent from the table, and
    :class:`OptionError` for a muscle without channels.
    """
    norm = {}
    for m, chans in mapping.items():
        chans = [chans] if isinstance(chans, str) else list(chans)
        if not chans:
            raise OptionError(f"EMG mapping gives no channel for muscle {m}; give at least one")
        norm[m] = chans
    wanted = [c for cs in norm.values() for c in cs]
    missing = sorted({c for c in wanted if c not in emg_df.columns}, key=wanted.index)
    if missing:
        users = [m for m, cs in norm.items() if any(c in missing for c in cs)]
        raise MissingColumnError(
            f"{_source(emg_df)}: missing EMG channel{'s' if len(missing) > 1 else ''} {name_list(missing)} "
            f"(mapped to {name_list(users)}); the file has {name_list(emg_df.columns)}"
        )
    out = pd.DataFrame(
        {m: emg_df[cs].to_numpy(dtype=float).mean(axis=1) for m, cs in norm.items()}, index=emg_df.index
    )
    out.attrs.update(emg_df.attrs)
    out.attrs["channels"] = {m: list(cs) for m, cs in norm.items()}
    return out


def require_window(df: pd.DataFrame, t0: float, tf: float, what: str = "EMG") -> None:
    """Raise :class:`DataMismatchError` unless the table covers ``[t0, tf]`` (to 1e-6 s)."""
    t = np.asarray(df.index, dtype=float)
    if not (t0 <= tf):
        raise OptionError(f"time window {t0:g}-{tf:g} s is empty")
    if t.size == 0 or t[0] > t0 + 1e-6 or t[-1] < tf - 1e-6:
        have = f"{t[0]:g}-{t[-1]:g} s" if t.size else "no samples"
        raise DataMismatchError(
            f"{_source(df)}: {what} covers {have}, not the requested window {t0:g}-{tf:g} s; "
            "choose a window inside the EMG recording (an electromechanical delay shifts its start)"
        )


def emg_at(df: pd.DataFrame, times_s) -> pd.DataFrame:
    """Linear interpolation of every column at ``times_s`` (which the EMG must cover)."""
    times = np.asarray(times_s, dtype=float).reshape(-1)
    require_window(df, float(times.min()), float(times.max()))
    t = np.asarray(df.index, dtype=float)
    out = pd.DataFrame(
        {c: np.interp(times, t, df[c].to_numpy(dtype=float)) for c in df.columns},
        index=pd.Index(times, name="time"),
    )
    out.attrs.update(df.attrs)
    return out

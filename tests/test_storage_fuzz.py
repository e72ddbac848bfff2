"""Fuzzing the storage-file reader (hypothesis).

The promise of :func:`musclemetab.io.read_storage`: a file either reads back as the data it
holds or the reader raises an :class:`InputFileError` whose message names the file, never
another exception. Valid files come from :func:`write_storage` (checked by round trip) and
from hand-built headers of both dialects; corrupted files are those files cut, spliced and
altered, and arbitrary bytes.
"""

from __future__ import annotations


import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from musclemetab.errors import InputFileError
from musclemetab.io import read_storage, write_storage
from musclemetab.io.storage import storage_from_arrays

FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

# column names as OpenSim writes them: no white space, unique, never "time"
NAME = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Z", "C")), min_size=1, max_size=12)
VALUE = st.floats(allow_nan=True, allow_infinity=True, width=64)


@st.composite
def tables(draw):
    """``(time, names, values)``: strictly increasing finite times, any values."""
    n_rows = draw(st.integers(1, 25))
    names = draw(st.lists(NAME.filter(lambda s: s.lower() != "time"), max_size=6, unique=True))
    t0 = draw(st.floats(-1e3, 1e3))
    # steps wide enough to stay distinct at the writer's 12 significant digits
    steps = draw(st.lists(st.floats(1e-6, 10.0), min_size=n_rows - 1, max_size=n_rows - 1))
    time = t0 + np.concatenate([[0.0], np.cumsum(steps)])
    values = np.array(draw(st.lists(st.lists(VALUE, min_size=len(names), max_size=len(names)),
                                    min_size=n_rows, max_size=n_rows)), dtype=float).reshape(n_rows, len(names))
    return time, names, values


def _read(path):
    """Read ``path``; any error must be an InputFileError naming the file."""
    try:
        return read_storage(path)
    except InputFileError as exc:
        assert str(path) in str(exc), str(exc)
        assert "\n" not in str(exc).strip(), str(exc)
        return None


def _assert_well_formed(df):
    t = df.index.to_numpy()
    assert t.dtype == float and np.isfinite(t).all() and np.all(np.diff(t) > 0)
    assert len(set(df.columns)) == len(df.columns) and "time" not in [str(c).lower() for c in df.columns]
    assert all(dt == float for dt in df.dtypes)


def _close(a, b):
    """Equal to the writer's 12 significant digits (NaN and infinities exactly)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    same_special = (np.isnan(a) & np.isnan(b)) | (np.isinf(a) & (a == b))
    finite = np.isfinite(a) & np.isfinite(b)
    ok = np.isclose(a, b, rtol=1e-11, atol=0.0) | same_special
    # numbers beyond the double range after rounding (1.79769313486e308 reads back as inf)
    ok |= ~finite & ~np.isnan(a) & ~np.isnan(b) & (np.abs(np.where(np.isinf(a), b, a)) > 1.7976931348e308)
    return bool(np.all(ok))


@FUZZ
@given(table=tables(), in_degrees=st.booleans())
def test_written_files_read_back(tmp_path, table, in_degrees):
    time, names, values = table
    df = storage_from_arrays(time, names=names, data=values, name="fuzz", in_degrees=in_degrees)
    path = write_storage(tmp_path / "table.sto", df)
    back = read_storage(path)
    _assert_well_formed(back)
    assert list(back.columns) == names
    assert back.attrs["name"] == "fuzz" and back.attrs["in_degrees"] is in_degrees
    assert _close(back.index.to_numpy(), time)
    assert _close(back.to_numpy(), values)


def _legacy_text(time, names, values):
    """A legacy (SIMM-style) header, numbers in Python's shortest exact form."""
    rows = np.column_stack([time, values])
    head = [f"fuzz.mot", f"datacolumns {rows.shape[1]}", f"datarows {rows.shape[0]}",
            f"range {time[0]!r} {time[-1]!r}", "endheader"]
    lines = ["\t".join(["time", *names]) + "\t"] + ["\t".join(repr(float(x)) for x in r) + "\t" for r in rows]
    return "\n".join(head + lines) + "\n"


@FUZZ
@given(table=tables())
def test_legacy_header_files_read_exactly(tmp_path, table):
    time, names, values = table
    path = tmp_path / "table.mot"
    path.write_text(_legacy_text(time, names, values), encoding="utf-8")
    back = read_storage(path)
    _assert_well_formed(back)
    assert list(back.columns) == names and back.attrs["in_degrees"] is None
    np.testing.assert_array_equal(back.index.to_numpy(), time)
    np.testing.assert_array_equal(back.to_numpy(), values)


_MUTATIONS = ("cut", "drop_line", "insert_line", "replace_token", "duplicate_line", "swap_lines", "blank_token")


@FUZZ
@given(table=tables(), legacy=st.booleans(), mutation=st.sampled_from(_MUTATIONS), data=st.data())
def test_corrupted_files_fail_cleanly(tmp_path, table, legacy, mutation, data):
    time, names, values = table
    path = tmp_path / "table.sto"
    if legacy:
        text = _legacy_text(time, names, values)
    else:
        write_storage(path, storage_from_arrays(time, names=names, data=values))
        text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    i = data.draw(st.integers(0, len(lines) - 1), label="line")
    junk = data.draw(st.text(max_size=20), label="junk")
    if mutation == "cut":
        text = text[: data.draw(st.integers(0, len(text)), label="cut at")]
    elif mutation == "drop_line":
        del lines[i]
    elif mutation == "insert_line":
        lines.insert(i, junk)
    elif mutation == "duplicate_line":
        lines.insert(i, lines[i])
    elif mutation == "swap_lines":
        j = data.draw(st.integers(0, len(lines) - 1), label="other line")
        lines[i], lines[j] = lines[j], lines[i]
    else:
        tokens = lines[i].split("\t")
        k = data.draw(st.integers(0, len(tokens) - 1), label="token")
        tokens[k] = junk if mutation == "replace_token" else ""
        lines[i] = "\t".join(tokens)
    if mutation != "cut":
        text = "\n".join(lines)
    path.write_bytes(text.encode("utf-8", errors="surrogatepass"))
    df = _read(path)
    if df is None:
        return
    _assert_well_formed(df)
    # a file read without complaint keeps the layout of the data it came from where the
    # mutation could not have touched it: the header's column names in order
    if mutation in ("cut", "drop_line", "duplicate_line") and df.shape[1] == len(names):
        assert list(df.columns) == names


@FUZZ
@given(blob=st.binary(max_size=400), header=st.booleans())
def test_arbitrary_bytes_fail_cleanly(tmp_path, blob, header):
    path = tmp_path / "noise.mot"
    path.write_bytes((b"noise\nendheader\ntime\ta\tb\n" if header else b"") + blob)
    df = _read(path)
    if df is not None:
        _assert_well_formed(df)


@pytest.mark.parametrize("bad", ["inf", "-inf", "Infinity"])
def test_infinite_time_is_refused(tmp_path, bad):
    path = tmp_path / "inf_time.mot"
    path.write_text(f"t\nendheader\ntime\tq\n0.0\t1\n0.01\t2\n{bad}\t3\n", encoding="utf-8")
    with pytest.raises(InputFileError, match=r"inf_time\.mot.*'time'.*(finite|increasing)"):
        read_storage(path)

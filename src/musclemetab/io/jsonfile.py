"""Reading the package's small JSON files (summaries, parameters, unit records, mappings)."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import is_dataclass
from pathlib import Path

import numpy as np

from ..errors import InputFileError

__all__ = ["read_json_object", "json_ready"]


def read_json_object(path: str | os.PathLike, *, missing: str = "not found", remedy: str = "") -> dict:
    """Read a JSON file that holds one object.

    Raises :class:`~musclemetab.errors.InputFileError` naming the file when it does not
    exist (``"<path>: <missing>"``), cannot be read or decoded, is not valid JSON, or holds
    something other than an object; ``remedy`` (what to do) is appended to the last three.
    """
    path = Path(path)
    tail = f"; {remedy}" if remedy else ""
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))  # with or without a byte-order mark
    except FileNotFoundError:
        raise InputFileError(f"{path}: {missing}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{path}: not a readable JSON file ({exc}){tail}") from None
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: a JSON object is expected, not {type(data).__name__}{tail}")
    return data


def json_ready(x):
    """``x`` with NumPy arrays and scalars, tuples and paths turned into the JSON types (lists,
    floats, ints, bools, strings) and dictionary keys into strings, for :func:`json.dumps`; a typed
    record (a dataclass with ``to_dict``, e.g. an entry of a solve's record) as its dictionary, a
    read-only mapping as a dictionary."""
    if is_dataclass(x) and hasattr(x, "to_dict"):
        return json_ready(x.to_dict())
    if isinstance(x, Mapping):
        return {str(k): json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_ready(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_ready(x.tolist())
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    return x

"""Plausibility flags: one implausible finding of a solve or of its metabolic results (:class:`Flag`),
read back from the records that keep them, listed in the ``quality`` column, warned, or refused
under strict checking.

The checks that make them are in :mod:`musclemetab.redundancy.plausibility` (the solution: passive
force, fiber lengths, saturation, reserves) and :mod:`musclemetab.metabolics.plausibility` (the
whole-body rate against walking speed, negative muscle-group rates); ``docs/quality.md`` lists
every flag, its threshold and its source.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

__all__ = ["Flag", "flags_from_records", "quality_text", "warn_flags", "check_strict"]


@dataclass(frozen=True)
class Flag:
    """One implausible finding: ``code`` (short, for tables), ``message`` (one line naming the
    muscles, DOFs or models, their values and the threshold), ``items`` (``{name: value}``, the
    worst first), ``threshold`` and, for a metabolic flag, the energy ``model``."""

    code: str
    message: str
    items: dict = field(default_factory=dict)
    threshold: float | None = None
    model: str | None = None

    def to_dict(self) -> dict:
        out = {"code": self.code, "message": self.message, "items": dict(self.items), "threshold": self.threshold}
        if self.model is not None:
            out["model"] = self.model
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> "Flag":
        return cls(code=str(d["code"]), message=str(d.get("message", "")), items=dict(d.get("items") or {}),
                   threshold=d.get("threshold"), model=d.get("model"))


def flags_from_records(records) -> list[Flag]:
    """Flags from their dictionaries (``summary.json``'s or ``unit.json``'s ``plausibility``); a
    :class:`Flag` as it is (a typed record's ``plausibility``)."""
    return [d if isinstance(d, Flag) else Flag.from_dict(d) for d in (records or [])]


def quality_text(flags: Sequence[Flag]) -> str:
    """The ``quality`` column: ``"ok"``, or the flags as ``code(name name ...)`` joined by ``"; "``,
    one entry per code in the order of first appearance, the names of its flags (every leg's) together."""
    if not flags:
        return "ok"
    names: dict[str, list[str]] = {}
    for f in flags:
        listed = names.setdefault(f.code, [])
        listed += [n for n in f.items if n not in listed]
    return "; ".join(f"{code}({' '.join(n)})" if n else code for code, n in names.items())


def warn_flags(flags: Sequence[Flag], where: str) -> None:
    """One :class:`~musclemetab.errors.PlausibilityWarning` per flag, ``"<where>: <message>"``
    (the command line prints each as one ``musclemetab: warning:`` line)."""
    import warnings

    from .errors import PlausibilityWarning

    for f in flags:
        warnings.warn(f"{where}: {f.message}", PlausibilityWarning, stacklevel=2)


def check_strict(flags: Sequence[Flag], where: str, written: str | None = None) -> None:
    """Raise :class:`~musclemetab.errors.ImplausibleResultError` naming the flags (strict checking)."""
    if not flags:
        return
    from .errors import ImplausibleResultError

    note = f"; the result is in {written} for inspection" if written else ""
    raise ImplausibleResultError(
        f"{where}: implausible result refused (strict): {quality_text(flags)}{note}; see the warnings, "
        "docs/quality.md, or run without strict checking"
    )

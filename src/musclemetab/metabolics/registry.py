"""The models by name, and evaluating several of them on the same muscle states."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from ..errors import OptionError
from ._common import PARAMETER_ARGUMENTS, STATE_ARGUMENTS, MetabolicRates
from .bhargava import bhargava2004
from .houdijk import houdijk2006
from .lichtwark import lichtwark2007
from .umberger import uchida2016, umberger2003, umberger2010

__all__ = ["MODELS", "STUDY_MODELS", "MODEL_COLOURS", "get_model", "parse_models", "compute_models"]

#: Every implemented model by its short name, in the order of the paper's Table 2.
#: One plotting colour per model, shared by every figure of the package.
MODEL_COLOURS = {
    "UM03": "#1f77b4",
    "BH04": "#d62728",
    "HO06": "#2ca02c",
    "LW07": "#9467bd",
    "UM10": "#17becf",
    "UC16": "#ff7f0e",
}

MODELS = {
    "UM03": umberger2003,
    "BH04": bhargava2004,
    "HO06": houdijk2006,
    "LW07": lichtwark2007,
    "UM10": umberger2010,
    "UC16": uchida2016,
}

#: The six models of the study (all of :data:`MODELS`; LW05 is not implemented).
STUDY_MODELS = ("UM03", "BH04", "HO06", "LW07", "UM10", "UC16")


def get_model(name: str):
    """The model function registered under ``name`` (case-insensitive)."""
    key = str(name).strip().upper()
    if key not in MODELS:
        hint = " (LW05 is not implemented; see docs/metabolics.md)" if key == "LW05" else ""
        raise OptionError(f"unknown metabolic model '{name}'{hint}; known models: {', '.join(MODELS)}")
    return MODELS[key]


def parse_models(models: str | Iterable[str] | None) -> list[str]:
    """Model names from ``"all"``, ``None``, ``"UM10,BH04"`` or a list; checked, unique, in order."""
    if models is None:
        return list(STUDY_MODELS)
    if isinstance(models, str):
        items = [m for m in models.replace(";", ",").replace(" ", ",").split(",") if m]
    else:
        items = [str(m) for m in models]
    if not items:
        raise OptionError(f"no metabolic model given; known models: {', '.join(MODELS)} (or 'all')")
    if len(items) == 1 and items[0].lower() == "all":
        return list(STUDY_MODELS)
    out: list[str] = []
    for m in items:
        get_model(m)
        key = m.strip().upper()
        if key not in out:
            out.append(key)
    return out


def compute_models(
    models: str | Iterable[str] | None,
    inputs: Mapping[str, object],
    *,
    time_s=None,
    options: Mapping[str, Mapping[str, object]] | None = None,
    **common_options,
) -> dict[str, MetabolicRates]:
    """Evaluate several models on the same muscle states.

    Parameters
    ----------
    models
        ``"all"``, a comma-separated string or a list of names of :data:`MODELS`.
    inputs
        The shared arguments by name (the seven states and the five parameters).
    time_s
        Time (s) along the last axis (needed by BH04's activation-heat decay).
    options
        Per-model keyword options, e.g. ``{"BH04": {"activation_heat_decay": False}}``.
    common_options
        Keyword options passed to every model (e.g. ``basal=False``).
    """
    names = parse_models(models)
    missing = [k for k in STATE_ARGUMENTS + PARAMETER_ARGUMENTS if k not in inputs]
    if missing:
        raise OptionError(f"metabolic models need {', '.join(missing)}; they are missing from the inputs")
    options = dict(options or {})
    unknown = [k for k in options if k.upper() not in MODELS]
    if unknown:
        raise OptionError(f"options given for unknown model(s) {', '.join(unknown)}; known: {', '.join(MODELS)}")
    args = {k: inputs[k] for k in STATE_ARGUMENTS + PARAMETER_ARGUMENTS}
    out = {}
    for name in names:
        opts = dict(common_options)
        opts.update({k: v for m, o in options.items() if m.upper() == name for k, v in o.items()})
        try:
            out[name] = MODELS[name](**args, time_s=time_s, **opts)
        except TypeError as exc:
            raise OptionError(f"{name}: invalid option ({exc})") from None
    return out

"""The models by name, and evaluating several of them on the same muscle states."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from ..colours import MODEL_COLOURS as _MODEL_COLOURS
from ..errors import OptionError
from ..messages import name_list
from ._common import PARAMETER_ARGUMENTS, STATE_ARGUMENTS, MetabolicRates
from .bhargava import bhargava2004
from .houdijk import houdijk2006
from .lichtwark import lichtwark2005, lichtwark2007
from .margaria import margaria1968
from .umberger import uchida2016, umberger2003, umberger2010

__all__ = ["MODELS", "STUDY_MODELS", "ADDITIONAL_MODELS", "ALL_MODELS", "MODEL_COLOURS", "get_model", "parse_models", "compute_models"]

#: One plotting colour per model, shared by every figure of the package (:mod:`musclemetab.colours`).
MODEL_COLOURS = _MODEL_COLOURS

#: The study's six models by their short names, in the order of the paper's Table 2: the
#: default model set everywhere ("all").
MODELS = {
    "UM03": umberger2003,
    "BH04": bhargava2004,
    "HO06": houdijk2006,
    "LW07": lichtwark2007,
    "UM10": umberger2010,
    "UC16": uchida2016,
}

#: The six models of the study (:data:`MODELS`).
STUDY_MODELS = ("UM03", "BH04", "HO06", "LW07", "UM10", "UC16")

#: Models beside the study's six, evaluated only when named (``--models all,LW05,MA68``).
ADDITIONAL_MODELS = {
    "LW05": lichtwark2005,
    "MA68": margaria1968,
}

#: Every implemented model: the study's six, then the additional ones.
ALL_MODELS = {**MODELS, **ADDITIONAL_MODELS}


def get_model(name: str):
    """The model function registered under ``name`` (case-insensitive)."""
    key = str(name).strip().upper()
    if key not in ALL_MODELS:
        raise OptionError(f"unknown metabolic model '{name}'; known models: {', '.join(ALL_MODELS)}")
    return ALL_MODELS[key]


def parse_models(models: str | Iterable[str] | None) -> list[str]:
    """Model names from ``"all"``, ``None``, ``"UM10,BH04"`` or a list; checked, unique, in order.

    ``"all"`` (alone or in a list, e.g. ``"all,LW05,MA68"``) stands for the study's six
    models; the additional models are evaluated only when named."""
    if models is None:
        return list(STUDY_MODELS)
    if isinstance(models, str):
        items = [m for m in models.replace(";", ",").replace(" ", ",").split(",") if m]
    else:
        items = [str(m) for m in models]
    if not items:
        raise OptionError(f"no metabolic model given; known models: {', '.join(ALL_MODELS)} (or 'all')")
    out: list[str] = []
    for m in items:
        keys = STUDY_MODELS if m.strip().lower() == "all" else (get_model(m).model_name,)
        out.extend(k for k in keys if k not in out)
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
        ``"all"``, a comma-separated string or a list of names of :data:`ALL_MODELS`.
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
        raise OptionError(f"metabolic models need {name_list(missing)}; they are missing from the inputs")
    options = dict(options or {})
    unknown = [k for k in options if k.upper() not in ALL_MODELS]
    if unknown:
        raise OptionError(f"options given for unknown model(s) {name_list(unknown)}; known: {', '.join(ALL_MODELS)}")
    args = {k: inputs[k] for k in STATE_ARGUMENTS + PARAMETER_ARGUMENTS}
    out = {}
    for name in names:
        opts = dict(common_options)
        opts.update({k: v for m, o in options.items() if m.upper() == name for k, v in o.items()})
        try:
            out[name] = ALL_MODELS[name](**args, time_s=time_s, **opts)
        except TypeError as exc:
            raise OptionError(f"{name}: invalid option ({exc})") from None
    return out

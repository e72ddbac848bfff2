"""The paper's Figure 2: metabolic rate and efficiency of a soleus for the six models, with
panels for the additional models LW05 and MA68 beside them.

Configuration (the paper's "general case"): slow-twitch fraction 0.8, mass 0.48 kg,
optimal fiber length 4.5 cm, ``vmax`` = 10 optimal lengths per second, activation levels
0.01, 0.33, 0.66 and 1.00 in steady state (``e = a``), one plane at ``l~M = 1`` (rate and
efficiency over velocity) and one at ``|vbar| = 0.1`` (over length). The curves
``fL``, ``fV``, ``fPE`` are the package's (:mod:`musclemetab.muscle`); efficiency is
``W_CE / Edot`` with ``W_CE = -a fL fV F0 V_CE``, concentric states only.

Open choices (the paper does not state them), each a parameter of :func:`figure2_data`
and printed in the figure:

* ``max_isometric_force_N``: default 5978.47 N, the example model's soleus, whose mass
  (0.476 kg) and optimal fiber length (4.51 cm) are the configuration's;
* ``bh04_stimulation_time_s``: BH04's activation-heat decay needs a time since stimulation
  onset that a steady state does not have. Default ``inf`` (the steady-state limit,
  ``phi = 0.06``); the study's threshold is kept (no activation heat for ``e <= 0.1``);
* ``lw05_stimulation_time_s``: the same for LW05's labile heat (default ``inf``: no labile
  heat; ``t_stim = 0``, the largest labile heat, for ``e <= 0.1`` by the same counter).
  The force is constant in a steady state: no thermoelastic heat;
* ``basal``: basal heat neither in the rates nor in the efficiency (default False);
* ``velocity_plane_vbar``: the sign of the "0.1" plane; default -0.1 (shortening is
  negative here, and efficiency is defined for concentric states only).

The paper's ordering of the metabolic rate (LW07 > HO06 > BH04 > the Umberger family)
does not follow from the equations at this configuration: :func:`ordering_summary`
computes how often each part holds (BH04 exceeds HO06 at most concentric states).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ..messages import name_list
from ..muscle import active_force_length, force_velocity, passive_force_length
from .registry import MODEL_COLOURS as _COLOURS
from .registry import ADDITIONAL_MODELS, ALL_MODELS, STUDY_MODELS

#: The models drawn by :func:`save_figure2` by default: the study's six, then the others.
FIGURE2_MODELS = STUDY_MODELS + tuple(ADDITIONAL_MODELS)

__all__ = ["FIGURE2_MODELS", "FIGURE2_DEFAULTS", "figure2_data", "figure2", "ordering_summary", "save_figure2",
           "EXAMPLE_SOLEUS_F0_N"]

#: Maximal isometric force of the example model's soleus (N).
EXAMPLE_SOLEUS_F0_N = 5978.474277147492

FIGURE2_DEFAULTS = {
    "slow_twitch_fraction": 0.8,
    "muscle_mass_kg": 0.48,
    "optimal_fiber_length_m": 0.045,
    "max_contraction_velocity": 10.0,
    "max_isometric_force_N": EXAMPLE_SOLEUS_F0_N,
    "activations": (0.01, 0.33, 0.66, 1.0),
    "length_plane": 1.0,
    "velocity_plane_vbar": -0.1,
    "bh04_stimulation_time_s": float("inf"),
    "lw05_stimulation_time_s": float("inf"),
    "basal": False,
    "n_velocity": 201,
    "n_length": 121,
    "length_range": (0.4, 1.6),
}

_UMBERGER = ("UM03", "UM10", "UC16")


def _evaluate(models, a, lm, vbar, cfg):
    """Rates (W) of every model and the mechanical power W_CE (W) at steady states."""
    a, lm, vbar = np.broadcast_arrays(np.asarray(a, float), np.asarray(lm, float), np.asarray(vbar, float))
    f0 = cfg["max_isometric_force_N"]
    fl = active_force_length(lm)
    fv = force_velocity(vbar)
    inputs = dict(
        excitation=a,
        activation=a,
        normalized_fiber_length=lm,
        normalized_fiber_velocity=vbar,
        active_force_length_multiplier=fl,
        force_velocity_multiplier=fv,
        passive_fiber_force_N=f0 * passive_force_length(lm),
        max_isometric_force_N=f0,
        optimal_fiber_length_m=cfg["optimal_fiber_length_m"],
        max_contraction_velocity=cfg["max_contraction_velocity"],
        muscle_mass_kg=cfg["muscle_mass_kg"],
        slow_twitch_fraction=cfg["slow_twitch_fraction"],
    )
    t_bh = cfg["bh04_stimulation_time_s"]
    # the study's counter gives t_stim = 0 (no activation heat) while e <= 0.1
    t_stim = np.where(a > 0.1, t_bh, 0.0)
    rates = {}
    for name in models:
        opts = {"basal": cfg["basal"]}
        if name == "BH04":
            opts["stimulation_time_s"] = t_stim
        elif name == "LW05":
            opts["stimulation_time_s"] = np.where(a > 0.1, cfg["lw05_stimulation_time_s"], 0.0)
            opts["fiber_force_rate_N_per_s"] = 0.0  # steady state
        rates[name] = ALL_MODELS[name](**inputs, **opts).total
    v_ce = vbar * cfg["max_contraction_velocity"] * cfg["optimal_fiber_length_m"]
    power = -(a * fl * fv * f0) * v_ce
    return rates, power


def _efficiency(power, rate, concentric):
    with np.errstate(divide="ignore", invalid="ignore"):
        eff = power / rate
    return np.where(concentric & (rate > 0), eff, np.nan)


def figure2_data(models=STUDY_MODELS, **config) -> dict:
    """Metabolic rate (W) and efficiency of the Figure-2 soleus over velocity and length.

    Parameters
    ----------
    models
        Model names (default: the six of the study; :data:`FIGURE2_MODELS` adds LW05 and MA68).
    config
        Overrides of :data:`FIGURE2_DEFAULTS` (see the module docstring for the open
        choices): ``max_isometric_force_N``, ``bh04_stimulation_time_s``, ``basal``,
        ``velocity_plane_vbar``, ``activations``, ``length_plane``, muscle parameters,
        grid sizes.

    Returns
    -------
    dict with ``config``, ``activations`` (A,), ``velocity`` = {``vbar`` (V,),
    ``rate_W`` {model: (A, V)}, ``efficiency`` {model: (A, V), NaN where not
    concentric}, ``power_W`` (A, V)} at ``l~M = length_plane``, and ``length`` = the same
    over ``lm`` (L,) at ``vbar = velocity_plane_vbar``.
    """
    unknown = set(config) - set(FIGURE2_DEFAULTS)
    if unknown:
        raise OptionError(
            f"unknown Figure-2 option(s) {name_list(sorted(unknown))}; options: {', '.join(FIGURE2_DEFAULTS)}"
        )
    cfg = {**FIGURE2_DEFAULTS, **config}
    models = [m.upper() for m in models]
    for m in models:
        if m not in ALL_MODELS:
            raise OptionError(f"unknown metabolic model '{m}'; known models: {', '.join(ALL_MODELS)}")
    acts = np.asarray(cfg["activations"], dtype=float)
    if acts.ndim != 1 or acts.size == 0 or np.any((acts <= 0) | (acts > 1)):
        raise OptionError("activations must be a list of values in (0, 1]")
    for key in ("bh04_stimulation_time_s", "lw05_stimulation_time_s"):
        if not float(cfg[key]) > 0:
            raise OptionError(f"{key} must be positive (s; inf for the steady-state limit)")
    vbar = np.linspace(-1.0, 1.0, int(cfg["n_velocity"]))
    lo, hi = cfg["length_range"]
    lm = np.linspace(float(lo), float(hi), int(cfg["n_length"]))
    a_col = acts[:, None]

    rates_v, power_v = _evaluate(models, a_col, cfg["length_plane"], vbar[None, :], cfg)
    conc_v = np.broadcast_to(vbar[None, :] < 0, power_v.shape)
    rates_l, power_l = _evaluate(models, a_col, lm[None, :], cfg["velocity_plane_vbar"], cfg)
    conc_l = np.broadcast_to(np.asarray(cfg["velocity_plane_vbar"]) < 0, power_l.shape)
    return {
        "config": cfg,
        "models": list(models),
        "activations": acts,
        "velocity": {
            "vbar": vbar,
            "normalized_fiber_length": float(cfg["length_plane"]),
            "rate_W": rates_v,
            "power_W": power_v,
            "efficiency": {m: _efficiency(power_v, r, conc_v) for m, r in rates_v.items()},
        },
        "length": {
            "normalized_fiber_length": lm,
            "vbar": float(cfg["velocity_plane_vbar"]),
            "rate_W": rates_l,
            "power_W": power_l,
            "efficiency": {m: _efficiency(power_l, r, conc_l) for m, r in rates_l.items()},
        },
    }


def ordering_summary(data: dict) -> dict:
    """How often the paper's rate ordering holds at the concentric states of the figure.

    Returns fractions (0..1) over all concentric states of both planes (every activation)
    of: ``LW07 > HO06``, ``HO06 > BH04``, ``BH04 > HO06``, ``BH04 > max(Umberger family)``,
    and the full chain ``LW07 > HO06 > BH04 > max(UM03, UM10, UC16)``; plus the mean
    absolute efficiency difference BH04 - HO06 at low (|vbar| <= 0.3) and high
    (|vbar| >= 0.7) shortening velocity, at ``l~M = length_plane``.
    """
    needed = {"LW07", "HO06", "BH04", *_UMBERGER}
    if not needed <= set(data["models"]):
        raise OptionError(f"the ordering needs the models {', '.join(sorted(needed))}")
    parts = []
    for plane in ("velocity", "length"):
        d = data[plane]
        if plane == "velocity":
            conc = np.broadcast_to(d["vbar"][None, :] < 0, d["power_W"].shape)
        else:
            conc = np.broadcast_to(np.asarray(d["vbar"]) < 0, d["power_W"].shape)
        r = {m: np.broadcast_to(d["rate_W"][m], conc.shape)[conc] for m in needed}
        parts.append(r)
    r = {m: np.concatenate([p[m] for p in parts]) for m in needed}
    if r["LW07"].size == 0:
        raise OptionError("no concentric state in the figure data")
    umb = np.maximum.reduce([r[m] for m in _UMBERGER])
    chain = (r["LW07"] > r["HO06"]) & (r["HO06"] > r["BH04"]) & (r["BH04"] > umb)
    v = data["velocity"]
    vb = v["vbar"]
    low = (vb < 0) & (vb >= -0.3)
    high = vb <= -0.7
    diff = np.abs(v["efficiency"]["BH04"] - v["efficiency"]["HO06"])
    return {
        "n_states": int(r["LW07"].size),
        "LW07>HO06": float(np.mean(r["LW07"] > r["HO06"])),
        "HO06>BH04": float(np.mean(r["HO06"] > r["BH04"])),
        "BH04>HO06": float(np.mean(r["BH04"] > r["HO06"])),
        "BH04>Umberger": float(np.mean(r["BH04"] > umb)),
        "LW07>HO06>BH04>Umberger": float(np.mean(chain)),
        "efficiency_gap_BH04_HO06_low_speed": float(np.nanmean(diff[:, low])),
        "efficiency_gap_BH04_HO06_high_speed": float(np.nanmean(diff[:, high])),
    }


def _choices_text(cfg: dict) -> str:
    t = cfg["bh04_stimulation_time_s"]
    t_txt = "inf (steady state, phi = 0.06)" if np.isinf(t) else f"{t:g} s"
    return (
        f"Open choices: F0 = {cfg['max_isometric_force_N']:.1f} N; BH04 stimulation time = {t_txt}, "
        f"no activation heat for e <= 0.1; basal heat {'included' if cfg['basal'] else 'excluded'} "
        f"(rates and efficiency); length plane at vbar = {cfg['velocity_plane_vbar']:+g} "
        f"({'shortening' if cfg['velocity_plane_vbar'] < 0 else 'lengthening'}); e = a (steady state). "
        f"Soleus: f_ST = {cfg['slow_twitch_fraction']:g}, m = {cfg['muscle_mass_kg']:g} kg, "
        f"lMo = {100 * cfg['optimal_fiber_length_m']:g} cm, vmax = {cfg['max_contraction_velocity']:g} lMo/s."
    )


def _additional_text(cfg: dict, models) -> str:
    """The additional models' settings, for the figure's caption."""
    parts = []
    if "LW05" in models:
        t = cfg["lw05_stimulation_time_s"]
        parts.append(f"LW05: stimulation time {'inf (no labile heat)' if np.isinf(t) else f'{t:g} s'} above e = 0.1, "
                     "0 (full labile heat) below; no thermoelastic heat (constant force)")
    if "MA68" in models:
        parts.append("MA68: W/0.25 when shortening, W/(-1.2) when lengthening")
    return "; ".join(parts) + "." if parts else ""


def save_figure2(path: str | os.PathLike, data: dict | None = None, **config) -> Path:
    """Draw Figure 2 (:func:`figure2`) and save it (format from the extension, e.g. ``.png``,
    ``.pdf``). The file is written atomically."""
    from ..io import atomic_path

    fig = figure2(data, **config)
    path = Path(path)
    suffix = path.suffix or ".png"
    with atomic_path(path, suffix=suffix) as tmp:
        fig.savefig(tmp, dpi=110, format=suffix.lstrip("."))
    return path


def figure2(data: dict | None = None, **config):
    """Figure 2 as a matplotlib figure (Agg canvas, no ``pyplot``).

    Rows: one per model (default :data:`FIGURE2_MODELS`: the study's six, then LW05 and
    MA68), and a last row comparing the models at full activation (where
    the rate ordering is visible). Columns: rate and efficiency over velocity at
    ``l~M = length_plane``; rate and efficiency over length at ``vbar =
    velocity_plane_vbar``. The open choices and the ordering found are printed on the
    figure. ``data``: from :func:`figure2_data` (default: computed from ``config``).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if data is None:
        data = figure2_data(**{"models": FIGURE2_MODELS, **config})
    elif config:
        raise OptionError("give either data or configuration options, not both")
    cfg = data["config"]
    models = data["models"]
    acts = data["activations"]
    v, ln = data["velocity"], data["length"]
    nrow = len(models) + 1
    fig = Figure(figsize=(15, 2.6 * nrow + 1.2))  # margins set below, once the title's height is known
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrow, 4, squeeze=False, sharex="col")  # each column: one abscissa
    shades = np.linspace(0.35, 1.0, len(acts))
    for i, m in enumerate(models):
        col = _COLOURS.get(m, "k")
        for j, a in enumerate(acts):
            kw = dict(color=col, alpha=float(shades[j]), lw=1.2, label=f"a = {a:g}")
            axes[i, 0].plot(v["vbar"], v["rate_W"][m][j], **kw)
            axes[i, 1].plot(v["vbar"], v["efficiency"][m][j], **kw)
            axes[i, 2].plot(ln["normalized_fiber_length"], ln["rate_W"][m][j], **kw)
            axes[i, 3].plot(ln["normalized_fiber_length"], ln["efficiency"][m][j], **kw)
        axes[i, 0].set_ylabel(f"{m}\nrate (W)")
        axes[i, 1].set_ylabel("efficiency")
        axes[i, 2].set_ylabel("rate (W)")
        axes[i, 3].set_ylabel("efficiency")
        axes[i, 0].axhline(0, color="0.6", lw=0.6)
        axes[i, 1].set_xlim(-1, 0)
        axes[i, 1].set_ylim(0, 1.2)
        axes[i, 3].set_ylim(0, 1.2)
        if i == 0:
            axes[i, 0].legend(fontsize=7, loc="upper right")
    last = nrow - 1
    j_full = int(np.argmax(acts))
    for m in models:
        col = _COLOURS.get(m, "k")
        axes[last, 0].plot(v["vbar"], v["rate_W"][m][j_full], color=col, label=m)
        axes[last, 1].plot(v["vbar"], v["efficiency"][m][j_full], color=col, label=m)
        axes[last, 2].plot(ln["normalized_fiber_length"], ln["rate_W"][m][j_full], color=col, label=m)
        axes[last, 3].plot(ln["normalized_fiber_length"], ln["efficiency"][m][j_full], color=col, label=m)
    axes[last, 0].set_ylabel(f"all models, a = {acts[j_full]:g}\nrate (W)")
    axes[last, 1].set_xlim(-1, 0)
    axes[last, 1].set_ylim(0, 1.2)
    axes[last, 3].set_ylim(0, 1.2)
    axes[last, 0].legend(fontsize=7, ncol=2)
    for ax in axes[last, 0:2]:
        ax.set_xlabel("vbar = v / (lMo vmax)  (< 0 shortening)", fontsize=8)
    for ax in axes[last, 2:4]:
        ax.set_xlabel("normalised fiber length", fontsize=8)
    for ax in axes[:last].ravel():  # the abscissa is numbered on the last row only
        ax.tick_params(labelbottom=False)
    axes[0, 0].set_title(f"rate over velocity, l~M = {v['normalized_fiber_length']:g}", fontsize=9)
    axes[0, 1].set_title("efficiency W/Edot (concentric)", fontsize=9)
    axes[0, 2].set_title(f"rate over length, vbar = {ln['vbar']:+g}", fontsize=9)
    axes[0, 3].set_title("efficiency over length", fontsize=9)
    text = _choices_text(cfg)
    extra_text = _additional_text(cfg, models)
    if extra_text:
        text += "\n" + extra_text
    if set(STUDY_MODELS) <= set(models):
        o = ordering_summary(data)
        text += (
            f"\nOrdering at {o['n_states']} concentric states: LW07 > HO06 > BH04 > Umberger family holds at "
            f"{100 * o['LW07>HO06>BH04>Umberger']:.0f} %; BH04 > HO06 at {100 * o['BH04>HO06']:.0f} % "
            f"(the paper states HO06 > BH04); LW07 > HO06 at {100 * o['LW07>HO06']:.0f} %."
        )
    import textwrap

    wrapped = "\n".join(textwrap.fill(par, 170) for par in text.split("\n"))
    extra = [m for m in models if m not in STUDY_MODELS]
    what = f"{len(models)} models" + (f" ({name_list(extra)} beside the study's)" if extra else "")
    title = f"Figure 2: soleus metabolic rate and efficiency, {what}\n" + wrapped
    fig.suptitle(title, fontsize=9, y=1.0 - 0.1 / fig.get_figheight(), va="top")
    # a fixed layout (a constrained layout measured every label of the 36 panels at each save:
    # half the drawing time): the title's lines at 9 pt, then the panels
    title_in = (title.count("\n") + 1) * 9 * 1.25 / 72 + 0.45
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.5 / fig.get_figheight(),
                        top=1.0 - title_in / fig.get_figheight(), wspace=0.25, hspace=0.15)
    return fig

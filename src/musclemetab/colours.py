"""The package's colours: one palette, safe for colour-blind readers, used by every figure.

The eight colours of Okabe and Ito (2008, "Color Universal Design"), distinguishable with
each of the common colour-vision deficiencies. Each metabolic model, each workflow and
each muscle group has one fixed colour; the two groups of a degree of freedom (e.g.
plantar- and dorsiflexors) share a hue, dark and light.
"""

from __future__ import annotations

__all__ = ["OKABE_ITO", "MODEL_COLOURS", "WORKFLOW_COLOURS", "GROUP_COLOURS", "lighter", "darker"]

#: The Okabe-Ito palette by name.
OKABE_ITO = {
    "black": "#000000",
    "orange": "#E69F00",
    "sky blue": "#56B4E9",
    "bluish green": "#009E73",
    "yellow": "#F0E442",
    "blue": "#0072B2",
    "vermillion": "#D55E00",
    "reddish purple": "#CC79A7",
}


def lighter(colour: str, amount: float = 0.5) -> str:
    """``colour`` (``#rrggbb``) mixed with white: ``amount`` 0 keeps it, 1 gives white."""
    rgb = [int(colour[i:i + 2], 16) for i in (1, 3, 5)]
    return "#" + "".join(f"{round(c + (255 - c) * amount):02X}" for c in rgb)


def darker(colour: str, amount: float = 0.5) -> str:
    """``colour`` (``#rrggbb``) mixed with black: ``amount`` 0 keeps it, 1 gives black."""
    rgb = [int(colour[i:i + 2], 16) for i in (1, 3, 5)]
    return "#" + "".join(f"{round(c * (1 - amount)):02X}" for c in rgb)


_O = OKABE_ITO

#: One colour per metabolic model (the study's six, then the additional two; yellow, the
#: palest, goes to MA68, drawn only when asked for).
MODEL_COLOURS = {
    "UM03": _O["blue"],
    "BH04": _O["vermillion"],
    "HO06": _O["bluish green"],
    "LW07": _O["reddish purple"],
    "UM10": _O["sky blue"],
    "UC16": _O["orange"],
    "LW05": _O["black"],
    "MA68": _O["yellow"],
}

#: One colour per workflow of the muscle redundancy solver.
WORKFLOW_COLOURS = {
    "effort-gen": _O["black"],
    "effort-cal": _O["orange"],
    "effort-ten": _O["blue"],
    "emg-ten": _O["vermillion"],
}

#: One colour per muscle group (``docs/analysis.md``): the extensor-like group of a degree
#: of freedom dark, its antagonist the same hue lighter; the remainder grey. Black is left to
#: the whole-body lines drawn with the groups.
GROUP_COLOURS = {
    "PF": _O["blue"],
    "DF": _O["sky blue"],
    "KE": _O["vermillion"],
    "KF": _O["orange"],
    "HE": _O["bluish green"],
    "HF": lighter(_O["bluish green"], 0.55),
    "HAD": _O["reddish purple"],
    "HAB": lighter(_O["reddish purple"], 0.55),
    "HIR": darker(_O["yellow"], 0.35),
    "HER": _O["yellow"],
    "other": "#999999",
}

"""Metabolic rates of every muscle along an OpenSim states trajectory (``docs/metabolics.md``,
section "Energy of an OpenSim motion").

:func:`read_opensim_states` turns a states file of a model (a CMC, Moco or forward-dynamics
``states.sto``) into the :class:`~musclemetab.metabolics.solution.SolutionStates` the package's
solutions give: OpenSim realises every state to ``Dynamics`` in the OpenSim worker
(:func:`musclemetab.opensim_bridge.trajectory.muscles_along_states`) and its own muscle
dynamics give the fiber length, the force-length multiplier, the passive fiber force, activation
and excitation (from the controls file; without one, excitation = activation, and the muscles
holding the model's default states at every state are left out). The fiber velocity is OpenSim's
(equilibrium with a fiber-length state, or the geometry of a rigid tendon), except for a
compliant-tendon DeGrooteFregly2016Muscle, whose velocity is by default that of the trajectory's
own tendon-force derivative where the file holds it (a Moco solution file's
``implicitderiv_normalized_tendon_force``: the velocity Moco solved with), else the time
derivative of OpenSim's fiber lengths along the states (its force equilibrium is ill-conditioned
at low activation and wrong for states made with other curves, such as the package's own
solutions: ``fiber_velocity="equilibrium"`` keeps it). ``F0``, ``lMo`` and ``vmax`` are the model's. So the
per-muscle and whole-body tables follow from
:func:`~musclemetab.metabolics.solution.metabolics_from_legs`.

When the model carries OpenSim metabolic probes (``Umberger2010MuscleMetabolicsProbe``,
``Bhargava2004MuscleMetabolicsProbe``), :func:`probe_muscle_properties` gives their per-muscle
slow-twitch ratios and the masses they use (provided, or ``F0 / specific tension x density x
lMo`` with the probe's specific tension and density), so that this package and OpenSim evaluate
the same muscles.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataMismatchError, OptionError
from .solution import SolutionStates

__all__ = ["OpenSimStates", "read_opensim_states", "FIBER_VELOCITY_SOURCES", "probe_muscle_properties", "split_sides",
           "MUSCLE_PARAMETER_SOURCES", "states_metabolics"]

#: ``--fiber-velocity``: a compliant-tendon DeGrooteFregly2016Muscle's fiber velocity from the
#: trajectory's own tendon-force derivative (a Moco solution file's), from the time derivative of
#: OpenSim's fiber lengths along the states, or from OpenSim's force equilibrium; ``auto`` (the
#: default): the trajectory's where the file holds it, else the derivative
FIBER_VELOCITY_SOURCES = ("auto", "trajectory", "derivative", "equilibrium")
#: ``--muscle-parameters``: the model's probes' (when it has any) or the package's own tables
MUSCLE_PARAMETER_SOURCES = ("probes", "package")
_QUANTITIES = ("excitation", "activation", "normalized_fiber_length", "normalized_fiber_velocity",
               "active_force_length_multiplier", "force_velocity_multiplier", "passive_fiber_force_N")


@dataclass
class OpenSimStates:
    """The muscle states of an OpenSim states file (:func:`read_opensim_states`)."""

    states: SolutionStates
    #: per metabolic probe of the model: ``name``, ``kind``, ``switches``, ``muscles`` (per-muscle
    #: parameters) and ``rates`` (OpenSim's per-muscle output at every state, W)
    probes: list = field(default_factory=list)
    #: ``(muscles, states)``: a DeGrooteFregly2016Muscle's fiber velocity off its curve, set to the bound
    clamped: np.ndarray | None = None
    #: the model's muscles not evaluated: without controls (``skipped_reason`` ``"no controls"``), or
    #: whose every state variable is the model's default at every state (``"default states"``: the
    #: other leg of a one-leg solution's model, read without its controls file)
    skipped_muscles: tuple[str, ...] = ()
    skipped_reason: str = ""
    #: ``"controls"`` (from the controls file) or ``"activation"`` (excitation = activation)
    excitation_source: str = "activation"
    muscle_classes: tuple[str, ...] = ()
    #: the fiber velocity (m/s) taken, ``(muscles, states)``
    fiber_velocity_m_per_s: np.ndarray | None = None
    #: per muscle, where its fiber velocity comes from: ``"derivative"`` (of OpenSim's fiber length
    #: along the states), ``"equilibrium"`` (OpenSim's muscle equilibrium) or ``"geometry"`` (rigid tendon)
    velocity_sources: tuple[str, ...] = ()


def read_opensim_states(model: str | os.PathLike, states: str | os.PathLike,
                        controls: str | os.PathLike | None = None, *,
                        fiber_velocity: str = "auto") -> OpenSimStates:
    """The muscle states of every muscle of ``model`` along the states file ``states``, from
    OpenSim's muscle dynamics (see the module's description).

    ``controls``: the simulation's controls file (columns ``/forceset/<muscle>`` or
    ``<muscle>``, interpolated to the state times); the model's muscles it has no column for
    are not evaluated. Without it every muscle's excitation is its activation, and the muscles
    whose state variables are the model's defaults at every state are not evaluated.
    ``fiber_velocity``: a compliant-tendon DeGrooteFregly2016Muscle's fiber velocity from the
    trajectory's own tendon-force derivative (``"trajectory"``: the columns
    ``<muscle path>/implicitderiv_normalized_tendon_force`` of a Moco solution file, the velocity
    Moco solved with), the time derivative of OpenSim's fiber lengths (``"derivative"``) or OpenSim's
    force equilibrium (``"equilibrium"``, as OpenSim's probes take it); ``"auto"``: the trajectory's
    where the file holds it, else the derivative; see ``docs/metabolics.md`` section 4.1.

    Raises
    ------
    DataMismatchError
        OpenSim cannot load the states into the model, or cannot realise a state.
    """
    from ..opensim_bridge import call

    if fiber_velocity not in FIBER_VELOCITY_SOURCES:
        raise OptionError(f"fiber velocity must be {', '.join(FIBER_VELOCITY_SOURCES)}, not {fiber_velocity!r}")
    got = call("trajectory:muscles_along_states", str(model), str(states),
               None if controls is None else str(controls), fiber_velocity)
    if got["failed_states"]:
        t, msg = got["failed_states"][0]
        raise DataMismatchError(
            f"{states}: OpenSim cannot realise the model's muscles at {len(got['failed_states'])} state(s), first at "
            f"t = {t:g} s ({msg}); check that the states belong to {model}")
    muscles = tuple(got["muscles"])
    p = got["parameters"]
    params = {m: {k: float(p[k][i]) for k in ("max_isometric_force_N", "optimal_fiber_length_m",
                                             "max_contraction_velocity")} for i, m in enumerate(muscles)}
    sol = SolutionStates(time_s=np.asarray(got["time_s"], dtype=float), muscles=muscles,
                         states={k: np.asarray(got[k], dtype=float) for k in _QUANTITIES}, parameters=params,
                         source=str(states))
    return OpenSimStates(states=sol, probes=list(got["probes"]), clamped=np.asarray(got["clamped"], dtype=bool),
                         skipped_muscles=tuple(got["skipped_muscles"]),
                         skipped_reason=got["skipped_reason"] if got["skipped_muscles"] else "", excitation_source=got["excitation_source"],
                         muscle_classes=tuple(got["muscle_classes"]),
                         fiber_velocity_m_per_s=np.asarray(got["fiber_velocity_m_per_s"], dtype=float),
                         velocity_sources=tuple(got["velocity_sources"]))


def probe_muscle_properties(read: OpenSimStates) -> tuple[dict, dict, str]:
    """``(masses, slow_twitch_fractions, description)`` by muscle from the model's metabolic
    probes (the first probe naming a muscle gives its values): the mass each probe uses
    (provided, or ``F0 / specific tension x density x lMo`` with its specific tension and
    density) and its slow-twitch ratio. Empty when the model has no metabolic probe."""
    masses, fst, used = {}, {}, []
    for pr in read.probes:
        n = 0
        for m, rec in pr["muscles"].items():
            if m in read.states.muscles and m not in masses:
                masses[m], fst[m] = float(rec["muscle_mass_kg"]), float(rec["slow_twitch_fraction"])
                n += 1
        if n:
            sig = sorted({f"{rec['specific_tension_Pa'] / 1e6:g}" for rec in pr["muscles"].values()})
            used.append(f"{pr['kind']} '{pr['name']}' ({n} muscles, specific tension {'/'.join(sig)} MPa)")
    return masses, fst, "; ".join(used)


def split_sides(states: SolutionStates) -> dict[str, SolutionStates]:
    """``{side: states}`` of the muscles of each leg (names ending ``_r``, ``_l``): one leg stands
    for both in the whole-body rate, two legs are added (:func:`~musclemetab.metabolics.solution.metabolics_from_legs`).
    A muscle of neither leg among the muscles of two legs is refused."""
    sides = {m: m[-1] if m.endswith(("_r", "_l")) else "" for m in states.muscles}
    present = sorted(set(sides.values()), reverse=True)
    if len(present) == 1:
        return {present[0]: SolutionStates(**{**states.__dict__, "side": present[0] or None})}
    if "" in present:
        odd = [m for m, s in sides.items() if not s]
        raise OptionError(f"{states.source}: muscle{'s' if len(odd) > 1 else ''} {', '.join(odd[:6])} belong to "
                          "neither leg (no _r/_l ending) while the others cover both legs; the whole-body rate adds "
                          "the legs: give a controls file of the leg muscles alone")
    out = {}
    for side in present:
        idx = [i for i, m in enumerate(states.muscles) if sides[m] == side]
        names = tuple(states.muscles[i] for i in idx)
        out[side] = SolutionStates(time_s=states.time_s, muscles=names,
                                   states={k: v[idx] for k, v in states.states.items()},
                                   parameters={m: states.parameters[m] for m in names}, source=states.source,
                                   side=side)
    return out


def states_metabolics(read: OpenSimStates, legs: dict, body_mass_kg: float, height_m: float | None, *,
                      muscle_parameters: str = "probes", muscle_properties=None, cycle_s=None,
                      **options) -> tuple[dict, str]:
    """The metabolic rates of the legs ``legs`` (:func:`split_sides` of ``read.states``, or some of
    them) of an OpenSim states file (``musclemetab metabolics --states`` and a study trial's
    ``states``): ``({side: SolutionMetabolics}, the probes used)``. With ``muscle_parameters =
    "probes"`` the muscle masses and slow-twitch ratios are those of the model's metabolic probes
    (:func:`probe_muscle_properties`; ``""`` when it has none), the rows of ``muscle_properties``
    winning over them; the ``options`` are those of
    :func:`~musclemetab.metabolics.solution.metabolics_from_legs`. ``cycle_s``: ``(start, end)`` (s)
    of the gait cycle the rates are averaged over (the states inside it are kept; the states must
    cover it to within 1.5 state intervals, else :class:`~musclemetab.errors.DataMismatchError`);
    ``None`` keeps every state."""
    from .solution import metabolics_from_legs

    if muscle_parameters not in MUSCLE_PARAMETER_SOURCES:
        raise OptionError(f"muscle parameters must be {' or '.join(MUSCLE_PARAMETER_SOURCES)}, not "
                          f"{muscle_parameters!r}")
    masses = fractions = None
    used = ""
    if muscle_parameters == "probes":
        masses, fractions, used = probe_muscle_properties(read)
    if muscle_properties:  # its rows win over the probes' values
        from ..properties import read_muscle_properties

        overrides = read_muscle_properties(muscle_properties)
        overrides.check_names([*read.states.muscles, *read.skipped_muscles])
        for values, column in ((masses, "mass_kg"), (fractions, "slow_twitch_fraction")):
            for m in [m for m in (values or {}) if overrides.for_muscle(m).get(column) is not None]:
                del values[m]
    span = dict(trim=(0, 0))
    if cycle_s is not None:
        from ..events import coverage

        coverage(read.states.time_s, float(cycle_s[0]), float(cycle_s[1]), None, f"{read.states.source}: the states")
        span = dict(trim=None, cycle_s=(float(cycle_s[0]), float(cycle_s[1])))
    results = metabolics_from_legs(legs, body_mass_kg, height_m, **span, muscle_properties=muscle_properties,
                                   muscle_masses_kg=masses or None, slow_twitch_fractions=fractions or None, **options)
    if used:
        for r in results.values():
            r.muscle_parameters = f"OpenSim metabolic probes of the model: {used}"
    return results, used

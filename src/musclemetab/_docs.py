"""The documentation of the parameters that several functions share, written once.

``docdict`` holds the text of each parameter (its first line unindented, the following ones
indented as under the first); :func:`fill_doc` fills ``%(name)s`` in a docstring with it,
indented as the docstring is (the pattern of MNE-Python's ``fill_doc``). The solver's pipelines
(:mod:`musclemetab.redundancy`) and the energy models (:mod:`musclemetab.metabolics`) use it.
"""

from __future__ import annotations

import re

__all__ = ["docdict", "fill_doc"]

docdict = {
    "model": """model
    The OpenSim ``.osim`` model.""",
    "side_dofs": """side, dofs
    The leg (``"r"``/``"l"``) and its DOFs. ``dofs=None`` (default) discovers them from the
    model (:func:`musclemetab.layout.discover_dofs`): the side's unlocked coordinates that the
    inverse dynamics holds a moment for (every trial's ID file; for the example subject the
    study's five right-leg DOFs).""",
    "passive": """passive
    Calibrated passive parameters of EFFORT-CAL, EFFORT-TEN and EMG-TEN: a
    ``passive_parameters.csv`` (``muscle,kPE,s0,sM``), the study's ``passiveMoments.mat`` or a
    :class:`~musclemetab.passive.PassiveParameters` (default: the published calibration shipped
    with the package).""",
    "emg_mapping": """emg_mapping
    EMG channels of the muscles: ``"default"`` (vastus intermedius tracks ``VI_a`` = mean of VL
    and VM, as the study describes), ``"authors"`` (vastus intermedius tracks ``ES``, as in the
    published example results), a ``{muscle: [channels]}`` mapping or a JSON file holding one.""",
    "labels": """labels
    Trial names (the folders of :meth:`.Result.write`); default the IK file stems.""",
    "cache_dir": """cache_dir
    Folder of the geometry and model caches (default: the package's).""",
    "check_units": """check_units
    Check the units of the inputs (IK angles, moments per body mass and per muscle capacity);
    ``False`` skips those checks (``--skip-unit-checks``).""",
    "options": """options
    :class:`~.ipopt.SolverOptions`: IPOPT's linear solver, iteration limit, print level
    (default ``SolverOptions()``).""",
    # the arguments every energy model takes (musclemetab.metabolics)
    "energy_model_arguments": """excitation : array_like
    Neural excitation ``e`` (-), 0..1.
activation : array_like
    Muscle activation ``a`` (-), 0..1.
normalized_fiber_length : array_like
    ``l~M = lM / lMo`` (-).
normalized_fiber_velocity : array_like
    ``vbar = v~M / vmax`` (-), fiber velocity in optimal lengths per second divided by
    the maximal contraction velocity (OpenSim's definition; -1..1); positive =
    lengthening. The fiber velocity in m/s is ``V_CE = vbar * vmax * lMo``.
active_force_length_multiplier : array_like
    ``fL(l~M)`` (-).
force_velocity_multiplier : array_like
    ``fV(vbar)`` (-).
passive_fiber_force_N : array_like
    Passive fiber force ``F0 * fPE(l~M)`` along the fiber (N).
max_isometric_force_N, optimal_fiber_length_m : array_like
    ``F0`` (N) and ``lMo`` (m), per muscle.
max_contraction_velocity : array_like
    ``vmax`` in optimal fiber lengths per second (10 in the study), per muscle.
muscle_mass_kg : array_like
    Muscle mass ``m`` (kg), per muscle.
slow_twitch_fraction : array_like
    Fraction of slow-twitch fibers ``f_ST`` (-), per muscle; ``f_FT = 1 - f_ST``.
time_s : array_like, optional
    Time (s) along the last axis; used only by models with a time-dependent term.
basal : bool
    Add the basal heat ``basal_rate_W_per_kg * m`` to the muscle's rate (after the
    non-negativity rule), as the study's code does (``basalOn = 1``). The paper instead
    adds 1.2 W/kg of *body* mass to the whole-body rate: see
    :func:`musclemetab.metabolics.whole_body_rate`, which removes this component
    under that rule.
basal_rate_W_per_kg : float
    Basal rate per kg of muscle mass (1.2).
check : bool
    Check shapes and values (finite states, positive parameters). Turn off only for
    inputs already checked.

Arguments are matched by name; states broadcast against each other, parameters are
aligned with the leading axes of the states (``(M,)`` for ``(M, T)`` states).

Returns
-------
MetabolicRates
    ``work``, ``activation_maintenance``, ``shortening_lengthening``, ``basal`` and
    ``total`` (W), arrays of the broadcast shape, plus model-specific ``extras`` (W).""",
    # the options of the Umberger family (musclemetab.metabolics.umberger)
    "umberger_options": """effort_scaling : float
    The factor ``S`` of both heats: 1.5 for aerobic activity (default: the study's value
    and OpenSim's ``aerobic_factor``), 1.0 for anaerobic activity (Umberger et al.
    2003; :data:`AEROBIC_FACTOR`, :data:`ANAEROBIC_FACTOR`).
minimum_heat_rate_W_per_kg : float or None
    Where the heat rate ``H_AM + H_SL`` of a muscle falls below this many W per kg of
    muscle mass, raise it to that value (``H_AM`` takes it, ``H_SL = 0``), before the
    non-negativity rule; Umberger et al. (2003) and OpenSim's
    ``enforce_minimum_heat_rate_per_muscle`` (1 W/kg, :data:`MINIMUM_HEAT_RATE_W_PER_KG`).
    Default None: not applied (commented out in the study's code).""",
}


_FIELD = re.compile(r"%\((\w+)\)s")


def fill_doc(func):
    """Fill ``%(name)s`` in ``func.__doc__`` with :data:`docdict`, indented as the docstring
    (its lines after the first, at the docstring's indentation); an unknown name raises
    :class:`KeyError`."""
    doc = func.__doc__
    if not doc:
        return func
    lines = doc.splitlines()
    indent = min((len(ln) - len(ln.lstrip()) for ln in lines[1:] if ln.strip()), default=0)
    pad = " " * indent

    def text(match):
        return "\n".join(ln if i == 0 or not ln else pad + ln for i, ln in enumerate(docdict[match[1]].splitlines()))

    func.__doc__ = _FIELD.sub(text, doc)
    return func

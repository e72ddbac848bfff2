"""The documentation of the parameters that the solver's pipelines share, written once.

``docdict`` holds the text of each parameter; :func:`fill_doc` fills ``%(name)s`` in a
docstring with it, indented as the docstring is (the pattern of MNE-Python's ``fill_doc``).
"""

from __future__ import annotations

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
}


def fill_doc(func):
    """Fill ``%(name)s`` in ``func.__doc__`` with :data:`docdict`, indented as the docstring."""
    doc = func.__doc__
    lines = doc.splitlines()
    indent = min((len(ln) - len(ln.lstrip()) for ln in lines[1:] if ln.strip()), default=0)
    pad = " " * indent
    filled = {k: "\n".join(ln if i == 0 or not ln else pad + ln for i, ln in enumerate(v.splitlines()))
              for k, v in docdict.items()}
    func.__doc__ = doc % filled
    return func

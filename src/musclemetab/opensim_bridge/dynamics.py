"""Inverse dynamics with OpenSim's InverseDynamicsTool (run inside the OpenSim worker only).

:func:`inverse_dynamics` runs the tool as OpenSim's GUI and command line do: the model's
muscles are excluded from the dynamics, the external loads are applied as the
``ExternalLoads`` file says, and the coordinates are low-pass filtered by the tool before
they are differentiated (``lowpass_cutoff_frequency_for_coordinates``; OpenSim's example
setups use 6 Hz). The generalised forces are written in OpenSim's format: ``<coordinate>_moment``
(N m) for rotational and ``<coordinate>_force`` (N) for translational coordinates.
"""

from __future__ import annotations

import os
import tempfile

import opensim as osim

from ..errors import ModelError


def inverse_dynamics(
    model_path: str,
    coordinates_path: str,
    external_loads_path: str,
    start_s: float,
    end_s: float,
    out_path: str,
    lowpass_cutoff_hz: float = 6.0,
) -> str:
    """Run the InverseDynamicsTool over ``[start_s, end_s]`` and write ``out_path`` (.sto).

    ``external_loads_path`` must name an ExternalLoads XML whose ``datafile`` is an absolute
    path (the caller writes such a copy; OpenSim would otherwise resolve it against the
    working directory).
    """
    try:
        model = osim.Model(os.path.abspath(model_path))
        model.initSystem()
    except Exception as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ModelError(f"{model_path}: OpenSim cannot load this model ({msg})") from None
    tool = osim.InverseDynamicsTool()
    tool.setModel(model)
    tool.setCoordinatesFileName(os.path.abspath(coordinates_path))
    tool.setExternalLoadsFileName(os.path.abspath(external_loads_path))
    tool.setLowpassCutoffFrequency(float(lowpass_cutoff_hz))
    tool.setStartTime(float(start_s))
    tool.setEndTime(float(end_s))
    excluded = osim.ArrayStr()
    excluded.append("muscles")
    tool.setExcludedForces(excluded)
    with tempfile.TemporaryDirectory(prefix="musclemetab-id-") as tmp:
        tool.setResultsDir(tmp)
        tool.setOutputGenForceFileName("inverse_dynamics.sto")
        if not tool.run():
            raise RuntimeError("OpenSim's InverseDynamicsTool reported a failure")
        with open(os.path.join(tmp, "inverse_dynamics.sto"), "rb") as src:
            data = src.read()
    with open(out_path, "wb") as dst:
        dst.write(data)
    return out_path

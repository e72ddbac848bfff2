"""The boundary to OpenSim: the only package that imports ``opensim``.

``opensim`` 4.6 bundles its own CasADi library under the same shared-library name as the
``casadi`` package, so the two cannot live in one Python process. Everything that needs
OpenSim therefore runs in a separate, persistent worker process started with
``python -m musclemetab.opensim_bridge.worker``; callers get plain Python objects and
NumPy arrays back through :func:`call`. The worker starts on first use (its start-up,
about half a second, is paid once per calling process) and stops when the caller exits.

Functions run in the worker live in the modules of this package that import ``opensim``
(:mod:`.model_ops`, :mod:`.probes`, :mod:`.states`, :mod:`.solution_model`, ...); call them by name::

    from musclemetab.opensim_bridge import call
    info = call("model_ops:read_model_info", "model.osim")
"""

from .client import call, call_in_background, shutdown, start_in_background, worker_startup_s

__all__ = ["call", "call_in_background", "shutdown", "start_in_background", "worker_startup_s"]

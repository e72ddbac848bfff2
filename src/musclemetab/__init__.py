"""musclemetab: muscle-by-muscle metabolic energy of walking.

From an OpenSim model, inverse kinematics and inverse dynamics (and optionally EMG),
musclemetab solves the muscle redundancy problem with compliant tendons and evaluates
literature models of muscle metabolic energy, muscle by muscle and instant by instant.

Importing the package is cheap: it imports neither ``opensim`` nor ``casadi``. The two
cannot share a process (they ship the same shared library), so OpenSim runs in a worker
process (:mod:`musclemetab.opensim_bridge`) and CasADi in the caller's.
"""

import logging

from .errors import MusclemetabError

# a library leaves the handling of its records to the application (messages.configure for the command line)
logging.getLogger("musclemetab").addHandler(logging.NullHandler())

__all__ = ["MusclemetabError", "__version__"]


def __getattr__(name):
    # ``__version__`` is read from the installed package's metadata when first asked for:
    # importing importlib.metadata costs a tenth of a second that most commands never need.
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("musclemetab")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree
            value = "0+unknown"
        globals()["__version__"] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

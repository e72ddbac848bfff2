"""musclemetab: muscle-by-muscle metabolic energy of walking.

From an OpenSim model, inverse kinematics and inverse dynamics (and optionally EMG),
musclemetab solves the muscle redundancy problem with compliant tendons and evaluates
literature models of muscle metabolic energy, muscle by muscle and instant by instant.

Importing the package is cheap: it imports neither ``opensim`` nor ``casadi``. The two
cannot share a process (they ship the same shared library), so OpenSim runs in a worker
process (:mod:`musclemetab.opensim_bridge`) and CasADi in the caller's.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from .errors import MusclemetabError

try:
    __version__ = _version("musclemetab")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

__all__ = ["MusclemetabError", "__version__"]

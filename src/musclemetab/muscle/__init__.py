"""The Hill-type muscle-tendon model: curves (NumPy and CasADi from one source)."""

from .curves import *  # noqa: F401,F403
from .curves import __all__ as _curves_all

__all__ = list(_curves_all)

"""Gait events and the gait cycle: the names of :mod:`musclemetab.events`, where they are
defined (the solver's window needs them before any analysis runs)."""

from ..events import *  # noqa: F401,F403
from ..events import __all__  # noqa: F401

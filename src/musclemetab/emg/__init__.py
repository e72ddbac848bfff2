"""EMG: processing raw signals into normalised envelopes and mapping channels to muscles."""

from .processing import *  # noqa: F401,F403
from .processing import __all__ as _all

__all__ = list(_all)

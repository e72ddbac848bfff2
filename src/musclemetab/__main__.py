"""``python -m musclemetab``: the ``musclemetab`` command (:mod:`musclemetab.commands`)."""

import sys

from .commands import main

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

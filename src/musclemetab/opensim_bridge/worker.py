"""The OpenSim worker process (``python -m musclemetab.opensim_bridge.worker``).

It imports ``opensim`` once, then serves calls from :mod:`.client` until its input closes, and
then ends at once (``os._exit``: every call has finished its files, and freeing the models it
keeps would take the caller's exit a few tenths of a second).
OpenSim writes log messages to standard output; the protocol stream is therefore a
duplicate of the original stdout, and file descriptor 1 is pointed at stderr. OpenSim's log is
kept to errors and its log file (``opensim.log``, which OpenSim otherwise writes into the
working folder) is switched off.
"""

from __future__ import annotations

import importlib
import os
import sys


def main() -> int:
    import signal

    # Ctrl-C is for the process that drives this worker (it stops asking); the worker ends
    # when its input closes.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    proto_out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # anything printed (OpenSim's log) goes to stderr
    proto_in = sys.stdin.buffer

    from .client import receive_message, send_message

    try:
        import opensim

        opensim.Logger.setLevelString("error")
        opensim.Logger.removeFileSink()  # no opensim.log in the user's working folder
    except Exception as exc:  # pragma: no cover - environment problem
        send_message(proto_out, ("failed", f"{type(exc).__name__}: {exc}"))
        return 1
    send_message(proto_out, ("ready", opensim.__version__))

    while True:
        try:
            target, args, kwargs = receive_message(proto_in)
        except EOFError:  # the caller is done: end at once, without tearing down OpenSim's models
            sys.stderr.flush()
            os._exit(0)
        try:
            mod_name, func_name = target.split(":")
            mod = importlib.import_module(f"musclemetab.opensim_bridge.{mod_name}")
            result = ("ok", getattr(mod, func_name)(*args, **kwargs))
        except Exception as exc:  # returned to the caller, which raises it
            from ..errors import MusclemetabError

            if not isinstance(exc, MusclemetabError):
                exc = RuntimeError(f"{type(exc).__name__}: {exc}")
            result = ("error", exc)
        send_message(proto_out, result)


if __name__ == "__main__":
    sys.exit(main())

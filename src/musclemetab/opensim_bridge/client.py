"""Client side of the OpenSim worker: start it, send calls, return results.

Wire protocol (pipes, one request at a time): each message is an 8-byte big-endian length
followed by a pickle. Request: ``(target, args, kwargs)`` with ``target = "module:function"``
relative to :mod:`musclemetab.opensim_bridge`. Reply: ``("ok", result)`` or
``("error", exception)``; package errors (``MusclemetabError``) are re-raised as they are.
"""

from __future__ import annotations

import atexit
import os
import pickle
import struct
import subprocess
import sys
import threading
import time

from ..errors import MusclemetabError, OpenSimWorkerError

_LOCK = threading.Lock()
_PROC: subprocess.Popen | None = None
_STARTUP_S: float | None = None
#: the worker being started (before it reports ready), so that an exit during its start stops it
_STARTING: subprocess.Popen | None = None


def send_message(stream, obj) -> None:
    """Write one message of the worker protocol: the pickle of ``obj`` after its length (8 bytes)."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack(">Q", len(data)))
    stream.write(data)
    stream.flush()


def receive_message(stream):
    """Read one message written by :func:`send_message`; :class:`EOFError` when the stream ends."""
    head = stream.read(8)
    if len(head) < 8:
        raise EOFError
    (n,) = struct.unpack(">Q", head)
    data = stream.read(n)
    if len(data) < n:
        raise EOFError
    return pickle.loads(data)


def _start() -> subprocess.Popen:
    global _STARTUP_S, _STARTING
    t0 = time.perf_counter()
    env = dict(os.environ)
    proc = _STARTING = subprocess.Popen(
        [sys.executable, "-m", "musclemetab.opensim_bridge.worker"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=None if env.get("MUSCLEMETAB_OPENSIM_VERBOSE") else subprocess.DEVNULL,
        env=env,
    )
    try:
        ready = receive_message(proc.stdout)
    except EOFError:
        proc.kill()
        raise OpenSimWorkerError(
            "the OpenSim worker process did not start; check that the 'opensim' package (4.6) "
            "imports in this environment: python -c 'import opensim'"
        ) from None
    if ready[0] != "ready":
        proc.kill()
        raise OpenSimWorkerError(f"the OpenSim worker process failed to start: {ready[1]}")
    _STARTUP_S = time.perf_counter() - t0
    return proc


def _ensure_started() -> None:
    global _PROC
    if _PROC is None or _PROC.poll() is not None:
        _PROC = _start()


def start_in_background() -> None:
    """Start the worker in a background thread, so that its start-up (``import opensim``,
    about a second) overlaps with the caller's work; :func:`call` waits for it. A start-up
    failure is reported by the next :func:`call`."""

    def run():
        with _LOCK:
            try:
                _ensure_started()
            except Exception:  # reported again by call()
                pass

    threading.Thread(target=run, daemon=True).start()


def call(target: str, *args, **kwargs):
    """Run ``module:function`` of :mod:`musclemetab.opensim_bridge` in the OpenSim worker."""
    global _PROC
    with _LOCK:
        _ensure_started()
        try:
            send_message(_PROC.stdin, (target, args, kwargs))
            status, payload = receive_message(_PROC.stdout)
        except (EOFError, BrokenPipeError):
            code = _PROC.poll()
            _PROC = None
            raise OpenSimWorkerError(
                f"the OpenSim worker process ended unexpectedly (exit code {code}) while running "
                f"{target}; set MUSCLEMETAB_OPENSIM_VERBOSE=1 to see OpenSim's messages"
            ) from None
        except BaseException:  # Ctrl-C mid-call: its reply would be read by the next call
            _PROC.kill()
            _PROC.wait()
            _PROC = None
            raise
    if status == "ok":
        return payload
    if isinstance(payload, MusclemetabError):
        raise payload
    raise OpenSimWorkerError(f"OpenSim failed in {target}: {payload}")


def call_in_background(target: str, *args, **kwargs) -> None:
    """Run ``module:function`` in the worker from a background thread of this process, for work
    done ahead whose result the worker keeps (e.g. :func:`.solution_model.prepare_solution_model`
    while the caller solves); nobody reads its result. The worker is a separate process, so the
    work runs beside the caller's. The next :func:`call` waits until its reply is in (one call at a
    time: each reply is read by the thread that sent the request). A failure is ignored: the call
    that needs the work does it again and reports it."""

    def run():
        try:
            call(target, *args, **kwargs)
        except Exception:  # done again, and reported, by the call that needs it
            pass

    threading.Thread(target=run, daemon=True).start()


def worker_startup_s() -> float | None:
    """Seconds the worker took to start (process start plus ``import opensim``), if started."""
    return _STARTUP_S


#: seconds the worker has to end once its input is closed (it ends at once when idle); a worker
#: still busy then, with work nobody waits for, is killed so that an exit is never held up by it
SHUTDOWN_WAIT_S = 1.0


def shutdown() -> None:
    """Stop the worker process (it is restarted on the next call). When another thread is
    starting it or waiting for a reply (an exit after Ctrl-C), the process is killed at once;
    an idle worker ends when its input closes, one that does not within :data:`SHUTDOWN_WAIT_S`
    is killed."""
    global _PROC
    if not _LOCK.acquire(timeout=0.2):
        starting = _STARTING
        if starting is not None and starting.poll() is None:
            starting.kill()
        return
    try:
        if _PROC is not None and _PROC.poll() is None:
            try:
                _PROC.stdin.close()
                _PROC.wait(timeout=SHUTDOWN_WAIT_S)
            except Exception:  # still busy (TimeoutExpired), or its input already broken
                _PROC.kill()
                _PROC.wait()
        if _PROC is not None:  # the worker's end of the pipes: closed, not left to the garbage collector
            for pipe in (_PROC.stdin, _PROC.stdout):
                try:
                    pipe.close()
                except Exception:  # pragma: no cover - best effort
                    pass
        _PROC = None
    finally:
        _LOCK.release()


atexit.register(shutdown)

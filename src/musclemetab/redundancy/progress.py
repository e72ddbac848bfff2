"""Progress lines of a running IPOPT solve: at most one line every :data:`PROGRESS_INTERVAL_S`
seconds on standard error (iteration, objective, constraint violation, time), while
:class:`solve_progress` is active."""

from __future__ import annotations

import time as _time

import numpy as np

from ..processes import interrupt_noted

__all__ = ["PROGRESS_INTERVAL_S", "solve_progress", "progress_interval", "ProgressLines"]


#: Seconds between two progress lines of a running solve (:func:`solve_progress`).
PROGRESS_INTERVAL_S = 5.0
_PROGRESS: dict = {"stream": None, "interval_s": None, "label": ""}


class solve_progress:
    """While this context is active, every IPOPT solve of this process writes a progress line
    at most every ``interval_s`` seconds (default :data:`PROGRESS_INTERVAL_S`) to ``stream``
    (default: a record of level INFO of the logger ``musclemetab.progress``, which the command
    line prints on standard error unless ``-q``)::

        musclemetab: solving: iteration 40, objective 2.7012e-01, constraint violation 3.1e-05, 21 s

    The line comes from IPOPT's iteration callback (CasADi's ``iteration_callback`` option):
    the iteration number, the objective and the largest violation of a constraint's bounds
    (unscaled, at the current iterate) and the time since the solve started. It does not change
    the solve: the callback only reads the iterate. ``musclemetab solve`` and ``estimate`` use it
    unless given ``--no-progress``; the legs of ``solve --side both --workers 2``, solved in other
    processes, turn it on there with the interval of this process (:func:`progress_interval`)
    and ``label`` naming the leg (``musclemetab: solving side l: iteration 40, ...``).
    """

    def __init__(self, interval_s: float | None = None, stream=None, label: str = ""):
        self.interval_s, self.stream, self.label = interval_s, stream, label
        self._previous = None

    def __enter__(self):
        self._previous = dict(_PROGRESS)
        _PROGRESS.update(stream=self.stream, interval_s=PROGRESS_INTERVAL_S if self.interval_s is None
                         else float(self.interval_s), label=self.label)
        return self

    def __exit__(self, *exc):
        _PROGRESS.clear()
        _PROGRESS.update(self._previous)
        return False


def progress_interval() -> float | None:
    """The interval (s) of the progress lines :func:`solve_progress` turned on in this process,
    or ``None`` when they are off."""
    return _PROGRESS.get("interval_s")


class ProgressLines:
    """Writes the progress lines of :func:`solve_progress` for one solve: :meth:`iteration` is
    called with each iterate; a line is written when ``interval_s`` has passed since the start
    or the last line (``clock``: seconds, default :func:`time.perf_counter`); ``label`` follows
    ``solving`` (e.g. `` side r``)."""

    def __init__(self, lbg, ubg, interval_s: float, stream=None, clock=None, label: str = ""):
        self.lbg, self.ubg = np.asarray(lbg, dtype=float).reshape(-1), np.asarray(ubg, dtype=float).reshape(-1)
        self.interval_s = float(interval_s)
        self.stream = stream  # None: the package's logger ``musclemetab.progress``, level INFO
        self.clock = clock or _time.perf_counter
        self.t0 = self.last = self.clock()
        self.count = 0
        self.lines = 0
        self.label = label

    def iteration(self, f, g) -> None:
        """One IPOPT iterate: objective ``f`` and constraint values ``g``."""
        self.count += 1
        now = self.clock()
        if now - self.last < self.interval_s:
            return
        self.last = now
        g = np.asarray(g, dtype=float).reshape(-1)
        viol = float(np.max(np.maximum(self.lbg - g, 0.0) + np.maximum(g - self.ubg, 0.0))) if g.size else 0.0
        # IPOPT calls back once for the starting point (iteration 0); a stream that cannot be
        # written (closed, full) loses the line, never the solve
        text = (f"solving{self.label}: iteration {self.count - 1}, objective {float(f):.4e}, "
                f"constraint violation {viol:.1e}, {now - self.t0:.0f} s")
        if self.stream is None:
            from ..messages import logger

            logger("progress").info(text)
            self.lines += 1
            return
        from ..messages import write_quietly

        self.lines += write_quietly(self.stream, f"musclemetab: {text}\n")


def _progress_callback(n_x: int, n_g: int, lbg, ubg):
    """The CasADi ``iteration_callback`` of :func:`solve_progress`, or ``None`` when it is off."""
    if _PROGRESS.get("interval_s") is None:
        return None
    import casadi as ca

    lines = ProgressLines(lbg, ubg, _PROGRESS["interval_s"], _PROGRESS.get("stream"), label=_PROGRESS.get("label", ""))

    class _Callback(ca.Callback):
        def __init__(self):
            ca.Callback.__init__(self)
            self.construct("musclemetab_progress", {})

        def get_n_in(self):
            return ca.nlpsol_n_out()

        def get_n_out(self):
            return 1

        def get_name_in(self, i):
            return ca.nlpsol_out(i)

        def get_name_out(self, i):
            return "ret"

        def get_sparsity_in(self, i):
            n = ca.nlpsol_out(i)
            size = {"f": 1, "x": n_x, "lam_x": n_x, "g": n_g, "lam_g": n_g}.get(n, 0)
            return ca.Sparsity.dense(size, 1)

        def eval(self, arg):
            try:
                names = [ca.nlpsol_out(i) for i in range(ca.nlpsol_n_out())]
                values = dict(zip(names, arg))
                lines.iteration(float(values["f"]), np.asarray(values["g"]).reshape(-1))
            except BaseException:
                # Ctrl-C during the callback (it may come inside CasADi's conversion of its arguments,
                # as an error that chains it): IPOPT is asked to stop (1), without CasADi's traceback;
                # processes.sigint_noted raises the interrupt once IPOPT has returned
                if interrupt_noted():
                    return [1]
                raise
            # Ctrl-C noted but its KeyboardInterrupt lost on the way (raised where Python drops it, such
            # as a weakref callback): IPOPT is asked to stop all the same
            return [1] if interrupt_noted() else [0]

    return _Callback()

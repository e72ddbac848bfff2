"""What every metabolic energy model shares: inputs, checks, the result type, the rules
that close a model (non-negativity, basal heat), and the evaluation of a model's equations
in cache-sized chunks on several threads (:func:`evaluate_chunked`).

All models take the same arguments (see :data:`SHARED_PARAMETERS_DOC`):

* seven muscle-state arrays of any common (broadcastable) shape, conventionally
  ``(muscles, time)``;
* five muscle parameters, scalars or arrays whose shape matches the *leading* axes of the
  states (``(M,)`` for states of shape ``(M, T)``) and which are broadcast along the
  trailing (time) axes. This differs from NumPy's trailing-axis rule on purpose: a
  per-muscle array can never be matched against the time axis by accident.

Sign conventions (``docs/metabolics.md``): fibre velocity is positive when the fibre
lengthens; the mechanical work rate ``W_CE = -F_CE V_CE`` is positive when the muscle does
work (shortening).

Chunk kernels write every intermediate into preallocated arrays (ufuncs with an output
argument) and select between branches on the bit patterns (:func:`select_into`), with the
same floating-point operations, in the same order, as the plain array formulas they
replace: results do not depend on the chunk size or the number of threads.
"""

from __future__ import annotations

import contextvars
import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..errors import DataMismatchError, OptionError

__all__ = [
    "BASAL_RATE_W_PER_KG",
    "MetabolicRates",
    "COMPONENTS",
    "STATE_ARGUMENTS",
    "PARAMETER_ARGUMENTS",
    "MuscleInputs",
    "prepare_inputs",
    "apply_non_negativity",
    "basal_rate",
    "basal_view",
    "shared_doc",
    "full_shape",
    "evaluate_chunked",
    "ChunkPlan",
    "run_chunks",
    "evaluation_threads",
    "non_negativity_into",
    "as_mask",
    "select_into",
    "keep_where",
    "total_into",
    "recruitment_terms",
    "recruitment_terms_into",
    "CHUNK_SIZE",
    "THREADS",
    "check_flag",
    "model_function",
]

#: Basal metabolic rate (W/kg), Umberger et al. (2003). The study's code adds it per kg of
#: *muscle* mass to every muscle; the paper adds it per kg of *body* mass (see
#: :mod:`musclemetab.metabolics.whole_body`).
BASAL_RATE_W_PER_KG = 1.2

#: The five components every model returns, in W.
COMPONENTS = ("work", "activation_maintenance", "shortening_lengthening", "basal", "total")

STATE_ARGUMENTS = (
    "excitation",
    "activation",
    "normalized_fiber_length",
    "normalized_fiber_velocity",
    "active_force_length_multiplier",
    "force_velocity_multiplier",
    "passive_fiber_force_N",
)

PARAMETER_ARGUMENTS = (
    "max_isometric_force_N",
    "optimal_fiber_length_m",
    "max_contraction_velocity",
    "muscle_mass_kg",
    "slow_twitch_fraction",
)

SHARED_PARAMETERS_DOC = """\
    excitation : array_like
        Neural excitation ``e`` (-), 0..1.
    activation : array_like
        Muscle activation ``a`` (-), 0..1.
    normalized_fiber_length : array_like
        ``l~M = lM / lMo`` (-).
    normalized_fiber_velocity : array_like
        ``vbar = v~M / vmax`` (-), fibre velocity in optimal lengths per second divided by
        the maximal contraction velocity (OpenSim's definition; -1..1); positive =
        lengthening. The fibre velocity in m/s is ``V_CE = vbar * vmax * lMo``.
    active_force_length_multiplier : array_like
        ``fL(l~M)`` (-).
    force_velocity_multiplier : array_like
        ``fV(vbar)`` (-).
    passive_fiber_force_N : array_like
        Passive fibre force ``F0 * fPE(l~M)`` along the fibre (N).
    max_isometric_force_N, optimal_fiber_length_m : array_like
        ``F0`` (N) and ``lMo`` (m), per muscle.
    max_contraction_velocity : array_like
        ``vmax`` in optimal fibre lengths per second (10 in the study), per muscle.
    muscle_mass_kg : array_like
        Muscle mass ``m`` (kg), per muscle.
    slow_twitch_fraction : array_like
        Fraction of slow-twitch fibres ``f_ST`` (-), per muscle; ``f_FT = 1 - f_ST``.
    time_s : array_like, optional
        Time (s) along the last axis; used only by models with a time-dependent term.
    basal : bool
        Add the basal heat ``basal_rate_W_per_kg * m`` to the muscle's rate (after the
        non-negativity rule), as the study's code does (``basalOn = 1``). The paper instead
        adds 1.2 W/kg of *body* mass to the whole-body rate: see
        :func:`musclemetab.metabolics.whole_body_rate`, which removes this component
        under that rule.
    basal_rate_W_per_kg : float
        Basal rate per kg of muscle mass (1.2).
    check : bool
        Check shapes and values (finite states, positive parameters). Turn off only for
        inputs already checked.

    Arguments are matched by name; states broadcast against each other, parameters are
    aligned with the leading axes of the states (``(M,)`` for ``(M, T)`` states).

    Returns
    -------
    MetabolicRates
        ``work``, ``activation_maintenance``, ``shortening_lengthening``, ``basal`` and
        ``total`` (W), arrays of the broadcast shape, plus model-specific ``extras`` (W)."""


def shared_doc(func):
    """Insert the shared parameter documentation at ``%(shared)s`` in a docstring."""
    if func.__doc__:
        func.__doc__ = func.__doc__.replace("%(shared)s", SHARED_PARAMETERS_DOC)
    return func


@dataclass(frozen=True, eq=False)
class MetabolicRates:
    """Metabolic rates of one model, per component, in W (arrays of one shape).

    ``total = work + activation_maintenance + shortening_lengthening + basal``, where
    ``work`` is the mechanical work rate the model counts (for UM10 only the positive,
    concentric part) and the heats are those after the model's non-negativity rule.
    ``extras`` holds model-specific sub-components in W (for instance BH04's and HO06's
    separate ``activation`` and ``maintenance`` heats). ``basal`` is constant in time: a
    read-only broadcast view of the per-muscle value (copy it to modify it).
    """

    model: str
    work: np.ndarray
    activation_maintenance: np.ndarray
    shortening_lengthening: np.ndarray
    basal: np.ndarray
    total: np.ndarray
    extras: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def heat(self) -> np.ndarray:
        """Total heat rate (W): activation/maintenance + shortening/lengthening + basal."""
        return self.activation_maintenance + self.shortening_lengthening + self.basal

    @property
    def shape(self) -> tuple[int, ...]:
        return self.total.shape

    def components(self) -> dict[str, np.ndarray]:
        """All components, the five standard ones first, then the extras (W)."""
        out = {name: getattr(self, name) for name in COMPONENTS}
        out.update(self.extras)
        return out

    def __getitem__(self, name: str) -> np.ndarray:
        comps = self.components()
        if name not in comps:
            raise OptionError(
                f"model {self.model} has no component '{name}'; it has {', '.join(comps)}"
            )
        return comps[name]

    def total_without_basal(self) -> np.ndarray:
        """``total - basal`` (W): the muscle's rate without any basal heat."""
        return self.total - self.basal


class MuscleInputs:
    """Checked inputs of a model call: NumPy arrays, parameters aligned for broadcasting.

    ``unchecked`` maps the names of the large states whose finiteness check was deferred to
    the model's evaluation (``prepare_inputs(..., defer_large=True)``) to their arrays;
    :func:`evaluate_chunked` with ``inputs=`` checks them chunk by chunk.
    """

    __slots__ = STATE_ARGUMENTS + PARAMETER_ARGUMENTS + ("shape", "ndim", "model", "unchecked")

    def states(self) -> dict[str, np.ndarray]:
        """The seven state arrays by name, in argument order."""
        return {name: getattr(self, name) for name in STATE_ARGUMENTS}


def _as_float(name: str, value, model: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise OptionError(
            f"{model}: argument '{name}' must be numeric (a number or an array of numbers), "
            f"not {type(value).__name__}"
        ) from None
    return arr


def _check_finite(name: str, arr: np.ndarray, model: str) -> None:
    if arr.ndim == 0:
        ok = bool(np.isfinite(arr))
    else:
        ok = bool(np.isfinite(arr).all())
    if not ok:
        bad = ~np.isfinite(arr)
        n_bad = int(bad.sum())
        where = np.unravel_index(int(np.flatnonzero(bad.ravel())[0]), arr.shape) if arr.ndim else ()
        kind = "NaN" if np.isnan(arr).any() else "infinite"
        raise OptionError(
            f"{model}: argument '{name}' holds {kind} values ({n_bad} of {arr.size}, first at index "
            f"{tuple(int(i) for i in where)}); remove or interpolate them before computing metabolic rates"
        )


def _check_states_finite(states: Mapping[str, np.ndarray], model: str) -> None:
    """:func:`_check_finite` for each state in order; large contiguous arrays are scanned in
    chunks on several threads (the first non-finite state raises, as checked one by one)."""
    pieces = []  # (name, flat array, start, stop) of the large arrays
    step = 4 * CHUNK_SIZE  # a test of finiteness per element is cheap: longer pieces
    for name, arr in states.items():
        if arr.size >= max(2 * step, PARALLEL_MIN_SIZE) and arr.flags.c_contiguous:
            flat = arr.reshape(-1)
            for start in range(0, flat.size, step):
                pieces.append((name, flat, start, min(flat.size, start + step)))
    finite = dict.fromkeys(states, True)
    if pieces:

        def work(i, arrays):
            name, flat, start, stop = pieces[i]
            ok = arrays[0][: stop - start]
            np.isfinite(flat[start:stop], ok)
            if not ok.all():
                finite[name] = False

        run_chunks(len(pieces), work, scratch="?", scratch_size=step)
    scanned = {name for name, *_ in pieces}
    for name, arr in states.items():
        if name not in scanned or not finite[name]:
            _check_finite(name, arr, model)


def _deferrable(arr: np.ndarray) -> bool:
    """Whether the finiteness check of a state can be left to the chunks of the evaluation."""
    return arr.size >= max(2 * CHUNK_SIZE, PARALLEL_MIN_SIZE) and arr.flags.c_contiguous


def prepare_inputs(
    model: str, values: Mapping[str, object], check: bool = True, defer_large: bool = False
) -> MuscleInputs:
    """Convert, check and align the shared model arguments.

    With ``defer_large=True`` the finiteness of large contiguous states is not scanned here
    but recorded in ``unchecked``, for :func:`evaluate_chunked` (``inputs=``) to check each
    chunk while it is in the processor's caches: one pass over memory fewer. The errors are
    the same (the first non-finite state in argument order is named).

    Raises
    ------
    DataMismatchError
        State arrays do not broadcast together, or a parameter's shape is not the leading
        part of the states' shape.
    OptionError
        A value is not numeric, not finite, or out of its range (``F0``, ``lMo``, ``vmax``
        > 0; mass >= 0; ``0 <= f_ST <= 1``).
    """
    out = MuscleInputs()
    states = {}
    for name in STATE_ARGUMENTS:
        try:
            states[name] = _as_float(name, values[name], model)
        except OptionError:
            if check:  # a non-finite state before this one is reported first
                _check_states_finite(states, model)
            raise
    unchecked = {}
    if check:
        if defer_large:
            unchecked = {name: arr for name, arr in states.items() if _deferrable(arr)}
        try:
            _check_states_finite({k: v for k, v in states.items() if k not in unchecked}, model)
        except OptionError:
            _check_states_finite(states, model)  # a deferred state before it is reported first
            raise
    try:
        shape = np.broadcast_shapes(*(a.shape for a in states.values()))
    except ValueError:
        shapes = ", ".join(f"{k} {v.shape}" for k, v in states.items())
        raise DataMismatchError(
            f"{model}: the muscle-state arrays do not have compatible shapes ({shapes}); give them "
            "one shape, e.g. (muscles, time)"
        ) from None
    ndim = len(shape)
    full = shape
    for name in PARAMETER_ARGUMENTS:
        arr = _as_float(name, values[name], model)
        if arr.ndim > ndim:
            raise DataMismatchError(
                f"{model}: parameter '{name}' has shape {arr.shape} but the muscle states have shape "
                f"{shape}; give one value per muscle (shape {shape[:1]}) or a scalar"
            )
        lead = shape[: arr.ndim]
        if any(p != s and p != 1 and s != 1 for p, s in zip(arr.shape, lead)):
            raise DataMismatchError(
                f"{model}: parameter '{name}' has shape {arr.shape}, which does not match the leading "
                f"axes {lead} of the muscle states (shape {shape}); give one value per muscle"
            )
        if check:
            _check_finite(name, arr, model)
            if name == "slow_twitch_fraction":
                if np.any((arr < 0) | (arr > 1)):
                    raise OptionError(f"{model}: slow_twitch_fraction must lie in [0, 1]")
            elif name == "muscle_mass_kg":
                if np.any(arr < 0):
                    raise OptionError(f"{model}: muscle_mass_kg must not be negative (kg)")
            elif np.any(arr <= 0):
                raise OptionError(f"{model}: parameter '{name}' must be positive")
        arr = arr.reshape(arr.shape + (1,) * (ndim - arr.ndim))
        full = np.broadcast_shapes(full, arr.shape)
        setattr(out, name, arr)
    for name, arr in states.items():
        setattr(out, name, arr)
    out.shape = full
    out.ndim = len(full)
    out.model = model
    out.unchecked = unchecked
    return out


class _NonFiniteChunk(Exception):
    """A chunk of a deferred state holds a non-finite value (see :func:`evaluate_chunked`)."""


def _finish_checks(inputs: MuscleInputs, states: list) -> list[int]:
    """Positions in ``states`` of the deferred states of ``inputs`` (checked per chunk); the
    deferred states not among them are scanned now."""
    pending = inputs.unchecked
    if not pending:
        return []
    ids = {id(arr) for arr in pending.values()}
    positions = [k for k, s in enumerate(states) if id(s) in ids]
    covered = {id(states[k]) for k in positions}
    rest = {name: arr for name, arr in pending.items() if id(arr) not in covered}
    if rest:
        try:
            _check_states_finite(rest, inputs.model)
        except OptionError:
            _report_non_finite(inputs)  # names the first non-finite state in argument order
    return positions


def _report_non_finite(inputs: MuscleInputs) -> None:
    """Raise the error of the first non-finite state of ``inputs`` in argument order."""
    _check_states_finite(inputs.states(), inputs.model)
    raise AssertionError("a deferred state was found non-finite, but no state is")  # pragma: no cover


def apply_non_negativity(work, heats_other, h_sl, *, strict: bool):
    """Paper Eq. 3: where the total rate is negative, raise ``H_SL`` so the total is zero.

    ``strict=True`` tests ``total < 0`` (UM03), otherwise ``total <= 0`` (UC16, BH04,
    HO06); the two differ only where the total is exactly zero, where the result is the
    same up to rounding.
    """
    rest = work + heats_other
    total = rest + h_sl
    neg = total < 0 if strict else total <= 0
    return np.where(neg, -rest, h_sl)


def basal_view(basal_w: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The basal component of a result: the per-muscle basal heat (W, parameter-shaped)
    as a read-only view of the states' ``shape`` (constant in time: no memory per sample)."""
    return np.broadcast_to(basal_w, shape)


def basal_rate(inp: MuscleInputs, basal: bool, basal_rate_W_per_kg: float) -> np.ndarray:
    """Basal heat ``rate * m`` (W), parameter-shaped (zeros when off)."""
    if not basal:
        return np.zeros_like(inp.muscle_mass_kg)
    rate = float(basal_rate_W_per_kg)
    if not np.isfinite(rate) or rate < 0:
        raise OptionError(f"basal_rate_W_per_kg must be a non-negative number, not {basal_rate_W_per_kg!r}")
    return rate * inp.muscle_mass_kg


#: Samples per chunk when evaluating a model (512 kB per array: the operands and temporaries
#: of a chunk stay in the processor's caches, while NumPy's fixed cost per call, and the
#: hand-over of the interpreter lock between threads at each call, are paid once per 65 536
#: samples). Results do not depend on it.
CHUNK_SIZE = 65536

#: Threads that evaluate the chunks of one model call, the calling thread included
#: (``None``: one per processor core available to the process and not busy with other
#: work at the time of the call; ``1``: the calling thread only). NumPy releases the
#: interpreter lock in its array loops, so the chunks run in parallel. Results do not
#: depend on it.
THREADS = None

#: Arrays smaller than this many elements are evaluated by the calling thread alone.
PARALLEL_MIN_SIZE = 131072

#: Share of a processor below which a worker thread stops taking chunks (see
#: :func:`run_chunks`).
MIN_CPU_SHARE = 0.6


def evaluation_threads() -> int:
    """Threads used for a large model evaluation: :data:`THREADS`, or the processor cores
    available to the process less those busy with other work.

    Busy cores are counted from the runnable tasks of ``/proc/loadavg`` (Linux), when the
    process may run on every processor of the machine (otherwise, e.g. in a container
    restricted to some processors, the machine-wide count says nothing about them). Threads
    that share a core with other work are slower than one thread: each hand-over of the
    interpreter lock then costs a context switch.
    """
    if THREADS is not None:
        return max(1, int(THREADS))
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    if n > 1 and n == os.cpu_count():
        n -= min(n - 1, _other_runnable_tasks())
    return max(1, n)


def _other_runnable_tasks() -> int:
    """Tasks running or ready to run on the machine, besides the calling thread (Linux)."""
    try:
        with open("/proc/loadavg") as f:
            running = int(f.read().split()[3].split("/")[0])
    except (OSError, ValueError, IndexError):
        return 0
    return max(0, running - 1)


_POOL: ThreadPoolExecutor | None = None
_POOL_WORKERS = 0
_POOL_LOCK = threading.Lock()
_SCRATCH = threading.local()


def _pool(workers: int) -> ThreadPoolExecutor:
    global _POOL, _POOL_WORKERS
    with _POOL_LOCK:
        if _POOL is None or _POOL_WORKERS < workers:
            old = _POOL
            _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="musclemetab-metabolics")
            _POOL_WORKERS = workers
            if old is not None:
                old.shutdown(wait=False)
        return _POOL


def _forget_pool() -> None:  # in a forked child the pool's threads do not exist
    global _POOL, _POOL_WORKERS
    _POOL, _POOL_WORKERS = None, 0


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _scratch(dtypes: str, size: int) -> list[np.ndarray]:
    """This thread's scratch arrays: one 1-D array of ``size`` elements per dtype character
    of ``dtypes`` (``"d"`` float64, ``"?"`` bool, ``"q"`` int64), kept between calls."""
    cache = getattr(_SCRATCH, "cache", None)
    if cache is None or cache[0] < size:
        cache = _SCRATCH.cache = (size, {})
    pools, out, used = cache[1], [], {}
    for ch in dtypes:
        arrays = pools.setdefault(ch, [])
        k = used.get(ch, 0)
        if k == len(arrays):
            arrays.append(np.empty(cache[0], dtype=ch))
        out.append(arrays[k])
        used[ch] = k + 1
    return out


def run_chunks(n_chunks: int, work, *, scratch: str = "", scratch_size: int = 0, threads: int | None = None) -> None:
    """Call ``work(i, scratch_arrays)`` for ``i`` in ``range(n_chunks)``, in any order, on up to
    ``threads`` threads (default :func:`evaluation_threads`; the calling thread is one of them).

    ``scratch_arrays`` are the running thread's scratch arrays (:func:`_scratch`): one 1-D
    array of at least ``scratch_size`` elements per dtype character of ``scratch``. Chunks must
    write to disjoint memory. Worker threads run in a copy of the caller's context (NumPy's
    floating-point error settings apply); the first exception is re-raised once every started
    chunk has finished.

    A worker thread that gets less than :data:`MIN_CPU_SHARE` of a processor while it works
    (measured over its chunks, from its second chunk on) stops taking chunks and leaves them
    to the other threads: it shares a core with other work, where it only slows the calling
    thread down (each hand-over of the interpreter lock then costs a context switch).
    """
    n_threads = min(evaluation_threads() if threads is None else max(1, int(threads)), n_chunks)
    if n_threads <= 1:
        arrays = _scratch(scratch, scratch_size)
        for i in range(n_chunks):
            work(i, arrays)
        return
    lock = threading.Lock()
    state = {"next": 0, "stop": False}

    def loop(worker: bool = False) -> None:
        arrays = _scratch(scratch, scratch_size)
        done, wall, cpu = 0, 0.0, 0.0
        while True:
            with lock:
                i = state["next"]
                state["next"] = i + 1
            if i >= n_chunks or state["stop"]:
                return
            if worker:
                t0, c0 = time.perf_counter(), time.thread_time()
            try:
                work(i, arrays)
            except BaseException:
                state["stop"] = True
                raise
            if worker:
                done += 1
                if done > 1:  # the first chunk includes the thread's start
                    wall += time.perf_counter() - t0
                    cpu += time.thread_time() - c0
                    if cpu < MIN_CPU_SHARE * wall:
                        return

    pool = _pool(n_threads - 1)
    futures = [pool.submit(contextvars.copy_context().run, loop, True) for _ in range(n_threads - 1)]
    error = None
    try:
        loop()
    finally:
        for f in futures:
            if not f.cancel():  # started: wait until its chunks are written
                exc = f.exception()
                if error is None and exc is not None:
                    error = exc
    if error is not None:
        raise error


class ChunkPlan:
    """How arrays of one shape are cut into chunks (see :func:`evaluate_chunked`).

    The arrays are viewed as ``n_rows x n_cols``: rows along the leading axes ``< lead``
    (those over which a parameter varies, at least ``min_lead`` of them), columns along
    the others, over which every parameter is constant. Long rows (``n_cols`` at least half
    of :data:`CHUNK_SIZE`) are cut into ``pieces`` pieces of ``length`` columns; short rows
    are taken ``block`` whole rows at a time.
    """

    def __init__(self, shape: tuple[int, ...], params: list, min_lead: int = 0):
        self.shape = shape = tuple(int(n) for n in shape)
        ndim = len(shape)
        lead = min_lead
        for p in params:
            p = np.asarray(p)
            if p.ndim == 0:
                continue
            if p.ndim != ndim:
                raise ValueError(f"parameter of shape {p.shape} is not aligned with states of shape {shape}")
            varying = [j for j, n in enumerate(p.shape) if n != 1]
            if varying:
                lead = max(lead, varying[-1] + 1)
        self.lead = lead
        self.n_rows = math.prod(shape[:lead])
        self.n_cols = math.prod(shape[lead:])
        size = CHUNK_SIZE
        if self.n_cols >= size // 2:
            self.pieces = -(-self.n_cols // size)
            self.length = -(-self.n_cols // self.pieces)
            self.block = 1
            self.n_chunks = self.n_rows * self.pieces
            self.chunk_size = self.length
        else:
            self.pieces = 0
            self.length = self.n_cols
            self.block = max(1, min(self.n_rows, size // max(1, self.n_cols)))
            self.n_chunks = -(-self.n_rows // self.block)
            self.chunk_size = self.block * self.n_cols
        if self.n_rows * self.n_cols == 0:
            self.n_chunks = 0

    def bounds(self, i: int) -> tuple[int, int, int, int]:
        """Rows ``r0:r1`` and columns ``t0:t1`` of chunk ``i``."""
        if self.pieces:
            r, j = divmod(i, self.pieces)
            t0 = j * self.length
            return r, r + 1, t0, min(self.n_cols, t0 + self.length)
        r0 = i * self.block
        return r0, min(self.n_rows, r0 + self.block), 0, self.n_cols


def evaluate_chunked(
    kernel,
    shape: tuple[int, ...],
    states: list,
    params: list,
    n_outputs: int,
    *,
    scratch: str = "",
    plan: ChunkPlan | None = None,
    inputs: MuscleInputs | None = None,
) -> list[np.ndarray]:
    """Evaluate an element-wise ``kernel`` in cache-sized chunks, on several threads.

    Parameters
    ----------
    kernel
        ``kernel(out, s, p, tmp, i)``: writes the ``n_outputs`` arrays ``out`` of chunk
        ``i`` for its state chunks ``s`` (one per state, all of one shape), with ``p`` the
        parameter values of the chunk (one per parameter: a 0-d array, or an array with one
        value per row of the chunk, shape ``(rows, 1)``); ``tmp`` are scratch arrays of the
        chunk's shape, one per dtype character of ``scratch`` (``"d"`` float64, ``"q"``
        int64, e.g. masks for :func:`select_into`, ``"?"`` bool). It must be element-wise
        (an element's result depends only on the element's operands) unless it uses the
        chunk index ``i`` with ``plan``.
    shape
        The broadcast shape of the states (and of the outputs); that of ``plan`` if given.
    states
        Arrays broadcastable to ``shape``.
    params
        Scalars, or arrays of ``len(shape)`` dimensions aligned with the states, which vary
        along leading axes only (parameter-shaped, see :func:`prepare_inputs`).
    n_outputs
        Number of output arrays.
    plan
        The :class:`ChunkPlan` (default: ``ChunkPlan(shape, params)``).
    inputs
        The model's :class:`MuscleInputs`: the states whose finiteness check it deferred
        (``unchecked``) are checked here, each chunk before the kernel reads it; a
        non-finite value raises the :class:`OptionError` of :func:`prepare_inputs`.

    Returns
    -------
    list of ``n_outputs`` new float arrays of ``shape``.

    A chunk is a piece of one row (long rows; the parameters are then 0-d arrays) or a
    block of whole rows (short rows), see :class:`ChunkPlan`. Chunks are evaluated in any
    order on :func:`evaluation_threads` threads (large arrays only); the results of an
    element-wise kernel do not depend on the chunking.
    """
    if plan is None:
        plan = ChunkPlan(shape, params)
    shape = plan.shape
    checked = [] if inputs is None else _finish_checks(inputs, states)
    outs = [np.empty(shape) for _ in range(n_outputs)]
    if plan.n_chunks == 0:
        return outs
    n_tmp = len(scratch)
    if checked:
        scratch += "?"
    n_rows, n_cols = plan.n_rows, plan.n_cols
    out2 = [o.reshape(n_rows, n_cols) for o in outs]
    state2 = [np.broadcast_to(np.asarray(s, dtype=float), shape).reshape(n_rows, n_cols) for s in states]
    row_shape = shape[: plan.lead] + (1,) * (len(shape) - plan.lead)
    params = [np.asarray(p, dtype=float) for p in params]
    param2 = [p if p.ndim == 0 else np.broadcast_to(p, row_shape).reshape(n_rows, 1) for p in params]

    if plan.pieces:  # pieces of one row
        # per row, the parameters as 0-d arrays (cheaper operands than NumPy scalars)
        row_params = [[p if p.ndim == 0 else p[r, 0, ...] for p in param2] for r in range(n_rows)]

        def work(i, arrays):
            r, _, t0, t1 = plan.bounds(i)
            n = t1 - t0
            s = [s[r, t0:t1] for s in state2]
            if checked:
                _check_chunk(s, checked, arrays[n_tmp][:n])
            kernel([o[r, t0:t1] for o in out2], s, row_params[r], [a[:n] for a in arrays[:n_tmp]], i)

    else:  # blocks of whole rows, parameters as columns

        def work(i, arrays):
            r0, r1, _, _ = plan.bounds(i)
            n = (r1 - r0) * n_cols
            s = [s[r0:r1] for s in state2]
            if checked:
                _check_chunk(s, checked, arrays[n_tmp][:n].reshape(r1 - r0, n_cols))
            kernel(
                [o[r0:r1] for o in out2],
                s,
                [p if p.ndim == 0 else p[r0:r1] for p in param2],
                [a[:n].reshape(r1 - r0, n_cols) for a in arrays[:n_tmp]],
                i,
            )

    threads = 1 if n_rows * n_cols < PARALLEL_MIN_SIZE else None
    try:
        run_chunks(plan.n_chunks, work, scratch=scratch, scratch_size=plan.chunk_size, threads=threads)
    except _NonFiniteChunk:
        _report_non_finite(inputs)
    except Exception:
        if checked:  # e.g. a FloatingPointError of the caller's settings, from a non-finite input
            _check_states_finite(inputs.states(), inputs.model)
        raise
    return outs


def _check_chunk(states: list, positions: list[int], ok: np.ndarray) -> None:
    """Raise :class:`_NonFiniteChunk` if a chunk of the states at ``positions`` holds a
    non-finite value (``ok``: bool scratch of the chunk's shape)."""
    for k in positions:
        np.isfinite(states[k], ok)
        if not ok.all():
            raise _NonFiniteChunk


def as_mask(mask: np.ndarray) -> np.ndarray:
    """Turn a 0/1 int64 array (a comparison written into it) into a selection mask
    for :func:`select_into` (-1, all bits set, where true; 0 where false), in place."""
    return np.negative(mask, mask)


def select_into(out: np.ndarray, mask: np.ndarray, x: np.ndarray, tmp: np.ndarray) -> None:
    """``out = np.where(mask, x, out)`` bit for bit, without branches.

    ``mask`` is an int64 selection mask (:func:`as_mask`), ``x`` a float array (0-d for a
    constant) broadcastable to ``out``, ``tmp`` a float scratch array of ``out``'s shape. The
    selection works on the bit patterns (``out ^ ((x ^ out) & mask)``): it copies values
    exactly (signed zeros and NaNs included) and costs the same whatever the pattern of the
    mask, unlike a branching selection, which is slow on irregular masks.
    """
    o = out.view(np.int64)
    t = tmp.view(np.int64)
    np.bitwise_xor(x.view(np.int64), o, t)
    np.bitwise_and(t, mask, t)
    np.bitwise_xor(o, t, o)


def keep_where(out: np.ndarray, mask: np.ndarray) -> None:
    """``out = np.where(mask, out, 0.0)`` bit for bit (``mask``: int64 selection mask)."""
    o = out.view(np.int64)
    np.bitwise_and(o, mask, o)


#: Constants as 0-d arrays: cheaper ufunc operands than Python floats, same arithmetic.
ZERO, HALF, ONE, TWO = np.array(0.0), np.array(0.5), np.array(1.0), np.array(2.0)
QUARTER_PI = np.array(0.25 * np.pi)


def non_negativity_into(work, heats_other, h_sl, rest, total, neg, tmp, *, strict: bool) -> None:
    """:func:`apply_non_negativity` in place (chunk kernels): updates ``h_sl``.

    Leaves ``rest = work + heats_other`` in ``rest``; ``total`` and ``tmp`` (float) and
    ``neg`` (int64) are scratch arrays.
    """
    np.add(work, heats_other, rest)
    np.add(rest, h_sl, total)
    if strict:
        np.less(total, ZERO, neg)
    else:
        np.less_equal(total, ZERO, neg)
    if neg.any():
        np.negative(rest, total)
        select_into(h_sl, as_mask(neg), total, tmp)


def total_into(total, rest, h_sl, basal_w) -> None:
    """``total = (rest + h_sl) + basal_w`` with ``rest = work + other heats`` (the models'
    total, summed in this order)."""
    np.add(rest, h_sl, total)
    np.add(total, basal_w, total)


def recruitment_terms(excitation):
    """``u_s = sin(pi e/2)`` and ``u_f = 1 - cos(pi e/2)`` (Bhargava et al. 2004).

    Both are computed from the half-angle tangent ``t = tan(pi e/4)``::

        u_s = 2 t / (1 + t^2),    u_f = 2 t^2 / (1 + t^2) = t u_s

    which are the two functions exactly (for every ``e``; ``t`` stays finite because
    ``pi e/4`` never lands on a pole in floating point). ``u_f`` has no cancellation near
    ``e = 0`` (as ``1 - cos`` has) nor near ``e = 1`` (as ``sin^2/(1 + sqrt(1 - sin^2))``
    has); both are within a few units in the last place of the exact values. One tangent is
    cheaper than a sine: NumPy evaluates ``tan`` with vector instructions where the processor
    has them, and ``sin`` one element at a time (about ten times slower for float64).
    """
    t = np.tan(QUARTER_PI * np.asarray(excitation, dtype=float))
    u_s = (2.0 * t) / (1.0 + t * t)
    return u_s, t * u_s


def recruitment_terms_into(excitation, t, u_s, tmp) -> None:
    """:func:`recruitment_terms` in place (chunk kernels): ``t = tan(pi e/4)`` into ``t`` and
    ``u_s`` into ``u_s`` (``tmp`` is a scratch array), with the same arithmetic; the caller
    forms ``u_f = t u_s`` where it needs it (or folds it into a coefficient)."""
    np.multiply(QUARTER_PI, excitation, t)
    np.tan(t, t)
    np.multiply(t, t, tmp)
    np.add(ONE, tmp, tmp)
    np.multiply(TWO, t, u_s)
    np.divide(u_s, tmp, u_s)


def full_shape(x, shape: tuple[int, ...]) -> np.ndarray:
    """``x`` as a float array of exactly ``shape`` (a broadcast copy when needed)."""
    x = np.asarray(x, dtype=float)
    return x if x.shape == shape else np.broadcast_to(x, shape).copy()


def check_flag(model: str, name: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise OptionError(f"{model}: option '{name}' must be True or False, not {value!r}")
    return bool(value)


def model_function(name: str):
    """Mark a function as the implementation of the model ``name`` (sets ``.model_name``)."""

    def deco(func):
        func.model_name = name
        return shared_doc(func)

    return deco


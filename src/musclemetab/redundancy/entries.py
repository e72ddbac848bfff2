"""The structured entries of a solve's record, typed: one small frozen dataclass per entry of
``summary.json`` (and of ``parameters.json``'s ``solve`` section) that has a fixed shape.

Each is built from the file's dictionary (:meth:`Entries.from_dict`) and gives it back
exactly (:meth:`Entries.to_dict`): the known entries are fields, the others (those of older or
newer files) are kept in ``extra`` and ``order`` is the file's order of entries, so that a folder
loads and writes again unchanged. A record is also a read-only mapping of the file's entries
(``entry["name"]``, ``entry.get("name")``, ``dict(entry)``). Entries that are genuinely
open-ended (per muscle, per DOF, per model, per input role) stay mappings, made read-only
(:class:`ReadOnlyMap`), and lists become tuples: a frozen record holds nothing that can change.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import ClassVar

__all__ = [
    "ReadOnlyMap", "frozen", "thaw", "entry", "Entries", "WorkflowRecord", "ProblemSize", "SolverOptionsRecord",
    "InputPreparation", "EnergyGoalRecord", "EnergyFormRecord", "EmgRecord", "FiberLengthBounds", "WindowRecord",
    "InverseDynamicsRecord", "AssistanceRecord", "ConvergenceRecord", "TrialRecord", "records",
]


class ReadOnlyMap(Mapping):
    """A mapping that cannot be changed (unlike :class:`types.MappingProxyType` it pickles, so
    that a solution travels between processes); equal to a dictionary of the same items."""

    __slots__ = ("_items",)

    def __init__(self, items=()):
        self._items = dict(items)

    def __getitem__(self, key):
        return self._items[key]

    def __iter__(self):
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"ReadOnlyMap({self._items!r})"

    def __reduce__(self):
        return ReadOnlyMap, (self._items,)


def frozen(value):
    """``value`` with its dictionaries made :class:`ReadOnlyMap` and its lists tuples, all the
    way down; typed records (anything with ``to_dict``) and other values as they are."""
    if isinstance(value, ReadOnlyMap) or hasattr(value, "to_dict"):
        return value
    if isinstance(value, Mapping):
        return ReadOnlyMap({k: frozen(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(frozen(v) for v in value)
    return value


def thaw(value):
    """The JSON-ready form of a frozen value: records as their ``to_dict()``, mappings as
    dictionaries, tuples as lists, all the way down."""
    if hasattr(value, "to_dict"):
        return thaw(value.to_dict())
    if isinstance(value, Mapping):
        return {k: thaw(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [thaw(v) for v in value]
    return value


def entry(kind=None):
    """A field of a record holding ``kind`` (a record class, or a function that makes the typed
    value from the file's); ``None`` when the file has no such entry."""
    convert = kind.from_dict if hasattr(kind, "from_dict") else kind
    return field(default=None, metadata={"convert": convert} if convert is not None else {})


class _Typed:
    """The round trip of a typed record and the dictionary of a file: fields are the known
    entries, ``extra`` the others as read and the field named by ``_ORDER`` the file's order."""

    _ORDER: ClassVar[str] = "order"

    @classmethod
    def _entry_names(cls) -> set:
        return {f.name for f in fields(cls)} - {"extra", cls._ORDER}

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != self._ORDER and value is not None:
                object.__setattr__(self, f.name, f.metadata.get("convert", frozen)(value))

    @classmethod
    def from_dict(cls, d):
        """From the file's dictionary (entries that are not fields go to ``extra``); a record of
        this class and ``None`` as they are."""
        if d is None or isinstance(d, cls):
            return d
        names = cls._entry_names()
        known = {k: v for k, v in d.items() if k in names}
        return cls(**known, extra={k: v for k, v in d.items() if k not in names}, **{cls._ORDER: tuple(d)})

    def _value(self, key: str):
        return self.extra[key] if key in self.extra else getattr(self, key)

    def to_dict(self) -> dict:
        """The file's dictionary (its entries in the file's order), JSON-ready."""
        return {k: thaw(self._value(k)) for k in getattr(self, self._ORDER)}

    def with_(self, **entries):
        """A copy with ``entries`` set (new ones after the others, as in the file). Only the
        record's fields may be set: an unknown name (a typo) raises :class:`TypeError` instead of
        becoming an entry nobody reads; entries of other files stay in ``extra`` as read."""
        names = self._entry_names()
        unknown = sorted(k for k in entries if k not in names)
        if unknown:
            raise TypeError(f"{type(self).__name__} has no entry {', '.join(map(repr, unknown))}; its entries are "
                            f"{', '.join(sorted(names))}")
        order = getattr(self, self._ORDER)
        return replace(self, **entries, **{self._ORDER: order + tuple(k for k in entries if k not in order)})


class Entries(_Typed, Mapping):
    """A typed entry of the record, and a read-only mapping of the file's dictionary."""

    def __getitem__(self, key: str):
        if key not in self.order:
            raise KeyError(key)
        return self._value(key)

    def __iter__(self):
        return iter(self.order)

    def __len__(self) -> int:
        return len(self.order)


def records(kind):
    """The conversion of a list of ``kind``'s dictionaries to a tuple of its records."""
    return lambda values: tuple(kind.from_dict(v) for v in values)


def _record(cls):
    """A frozen record class whose equality is the mapping's (a record equals the dictionary of
    the same entries)."""
    return dataclass(frozen=True, eq=False)(cls)


@_record
class WorkflowRecord(Entries):
    """``workflow``: the preset (``name``, ``description``, the passive parameters' source, the
    effort ``weights``, the generic tendon stiffness), or the trial of a problem of several and
    the estimated factors (``estimate``)."""

    name: str | None = None
    description: str | None = None
    passive_source: str | None = None
    weights: Mapping | None = None
    tendon_stiffness_other_muscles: float | None = None
    #: the tendon stiffness ``kT`` per muscle (and its sources) of the presets that set it
    tendon_stiffness: Mapping | None = None
    tendon_stiffness_source: str | None = None
    tendon_stiffness_sources: Mapping | None = None
    tendon_stiffness_literature: Mapping | None = None
    trial: str | None = None
    #: the factors an EMG-TEN problem estimated (per muscle) and its trials
    tendon_stiffness_scale: Mapping | None = None
    emg_scale: Mapping | None = None
    emg_channels: Mapping | None = None
    trials: tuple | None = None
    estimate: Mapping | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class ProblemSize(Entries):
    """``problem_size``: the NLP's variables and equality constraints."""

    variables: int | None = None
    equality_constraints: int | None = None
    inequality_constraints: int | None = None
    mesh_intervals: int | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class EnergyGoalRecord(Entries):
    """``energy_goal`` (and ``solver_options['energy']``): the energy model, its weight against
    the effort, the body size and the options (:meth:`~.energy.EnergyGoal.record`)."""

    model: str | None = None
    weight: float | None = None
    effort_weight: float | None = None
    smoothing: float | None = None
    body_mass_kg: float | None = None
    height_m: float | None = None
    muscle_mass_rule: str | None = None
    muscle_properties: object = None
    options: Mapping | None = None
    form: str | None = None
    term: str | None = None
    w_activation: float | None = None
    leg_mean_W_per_kg: float | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class SolverOptionsRecord(Entries):
    """``solver_options``: the effort weights, then :class:`~.ipopt.SolverOptions` as recorded
    (:func:`~.ipopt.solver_record`); ``ipopt`` holds the user's IPOPT options as given."""

    w_activation: float | None = None
    w_reserve: float | None = None
    w_velocity: float | None = None
    stop: str | None = None
    optimal_reserve_Nm: float | None = None
    tol: float | None = None
    max_iter: int | None = None
    linear_solver: str | None = None
    linear_solver_library: str | None = None
    derivatives: str | None = None
    tune_malloc: bool | None = None
    blas_threads: int | None = None
    ipopt: Mapping | None = None
    energy: EnergyGoalRecord | None = entry(EnergyGoalRecord)
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class InputPreparation(Entries):
    """``input_preparation``: the filter of the kinematics, the mesh density, the interpolation
    (and, with EMG, how the EMG reaches the nodes)."""

    filter: str | None = None
    mesh_intervals_per_second: float | None = None
    interpolation: str | None = None
    emg: str | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class EnergyFormRecord(Entries):
    """``energy_form``: the energy goal's model, form, the non-negativity rule it minimises and
    its smoothing (:meth:`~.energy.EnergyGoal.form_record`)."""

    model: str | None = None
    form: str | None = None
    non_negativity: str | None = None
    smoothing: float | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class EmgRecord(Entries):
    """``emg`` of an EMG-informed estimate: mode, tolerance, weight, the channels' ``mapping``,
    the estimated ``scale`` per muscle and its ``bounds``, the largest deviation per trial."""

    mode: str | None = None
    tolerance: float | None = None
    weight: float | None = None
    mapping: Mapping | None = None
    scale: Mapping | None = None
    bounds: tuple | None = None
    max_deviation: Mapping | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class FiberLengthBounds(Entries):
    """``fiber_length_bounds``: the ``default`` bounds of the normalised fiber length and the
    ``widened_upper`` bound of each muscle whose bound is widened
    (:func:`~.bounds.fiber_length_bounds_record`)."""

    default: tuple | None = None
    widened_upper: Mapping | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class WindowRecord(Entries):
    """``window``: the solved window (s), where it came from, the gait cycle it pads and the
    padding, and the warnings its resolution gave (:meth:`~.window.TrialWindow.record`)."""

    start_s: float | None = None
    end_s: float | None = None
    source: str | None = None
    gait_cycle: Mapping | None = None
    padding_s: tuple | None = None
    warnings: tuple | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class InverseDynamicsRecord(Entries):
    """``inverse_dynamics`` of a trial whose moments the package computed: the tool, the
    coordinates' low-pass frequency, the external loads and their force data."""

    computed_by: str | None = None
    coordinate_lowpass_hz: float | None = None
    external_loads: str | None = None
    ground_force_data: str | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class AssistanceRecord(Entries):
    """``assistance`` of an assisted trial: the device's file, gain, axis, assisted DOFs, the
    gait cycle, its work and power, and its torque and power at the mesh nodes
    (:func:`~.assistance.assistance_record`)."""

    file: str | None = None
    gain: float | None = None
    axis: str | None = None
    dofs: tuple | None = None
    cycle_s: tuple | None = None
    cycle_source: str | None = None
    positive_work_J: float | None = None
    negative_work_J: float | None = None
    net_work_J: float | None = None
    mean_positive_power_W: float | None = None
    mean_negative_power_W: float | None = None
    duration_s: float | None = None
    time_s: tuple | None = None
    torque_Nm: Mapping | None = None
    power_W: tuple | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class ConvergenceRecord(Entries):
    """``convergence``: where IPOPT stopped and how converged the rates are
    (:func:`~.convergence.convergence_record`); ``rate_residue`` per energy model."""

    stop: str | None = None
    tolerance: float | None = None
    final_barrier_parameter: float | None = None
    off_level: float | None = None
    largest_off_activation: float | None = None
    rate_residue: Mapping | None = None
    max_rate_residue: float | None = None
    note: str | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()


@_record
class TrialRecord(Entries):
    """One trial of a problem of several (``parameters.json``'s ``solve.trials``): its label,
    window (s), mesh intervals and input files."""

    label: str | None = None
    time_window_s: tuple | None = None
    n_intervals: int | None = None
    inputs: Mapping | None = None
    extra: Mapping = field(default_factory=dict)
    order: tuple = ()

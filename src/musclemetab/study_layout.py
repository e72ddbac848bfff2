"""The layout of a study folder: the name of every file and folder ``musclemetab run`` writes
there and ``musclemetab report`` reads, defined once for both.

::

    DIR/study.json        the settings, subjects and software versions of the run
    DIR/results.csv       one row per subject × trial × workflow × model
    DIR/results.parquet   the same table
    DIR/failures.csv      one row per failed unit, with its reason
    DIR/per_muscle.csv    one row per muscle of every unit (:mod:`musclemetab.metabolics.per_muscle`)
    DIR/prepared/<subject>/  the subject's model scaled from its static trial (model.osim, marker
                          errors, prepare.json) and, per trial from markers, <trial>/ik.mot,
                          ik_marker_errors.csv (and a C3D trial's ground forces)
    DIR/units/<subject>/<trial>/<workflow>/[<side>/]
                          unit.json (the unit's record: status, gait cycle, hashes of its files),
                          timeseries.csv (rates over the cycle), solution.sto and summary.json
                          (:mod:`musclemetab.redundancy.solution`)

It also gives the software versions a run records in ``study.json`` and a report sets beside
those installed where it is written (:func:`software_versions`).
"""

from __future__ import annotations

import sys
from pathlib import Path

from .metabolics.per_muscle import PER_MUSCLE_FILE

__all__ = [
    "STUDY_JSON",
    "RESULTS_CSV",
    "RESULTS_PARQUET",
    "FAILURES_CSV",
    "PER_MUSCLE_FILE",
    "PER_MUSCLE_PARQUET",
    "GROUP_KEY_CSV",
    "DATA_DICTIONARY_CSV",
    "LOCK_FILE",
    "UNITS_FOLDER",
    "PREPARED_FOLDER",
    "prepared_path",
    "UNIT_FILE",
    "TIMESERIES_FILE",
    "unit_path",
    "software_versions",
]

STUDY_JSON = "study.json"
RESULTS_CSV = "results.csv"
RESULTS_PARQUET = "results.parquet"
FAILURES_CSV = "failures.csv"
PER_MUSCLE_PARQUET = "per_muscle.parquet"
GROUP_KEY_CSV = "muscle_groups.csv"
DATA_DICTIONARY_CSV = "data_dictionary.csv"
from .io.atomic import LOCK_FILE  # noqa: E402  (defined with the lock, musclemetab.io.atomic.FolderLock)
#: The folder holding one folder per unit: ``units/<subject>/<trial>/<workflow>``.
UNITS_FOLDER = "units"
#: The record of one unit, in its folder.
UNIT_FILE = "unit.json"
#: The unit's metabolic rates over the gait cycle (long table), in its folder.
TIMESERIES_FILE = "timeseries.csv"


#: The folder of what the study makes from markers: ``prepared/<subject>/[<trial>/]``.
PREPARED_FOLDER = "prepared"


def prepared_path(subject: str, trial: str | None = None) -> Path:
    """The folder of a subject's scaled model (or, with ``trial``, of the trial's IK), relative to
    the study folder."""
    base = Path(PREPARED_FOLDER) / str(subject)
    return base / str(trial) if trial is not None else base


def unit_path(subject: str, trial: str, workflow: str) -> Path:
    """The folder of a subject's trial solved with a workflow, relative to the study folder."""
    return Path(UNITS_FOLDER) / str(subject) / str(trial) / str(workflow)


def software_versions() -> dict[str, str]:
    """Versions of the package and of the libraries its numbers depend on (read from the
    packages' metadata: nothing is imported)."""
    from importlib.metadata import PackageNotFoundError, version

    from . import __version__

    out = {"musclemetab": __version__, "python": sys.version.split()[0]}
    for name in ("opensim", "casadi", "numpy", "scipy", "pandas", "matplotlib", "dask", "distributed"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            pass
    return out

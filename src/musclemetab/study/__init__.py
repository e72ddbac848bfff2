"""Studies at scale: subjects × trials × workflows × metabolic models, resumable.

* :mod:`~musclemetab.study.spec`: the TOML study file (:func:`load_study`);
* :mod:`~musclemetab.study.units`: units of work, their keys and how one unit runs;
* :mod:`~musclemetab.study.runner`: :func:`run_study` (process pool or Dask) and the
  results table;
* :mod:`~musclemetab.study.demo`: the example subject's study (``musclemetab demo``).
"""

from .runner import StudyRun, collect_results, run_study, software_versions
from .spec import Study, Subject, Trial, load_study, study_from_dict
from .units import Unit, plan_units

__all__ = [
    "Study", "Subject", "Trial", "load_study", "study_from_dict",
    "Unit", "plan_units", "run_study", "StudyRun", "collect_results", "software_versions",
]

"""The package's error hierarchy.

Every error raised on bad input derives from :class:`MusclemetabError`. Messages name the
file, column, muscle or option at fault and say what to do about it. The command-line
interface prints the message on one line and exits with a non-zero code.

Errors are plain exceptions carrying one message string, so they cross process
boundaries (the OpenSim worker, a process pool, a Dask cluster) unchanged.
"""

from __future__ import annotations


class MusclemetabError(Exception):
    """Root of every error this package raises on purpose."""

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message

    def __reduce__(self):  # picklable across processes
        return (type(self), (self.message,))

    def __str__(self) -> str:
        return self.message


class InputFileError(MusclemetabError):
    """A file is missing, unreadable, truncated or malformed."""


class StorageFormatError(InputFileError):
    """An OpenSim storage file (.mot/.sto) does not follow the format."""


class MissingColumnError(InputFileError):
    """A required column is absent from a data file."""


class TimeColumnError(InputFileError):
    """A time column holds NaN or is not strictly increasing."""


class ModelError(MusclemetabError):
    """An OpenSim model cannot be loaded, or lacks a coordinate or muscle asked for."""


class UnknownMuscleError(ModelError):
    """A muscle name is not in the model, or (strict) not in the anatomical muscle table."""


class UnknownCoordinateError(ModelError):
    """A degree of freedom is not a coordinate of the model."""


class OptionError(MusclemetabError):
    """An option or argument has an invalid value."""


class OutputError(MusclemetabError):
    """An output file or folder cannot be written (no permission, disk full, file-size limit)."""


class DataMismatchError(MusclemetabError):
    """Inputs that must agree (time ranges, units, models, shapes) do not."""


class SolverError(MusclemetabError):
    """An optimisation problem could not be built or did not converge."""


class ImplausibleResultError(MusclemetabError):
    """A result with a plausibility flag, refused because strict checking was asked for
    (``--strict``, the study file's ``strict``; ``docs/quality.md``)."""


class OpenSimWorkerError(MusclemetabError):
    """The isolated OpenSim process failed unexpectedly."""


class DatasetError(MusclemetabError):
    """Example data could not be found, downloaded or verified."""


class MusclemetabWarning(UserWarning):
    """Root of the warnings this package gives (results usable, but look at them)."""


class CacheWarning(MusclemetabWarning):
    """A cache entry or folder could not be used; the result was computed without it."""


class LargeReserveWarning(MusclemetabWarning):
    """The reserve actuators carry a large share of a joint moment."""


class PlausibilityWarning(MusclemetabWarning):
    """A result has a plausibility flag (``docs/quality.md``): a value walking does not reach."""


class MuscleTableWarning(MusclemetabWarning):
    """Some muscles are not in the anatomical muscle table and take fallback properties."""


class LumpedMuscleWarning(MusclemetabWarning):
    """Some muscles' maximal isometric forces stand for several anatomical muscles (a lumped
    muscle of a reduced model): their masses come from force and optimal fiber length."""


class MarkerErrorWarning(MusclemetabWarning):
    """Marker errors of inverse kinematics or of a static pose exceed OpenSim's best-practice
    limits (RMS 2 cm, maximum 4 cm; ``docs/lab_data.md``)."""


class WindowWarning(MusclemetabWarning):
    """The solve window was clipped at the edge of the data (the record says where)."""


class FigureLayoutWarning(MusclemetabWarning):
    """A text of a report's figure is cut by the figure's edge or drawn over another text
    (:func:`musclemetab.report.layout_check.figure_problems`): the figure is written, but
    that text cannot be read."""


class TruncatedFileWarning(MusclemetabWarning):
    """A storage file's last data line has no line end: the file may have been cut inside that
    line (a number cut short cannot be told from a whole one); the file is read as it is."""

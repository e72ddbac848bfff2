"""From the motion-capture lab's files to OpenSim's: markers, force plates, feet.

* :mod:`.c3d` reads a C3D file (markers and force-plate channels, with ``ezc3d``) into a
  :class:`~.trial.LabTrial` in OpenSim's frame and units (y up, metres, newtons);
* :mod:`.trc` reads and writes OpenSim's marker files (``.trc``);
* :mod:`.plates` removes the plates' offsets, computes centre of pressure and free moment and
  gives each foot contact of a plate to the foot that stands on it, from the markers;
* :mod:`.export` writes the ground-force ``.mot`` and the ExternalLoads ``.xml`` OpenSim's
  InverseDynamicsTool reads, and :func:`.export.convert_c3d` does all of it for one file.

See ``docs/lab_data.md``.
"""

from .c3d import read_c3d
from .export import convert_c3d, write_ground_forces
from .plates import PlateContact, assign_feet, foot_marker_sets
from .trc import read_trc, write_trc
from .trial import LabTrial, Markers, Plate

__all__ = [
    "LabTrial", "Markers", "Plate", "PlateContact", "read_c3d", "read_trc", "write_trc", "assign_feet",
    "foot_marker_sets", "write_ground_forces", "convert_c3d",
]

"""OpenSim's side of the lab data (run inside the OpenSim worker only): how OpenSim reads the
marker and ground-force files the package writes."""

from __future__ import annotations

import os

import opensim as osim


def read_lab_files(trc_path: str | None = None, external_loads_path: str | None = None) -> dict:
    """What OpenSim reads from a ``.trc`` (marker names, frames, rate, units) and an
    ExternalLoads file (its forces: name, body, identifiers; the number of rows of its data)."""
    out = {}
    if trc_path:
        table = osim.TimeSeriesTableVec3(os.path.abspath(trc_path))
        out["markers"] = list(table.getColumnLabels())
        out["frames"] = int(table.getNumRows())
        out["units"] = table.getTableMetaDataAsString("Units")
        out["rate"] = float(table.getTableMetaDataAsString("DataRate"))
        first = table.getRowAtIndex(0)
        out["first_row_m"] = [[first[i][k] for k in range(3)] for i in range(first.size())]
    if external_loads_path:
        loads = osim.ExternalLoads(os.path.abspath(external_loads_path), True)
        forces = []
        for i in range(loads.getSize()):
            f = loads.get(i)
            forces.append({"name": f.getName(), "body": f.get_applied_to_body(),
                           "force_identifier": f.get_force_identifier(),
                           "point_identifier": f.get_point_identifier(),
                           "torque_identifier": f.get_torque_identifier()})
        datafile = loads.getDataFileName()
        if not os.path.isabs(datafile):
            datafile = os.path.join(os.path.dirname(os.path.abspath(external_loads_path)), datafile)
        data = osim.Storage(datafile)
        out["forces"] = forces
        out["data_rows"] = int(data.getSize())
    return out

"""OpenSim's AnalyzeTool + MuscleAnalysis on one IK motion (baseline for geometry.py).

Run as a script in its own process (it imports opensim). Prints a JSON line with the
seconds spent importing OpenSim, loading the model and running the tool.
"""

import json
import sys
import tempfile
import time

t0 = time.perf_counter()
import opensim as osim  # noqa: E402

osim.Logger.setLevelString("error")
t_import = time.perf_counter() - t0

model_path, ik_path, t_start, t_end = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
dofs = sys.argv[5].split(",")
with tempfile.TemporaryDirectory() as out:
    setup = osim.AnalyzeTool()
    setup.setName("bench")
    setup.setModelFilename(model_path)
    setup.setCoordinatesFileName(ik_path)
    setup.setLowpassCutoffFrequency(-1)
    setup.setInitialTime(t_start)
    setup.setFinalTime(t_end)
    setup.setResultsDir(out)
    setup.setSolveForEquilibrium(False)
    ma = osim.MuscleAnalysis()
    ma.setStartTime(t_start)
    ma.setEndTime(t_end)
    ma.setStepInterval(1)
    ma.setInDegrees(True)
    ma.setComputeMoments(True)
    names = osim.ArrayStr()
    for d in dofs:
        names.append(d)
    ma.setCoordinates(names)
    setup.getAnalysisSet().cloneAndAppend(ma)
    xml = f"{out}/setup.xml"
    setup.printToXML(xml)

    t1 = time.perf_counter()
    tool = osim.AnalyzeTool(xml)  # loads the model
    t_load = time.perf_counter() - t1
    t2 = time.perf_counter()
    tool.run()
    t_run = time.perf_counter() - t2
    n_files = len(__import__("os").listdir(out))
print(json.dumps(dict(import_s=t_import, load_s=t_load, run_s=t_run, files=n_files)))

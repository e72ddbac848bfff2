"""Small test models built with OpenSim's API (run as a script in its own process: OpenSim only).

``python tests/opensim_models.py SOURCE.osim OUT.osim [--right-only]`` writes a sagittal-plane, lumped-muscle
version of a gait2392-family model, the layout of OpenSim's gait10dof18musc: every coordinate
locked except pelvis tilt and its two sagittal translations and each leg's hip flexion, knee and
ankle; the 92 muscles replaced by 9 per leg (``hamstrings``, ``bifemsh``, ``glut_max``,
``iliopsoas``, ``rect_fem``, ``vasti``, ``gastroc``, ``soleus``, ``tib_ant``), each with the path
of its first part and the summed maximal isometric force of its parts. The right leg's muscles
are ``DeGrooteFregly2016Muscle``, the left leg's ``Millard2012EquilibriumMuscle``; with
``--right-only`` the left leg has no muscles.

``python tests/opensim_models.py SOURCE.osim OUT.osim --merge KEEP=PART,PART [--merge ...]`` writes the
model with, on each side, the muscles ``PART_r``, ``PART_l`` merged into ``KEEP_r``, ``KEEP_l``: the kept
muscle (its path, optimal fiber length, tendon slack length, pennation, class) carries the summed
maximal isometric force of itself and its parts, which are removed (a lumped muscle of a reduced
model).
"""

from __future__ import annotations

import sys

KEEP = ("pelvis_tilt", "pelvis_tx", "pelvis_ty", "hip_flexion_{s}", "knee_angle_{s}", "ankle_angle_{s}")
LUMPED = {
    "hamstrings": ("semimem", "semiten", "bifemlh"),
    "bifemsh": ("bifemsh",),
    "glut_max": ("glut_max1", "glut_max2", "glut_max3"),
    "iliopsoas": ("iliacus", "psoas"),
    "rect_fem": ("rect_fem",),
    "vasti": ("vas_med", "vas_int", "vas_lat"),
    "gastroc": ("med_gas", "lat_gas"),
    "soleus": ("soleus",),
    "tib_ant": ("tib_ant",),
}


def lumped_sagittal(source: str, out: str, right_only: bool = False) -> None:
    import opensim as osim

    osim.Logger.setLevelString("error")
    model = osim.Model(source)
    keep = {k.format(s=s) for k in KEEP for s in "rl"}
    coords = model.getCoordinateSet()
    for i in range(coords.getSize()):
        if coords.get(i).getName() not in keep:
            coords.get(i).set_locked(True)
    forces = model.updForceSet()
    old = {forces.get(i).getName(): osim.Muscle.safeDownCast(forces.get(i)) for i in range(forces.getSize())}
    new = []
    sides = (("r", osim.DeGrooteFregly2016Muscle), ("l", osim.Millard2012EquilibriumMuscle))
    for side, kind in sides[:1] if right_only else sides:
        for name, parts in LUMPED.items():
            first = old[f"{parts[0]}_{side}"]
            mus = kind()
            mus.setName(f"{name}_{side}")
            mus.set_path(first.get_path())
            mus.setMaxIsometricForce(sum(old[f"{p}_{side}"].getMaxIsometricForce() for p in parts))
            mus.setOptimalFiberLength(first.getOptimalFiberLength())
            mus.setTendonSlackLength(first.getTendonSlackLength())
            mus.setPennationAngleAtOptimalFiberLength(first.getPennationAngleAtOptimalFiberLength())
            mus.setMaxContractionVelocity(10.0)
            new.append(mus)
    for i in reversed(range(forces.getSize())):
        if osim.Muscle.safeDownCast(forces.get(i)) is not None:
            forces.remove(i)
    for mus in new:
        model.addForce(mus)
    model.finalizeConnections()
    model.initSystem()
    model.printToXML(out)


def merged_muscles(source: str, out: str, merges: dict[str, tuple[str, ...]]) -> None:
    """``merges``: ``{kept muscle: (merged muscles, ...)}`` (side-free names), done on both sides."""
    import opensim as osim

    osim.Logger.setLevelString("error")
    model = osim.Model(source)
    forces = model.updForceSet()
    for keep, parts in merges.items():
        for side in "rl":
            kept = osim.Muscle.safeDownCast(forces.get(f"{keep}_{side}"))
            merged = [osim.Muscle.safeDownCast(forces.get(f"{p}_{side}")) for p in parts]
            kept.setMaxIsometricForce(kept.getMaxIsometricForce() + sum(m.getMaxIsometricForce() for m in merged))
            for p in parts:
                forces.remove(forces.getIndex(f"{p}_{side}"))
    model.finalizeConnections()
    model.initSystem()
    model.printToXML(out)


if __name__ == "__main__":
    if "--merge" in sys.argv:
        pairs = [sys.argv[i + 1].split("=") for i, a in enumerate(sys.argv) if a == "--merge"]
        merged_muscles(sys.argv[1], sys.argv[2], {k: tuple(v.split(",")) for k, v in pairs})
    else:
        lumped_sagittal(sys.argv[1], sys.argv[2], right_only="--right-only" in sys.argv[3:])

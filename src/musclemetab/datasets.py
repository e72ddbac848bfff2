"""Example data: the study's subject at three speeds, OpenSim's gait2392 subject, a C3D trial.

Three data sets, none part of this package, each downloaded on first use with pooch from a
pinned commit of its public repository and checked against SHA-256 hashes:

* :func:`example_subject`: the subject published with the reference study (repository
  ``israelluis/MetabolicRateWalking``, GPL-2.0; ``data/example_subject_manifest.txt``);
  Rajagopal-family model, right leg, 100 Hz, IK, ID, EMG, passive-calibration trials;
* :func:`gait2392_subject01`: OpenSim's own walking example (repository
  ``opensim-org/opensim-models``, Apache-2.0; ``data/gait2392_subject01_manifest.txt``);
  gait2392 model with Thelen muscles, both legs, 60 Hz IK, ground forces and an ExternalLoads
  file, and an ID file that covers no complete gait cycle; the lab's markers (static and walking
  trials, ``.trc``), the generic model and OpenSim's scaling and IK setups;
* :func:`c3d_walking`: a walking trial as a motion-capture lab exports it (C3D, markers and
  force-plate channels) from OpenSim's test suite (``opensim-org/opensim-core``, Apache-2.0).

Set ``MUSCLEMETAB_DATA`` to a folder that already holds the files (offline machines, test
systems) and no download happens. The folder may hold one data set's files directly, or one
sub-folder per data set named ``example_subject``, ``gait2392_subject01`` and ``c3d_walking``. Files found
there are checked against the same hashes.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from urllib.parse import quote

from .io.atomic import file_sha256
from .errors import DatasetError
from .messages import name_list

__all__ = [
    "ExampleSubject",
    "example_subject",
    "Gait2392Subject",
    "gait2392_subject01",
    "c3d_walking",
    "manifest",
    "SOURCE_COMMIT",
    "SOURCE_REPOSITORY",
]

SOURCE_REPOSITORY = "israelluis/MetabolicRateWalking"
SOURCE_COMMIT = "acaf8a1af4c9dd1fae763b50ea4cabbe0be1a0e9"
_BASE_URL = f"https://raw.githubusercontent.com/{SOURCE_REPOSITORY}/{SOURCE_COMMIT}/"
ENV_VAR = "MUSCLEMETAB_DATA"

SPEEDS = ("slow", "normal", "fast")


GAIT2392_REPOSITORY = "opensim-org/opensim-models"
GAIT2392_COMMIT = "20a888b9655e73fb84963d6e03eee3752cf6074b"
_GAIT2392_URL = f"https://raw.githubusercontent.com/{GAIT2392_REPOSITORY}/{GAIT2392_COMMIT}/"


def manifest(dataset: str = "example_subject") -> dict[str, tuple[str, str]]:
    """``{local file name: (sha256, path in the source repository)}`` of a data set."""
    out = {}
    text = resources.files("musclemetab").joinpath(f"data/{dataset}_manifest.txt").read_text()
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        name, sha, path = line.split(None, 2)
        out[name] = (sha, path.strip())
    return out


@dataclass(frozen=True)
class ExampleSubject:
    """Local paths of the example subject's files."""

    folder: Path
    model: Path
    calibration_model: Path
    ik: dict
    id: dict
    emg: dict
    calibration_trials: dict
    passive_moments_mat: Path
    reference_muscle_analysis: Path
    body_mass_kg: float = 72.6
    height_m: float = 1.743

    def trial(self, speed: str) -> dict:
        """``{'ik': Path, 'id': Path, 'emg': Path}`` of one speed (slow, normal, fast)."""
        if speed not in SPEEDS:
            raise DatasetError(f"the example subject has speeds {', '.join(SPEEDS)}, not {speed!r}")
        return {"ik": self.ik[speed], "id": self.id[speed], "emg": self.emg[speed]}


def _sha256(path: Path) -> str:
    return file_sha256(path)


def _fetch_all(entries: dict, dataset: str = "example_subject", repository: str | None = None,
               commit: str | None = None, base_url: str | None = None) -> Path:
    import pooch

    repository = repository or SOURCE_REPOSITORY
    commit = commit or SOURCE_COMMIT
    base_url = base_url or _BASE_URL
    cache = pooch.os_cache("musclemetab") / dataset / commit[:12]
    fetcher = pooch.create(
        path=cache,
        base_url=base_url,
        registry={name: f"sha256:{sha}" for name, (sha, _) in entries.items()},
        urls={name: base_url + quote(path) for name, (_, path) in entries.items()},
    )
    for name in entries:
        try:
            fetcher.fetch(name)
        except Exception as exc:
            raise DatasetError(
                f"could not download example file {name} from {repository}@{commit[:7]} "
                f"({type(exc).__name__}: {exc}); check the network, or set {ENV_VAR} to a folder "
                "that holds the files"
            ) from None
    return Path(cache)


def _local_root(folder, dataset: str, entries: dict, verify: bool) -> Path | None:
    """The local folder holding ``dataset`` (directly or in a sub-folder named after it)."""
    folder = folder or os.environ.get(ENV_VAR)
    if not folder:
        return None
    root = Path(folder).expanduser()
    if (root / dataset).is_dir() and not all((root / n).is_file() for n in entries):
        root = root / dataset
    missing = [n for n in entries if not (root / n).is_file()]
    if missing:
        raise DatasetError(
            f"{root}: missing {dataset} file{'s' if len(missing) > 1 else ''} {', '.join(missing[:4])}"
            f"{' ...' if len(missing) > 4 else ''}; point {ENV_VAR} at a folder holding a complete copy "
            f"(or a sub-folder {dataset}/ with one), or unset it to download"
        )
    if verify:
        bad = [n for n, (sha, _) in entries.items() if _sha256(root / n) != sha]
        if bad:
            raise DatasetError(
                f"{root}: file{'s' if len(bad) > 1 else ''} {name_list(bad)} differ from the published "
                f"{dataset} data (SHA-256 mismatch); restore the original files"
            )
    return root


def example_subject(folder: str | os.PathLike | None = None, verify: bool = True) -> ExampleSubject:
    """Paths of the example subject's files, downloading them if needed.

    Parameters
    ----------
    folder
        A folder holding the files; default ``$MUSCLEMETAB_DATA`` if set, else the pooch
        cache (files downloaded on first use).
    verify
        Check every local file against its SHA-256.
    """
    entries = manifest()
    root = _local_root(folder, "example_subject", entries, verify)
    if root is None:
        root = _fetch_all(entries)
    return ExampleSubject(
        folder=root,
        model=root / "1_scaledHMK_rajagopal2022_MIF2.osim",
        calibration_model=root / "Rajagopal2015_passiveCal_hipAbdMoved.osim",
        ik={s: root / f"IK_sub1_{s}.mot" for s in SPEEDS},
        id={s: root / f"ID_sub1_{s}.sto" for s in SPEEDS},
        emg={s: root / f"EMG_sub1_{s}.mot" for s in SPEEDS},
        calibration_trials={
            j: {"motion": root / f"Trial{k}_r_rajagopalModel.mot", "moments": root / f"Trial{k}_r_rajagopalModel.sto"}
            for j, k in (("ankle", "Ank"), ("knee", "Kne"), ("hip", "Hip"))
        },
        passive_moments_mat=root / "passiveMoments.mat",
        reference_muscle_analysis=root / "reference_muscle_analysis",
    )


@dataclass(frozen=True)
class Gait2392Subject:
    """Local paths of OpenSim's gait2392 walking example (subject01, walk1).

    Both legs, 60 Hz inverse kinematics (0.5-4.0 s, degrees), ground forces at 600 Hz
    (0-2.5 s) with the ExternalLoads file that applies them to ``calcn_r`` and ``calcn_l``,
    and OpenSim's inverse dynamics for 0.4-1.6 s only. Body height is not recorded.
    """

    folder: Path
    model: Path
    ik: Path
    grf: Path
    external_loads: Path
    id_setup: Path
    id: Path
    generic_model: Path | None = None
    static: Path | None = None
    markers: Path | None = None
    scale_setup: Path | None = None
    scale_marker_set: Path | None = None
    ik_setup: Path | None = None
    body_mass_kg: float = 72.6
    height_m: float | None = None


def gait2392_subject01(folder: str | os.PathLike | None = None, verify: bool = True) -> Gait2392Subject:
    """Paths of OpenSim's gait2392 walking example, downloading the files if needed.

    Parameters are those of :func:`example_subject`; with ``$MUSCLEMETAB_DATA`` set, the
    files are looked for there or in its sub-folder ``gait2392_subject01``.
    """
    entries = manifest("gait2392_subject01")
    root = _local_root(folder, "gait2392_subject01", entries, verify)
    if root is None:
        root = _fetch_all(entries, "gait2392_subject01", GAIT2392_REPOSITORY, GAIT2392_COMMIT, _GAIT2392_URL)
    return Gait2392Subject(
        folder=root,
        model=root / "subject01_simbody.osim",
        ik=root / "subject01_walk1_ik.mot",
        grf=root / "subject01_walk1_grf.mot",
        external_loads=root / "subject01_walk1_grf.xml",
        id_setup=root / "subject01_Setup_InverseDynamics.xml",
        id=root / "subject01_walk1_id.sto",
        generic_model=root / "gait2392_thelen2003muscle.osim",
        static=root / "subject01_static.trc",
        markers=root / "subject01_walk1.trc",
        scale_setup=root / "subject01_Setup_Scale.xml",
        scale_marker_set=root / "gait2392_Scale_MarkerSet.xml",
        ik_setup=root / "subject01_Setup_IK.xml",
    )


OPENSIM_CORE_REPOSITORY = "opensim-org/opensim-core"
OPENSIM_CORE_COMMIT = "0435b081dc383498e217f92ca63bb97616145c14"
_OPENSIM_CORE_URL = f"https://raw.githubusercontent.com/{OPENSIM_CORE_REPOSITORY}/{OPENSIM_CORE_COMMIT}/"


def c3d_walking(folder: str | os.PathLike | None = None, verify: bool = True) -> Path:
    """Path of ``walking2.c3d``, a walking trial of OpenSim's test suite (repository
    ``opensim-org/opensim-core``, Apache-2.0; ``data/c3d_walking_manifest.txt``): 44 markers at
    250 Hz and two force plates at 2000 Hz in one C3D file. Parameters are those of
    :func:`example_subject`; with ``$MUSCLEMETAB_DATA`` set, the file is looked for there or in
    its sub-folder ``c3d_walking``."""
    entries = manifest("c3d_walking")
    root = _local_root(folder, "c3d_walking", entries, verify)
    if root is None:
        root = _fetch_all(entries, "c3d_walking", OPENSIM_CORE_REPOSITORY, OPENSIM_CORE_COMMIT, _OPENSIM_CORE_URL)
    return root / "walking2.c3d"

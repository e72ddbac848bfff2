"""Example data: one subject walking at three speeds.

The files are those published with the reference study (repository
``israelluis/MetabolicRateWalking``, GPL-2.0), downloaded on first use with pooch from a
pinned commit and checked against SHA-256 hashes (``data/example_subject_manifest.txt``).
They are not part of this package.

Set ``MUSCLEMETAB_DATA`` to a folder that already holds the files (for instance a copy
made for offline use, or the folder a test system provides) and no download happens; the
files found there are checked against the same hashes.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from urllib.parse import quote

from .io.atomic import file_sha256
from .errors import DatasetError

__all__ = ["ExampleSubject", "example_subject", "manifest", "SOURCE_COMMIT", "SOURCE_REPOSITORY"]

SOURCE_REPOSITORY = "israelluis/MetabolicRateWalking"
SOURCE_COMMIT = "acaf8a1af4c9dd1fae763b50ea4cabbe0be1a0e9"
_BASE_URL = f"https://raw.githubusercontent.com/{SOURCE_REPOSITORY}/{SOURCE_COMMIT}/"
ENV_VAR = "MUSCLEMETAB_DATA"

SPEEDS = ("slow", "normal", "fast")


def manifest() -> dict[str, tuple[str, str]]:
    """``{local file name: (sha256, path in the source repository)}``."""
    out = {}
    text = resources.files("musclemetab").joinpath("data/example_subject_manifest.txt").read_text()
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


def _fetch_all(entries: dict) -> Path:
    import pooch

    cache = pooch.os_cache("musclemetab") / "example_subject" / SOURCE_COMMIT[:12]
    fetcher = pooch.create(
        path=cache,
        base_url=_BASE_URL,
        registry={name: f"sha256:{sha}" for name, (sha, _) in entries.items()},
        urls={name: _BASE_URL + quote(path) for name, (_, path) in entries.items()},
    )
    for name in entries:
        try:
            fetcher.fetch(name)
        except Exception as exc:
            raise DatasetError(
                f"could not download example file {name} from {SOURCE_REPOSITORY}@{SOURCE_COMMIT[:7]} "
                f"({type(exc).__name__}: {exc}); check the network, or set {ENV_VAR} to a folder "
                "that holds the files"
            ) from None
    return Path(cache)


def example_subject(folder: str | os.PathLike | None = None, verify: bool = True) -> ExampleSubject:
    """Paths of the example subject's files, downloading them if needed.

    Parameters
    ----------
    folder
        A folder holding the files; default ``$MUSCLEMETAB_DATA`` if set, else the pooch
        cache (files downloaded on first use).
    verify
        Check every local file against its SHA-256 (about 30 ms).
    """
    entries = manifest()
    folder = folder or os.environ.get(ENV_VAR)
    if folder:
        root = Path(folder).expanduser()
        missing = [n for n in entries if not (root / n).is_file()]
        if missing:
            raise DatasetError(
                f"{root}: missing example file{'s' if len(missing) > 1 else ''} {', '.join(missing[:4])}"
                f"{' ...' if len(missing) > 4 else ''}; point {ENV_VAR} at a complete copy or unset it to download"
            )
        if verify:
            bad = [n for n, (sha, _) in entries.items() if _sha256(root / n) != sha]
            if bad:
                raise DatasetError(
                    f"{root}: file{'s' if len(bad) > 1 else ''} {', '.join(bad)} differ from the published "
                    "example data (SHA-256 mismatch); restore the original files"
                )
    else:
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

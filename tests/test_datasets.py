"""Example data: local copies, hash checks and the download path (over loopback HTTP)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import musclemetab.datasets as ds
from musclemetab.errors import DatasetError


def test_manifest_matches_the_files(example):
    entries = ds.manifest()
    assert len(entries) == 24
    for name, (sha, _) in entries.items():
        assert ds._sha256(example.folder / name) == sha


def test_paths(example):
    assert example.model.name == "1_scaledHMK_rajagopal2022_MIF2.osim"
    assert example.trial("slow")["emg"].name == "EMG_sub1_slow.mot"
    assert all(p.is_file() for p in example.ik.values())
    with pytest.raises(DatasetError, match="speeds"):
        example.trial("brisk")


def _copy(example, dst: Path) -> Path:
    shutil.copytree(example.folder, dst)
    return dst


def test_incomplete_or_altered_copy_is_refused(example, tmp_path):
    copy = _copy(example, tmp_path / "copy")
    (copy / "ID_sub1_fast.sto").unlink()
    with pytest.raises(DatasetError, match="ID_sub1_fast.sto"):
        ds.example_subject(copy)
    shutil.copy(example.folder / "ID_sub1_fast.sto", copy)
    with open(copy / "IK_sub1_slow.mot", "a") as f:
        f.write("\n")
    with pytest.raises(DatasetError, match="IK_sub1_slow.mot.*SHA-256"):
        ds.example_subject(copy)


def _cache_in(tmp_path, monkeypatch):
    import pooch

    monkeypatch.delenv(ds.ENV_VAR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(pooch, "os_cache", lambda name: tmp_path / "cache" / name)


def test_download_with_pooch_checks_hashes(example, dataset_mirror, tmp_path, monkeypatch):
    root, url = dataset_mirror("example_subject", example.folder, ds.SOURCE_COMMIT)
    monkeypatch.setattr(ds, "_BASE_URL", url)
    _cache_in(tmp_path, monkeypatch)
    subject = ds.example_subject()
    assert subject.model.is_file() and str(tmp_path / "cache") in str(subject.model)
    assert (subject.reference_muscle_analysis / "IK_sub1_normal_MuscleAnalysis_Length.sto").is_file()
    # a tampered file on the server fails the hash check
    shutil.rmtree(tmp_path / "cache")
    tampered = root / ds.SOURCE_COMMIT / ds.manifest()["EMG_sub1_fast.mot"][1]
    tampered.write_text(tampered.read_text() + "\n")
    with pytest.raises(DatasetError, match="EMG_sub1_fast.mot"):
        ds.example_subject()


def test_gait2392_download_with_pooch_checks_hashes(gait2392, dataset_mirror, tmp_path, monkeypatch):
    root, url = dataset_mirror("gait2392_subject01", gait2392.folder, ds.GAIT2392_COMMIT)
    monkeypatch.setattr(ds, "_GAIT2392_URL", url)
    _cache_in(tmp_path, monkeypatch)
    subject = ds.gait2392_subject01()
    assert str(tmp_path / "cache") in str(subject.model)
    for name, (sha, _) in ds.manifest("gait2392_subject01").items():
        assert ds._sha256(subject.folder / name) == sha
    assert subject.ik.read_bytes() == gait2392.ik.read_bytes()
    # a file missing on the server names the file that could not be had
    shutil.rmtree(tmp_path / "cache")
    (root / ds.GAIT2392_COMMIT / ds.manifest("gait2392_subject01")["subject01_walk1_grf.mot"][1]).unlink()
    with pytest.raises(DatasetError, match="subject01_walk1_grf.mot"):
        ds.gait2392_subject01()

"""Example data: local copies, hash checks and the download path (over loopback HTTP)."""

from __future__ import annotations

import functools
import http.server
import shutil
import threading
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


@pytest.fixture()
def mirror(example, tmp_path):
    """A loopback HTTP server laid out like the source repository at the pinned commit."""
    root = tmp_path / "www"
    for name, (_, path) in ds.manifest().items():
        target = root / ds.SOURCE_COMMIT / path
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(example.folder / name, target)
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(root))
    handler.log_message = lambda *a, **k: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield root, f"http://127.0.0.1:{server.server_address[1]}/{ds.SOURCE_COMMIT}/"
    server.shutdown()


def test_download_with_pooch_checks_hashes(mirror, tmp_path, monkeypatch):
    root, url = mirror
    monkeypatch.delenv(ds.ENV_VAR, raising=False)
    monkeypatch.setattr(ds, "_BASE_URL", url)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    import pooch

    monkeypatch.setattr(pooch, "os_cache", lambda name: tmp_path / "cache" / name)
    subject = ds.example_subject()
    assert subject.model.is_file() and str(tmp_path / "cache") in str(subject.model)
    assert (subject.reference_muscle_analysis / "IK_sub1_normal_MuscleAnalysis_Length.sto").is_file()
    # a tampered file on the server fails the hash check
    shutil.rmtree(tmp_path / "cache")
    tampered = root / ds.SOURCE_COMMIT / ds.manifest()["EMG_sub1_fast.mot"][1]
    tampered.write_text(tampered.read_text() + "\n")
    with pytest.raises(DatasetError, match="EMG_sub1_fast.mot"):
        ds.example_subject()

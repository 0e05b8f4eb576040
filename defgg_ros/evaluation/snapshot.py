"""Freeze the training data of shipped weights: the growing dataset cut to a training run's manifest.

``defgg-train`` records, per scene, how many trial records existed when it
started (its manifest) and a fingerprint over exactly those. ``write_snapshot``
copies the header, those scenes and those first trial lines (byte for byte)
into a .tar.gz and checks that the extracted copy has the recorded
fingerprint, so ``defgg-train --data <extracted>`` sees the same data.
"""
from __future__ import annotations

import io
import tarfile
import tempfile
from pathlib import Path

from defgg_ros.atomic import atomic_path
from defgg_ros.data.dataset import manifest_fingerprint


class SnapshotError(RuntimeError):
    """The dataset no longer holds what the training run used."""


def _trial_lines(path: Path, n: int) -> bytes:
    if n == 0:
        return b""
    if not path.is_file():
        raise SnapshotError(f"{path}: missing, the run used {n} records of it")
    lines = path.read_bytes().split(b"\n")
    complete = [ln for ln in lines[:-1] if ln.strip()] if lines else []
    if len(complete) < n:
        raise SnapshotError(f"{path}: has {len(complete)} complete records, the run used {n}")
    return b"\n".join(complete[:n]) + b"\n" if n else b""


def _add(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mtime = 0          # reproducible archive bytes
    tar.addfile(info, io.BytesIO(data))


def write_snapshot(data_root, manifest: dict, fingerprint: str, out_path, top: str = "train_data") -> Path:
    """Write <out_path> (.tar.gz) holding `top`/ = the dataset as the run saw it; verify its fingerprint."""
    data_root = Path(data_root)
    with atomic_path(out_path) as tmp:
        with tarfile.open(tmp, "w:gz", compresslevel=9) as tar:
            _add(tar, f"{top}/dataset.json", (data_root / "dataset.json").read_bytes())
            for sid in sorted(manifest):
                _add(tar, f"{top}/scenes/{sid}.npz", (data_root / "scenes" / f"{sid}.npz").read_bytes())
                _add(tar, f"{top}/trials/{sid}.jsonl",
                     _trial_lines(data_root / "trials" / f"{sid}.jsonl", int(manifest[sid])))
        got = verify_snapshot(tmp, manifest, top)
        if got != fingerprint:
            raise SnapshotError(f"snapshot fingerprint {got} != the run's {fingerprint}: the dataset changed")
    Path(out_path).chmod(0o644)
    return Path(out_path)


def verify_snapshot(archive, manifest: dict, top: str = "train_data") -> str:
    """Extract to a temporary folder and return the fingerprint of the manifest's trials there."""
    with tempfile.TemporaryDirectory() as tmp:
        with tarfile.open(archive, "r:gz") as tar:
            tar.extractall(tmp, filter="data")
        return manifest_fingerprint(Path(tmp) / top, manifest)

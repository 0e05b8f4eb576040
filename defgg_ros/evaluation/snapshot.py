"""Freeze the training data of shipped weights: the growing dataset cut to a training run's manifest.

``defgg-train`` records, per scene, how many trial records existed when it
started (its manifest) and a fingerprint over exactly those. ``write_snapshot``
copies the header, those scenes and those first trial lines (byte for byte)
into a .tar.gz and checks that the extracted copy has the recorded
fingerprint, so ``defgg-train --data <extracted>`` sees the same data.
"""
from __future__ import annotations

import gzip
import io
import json
import tarfile
import tempfile
from pathlib import Path

from defgg_ros.atomic import atomic_path
from defgg_ros.data.dataset import manifest_fingerprint
from defgg_ros.data.format import trials_path


class SnapshotError(RuntimeError):
    """The dataset no longer holds what the training run used."""


def _trial_lines(path: Path, n: int) -> bytes:
    if n == 0:
        return b""
    if not path.is_file():
        raise SnapshotError(f"{path}: missing, the run used {n} records of it")
    data = path.read_bytes()
    lines = (gzip.decompress(data) if path.suffix == ".gz" else data).split(b"\n")
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
    return write_merged_snapshot([(data_root, manifest, fingerprint)], out_path, top)[0]


def write_merged_snapshot(parts, out_path, top: str = "train_data") -> tuple:
    """Freeze one or more datasets (root, manifest, fingerprint) with disjoint scenes into one archive.

    The header (dataset.json) is the first root's; ``frozen_from.json`` lists every source with its
    manifest and fingerprint, and each part's fingerprint is re-checked on the extracted copy.
    Returns (path, fingerprint of the whole frozen copy).
    """
    seen = {}
    for root, manifest, _ in parts:
        for sid in manifest:
            if sid in seen:
                raise SnapshotError(f"scene {sid} is in both {seen[sid]} and {root}")
            seen[sid] = root
    sources = [{"root": str(root), "fingerprint": fp, "manifest": manifest} for root, manifest, fp in parts]
    with atomic_path(out_path) as tmp:
        with tarfile.open(tmp, "w:gz", compresslevel=9) as tar:
            _add(tar, f"{top}/dataset.json", (Path(parts[0][0]) / "dataset.json").read_bytes())
            _add(tar, f"{top}/frozen_from.json", json.dumps(sources, indent=1, sort_keys=True).encode())
            for root, manifest, _ in parts:
                root = Path(root)
                for sid in sorted(manifest):
                    _add(tar, f"{top}/scenes/{sid}.npz", (root / "scenes" / f"{sid}.npz").read_bytes())
                    _add(tar, f"{top}/trials/{sid}.jsonl",
                         _trial_lines(trials_path(root, sid), int(manifest[sid])))
        whole = {sid: n for _, manifest, _ in parts for sid, n in manifest.items()}
        with tempfile.TemporaryDirectory() as extracted:
            with tarfile.open(tmp, "r:gz") as tar:
                tar.extractall(extracted, filter="data")
            for root, manifest, fp in parts:
                got = manifest_fingerprint(Path(extracted) / top, manifest)
                if got != fp:
                    raise SnapshotError(f"{root}: frozen fingerprint {got} != {fp}: the dataset changed while freezing")
            fingerprint = manifest_fingerprint(Path(extracted) / top, whole)
    Path(out_path).chmod(0o644)
    return Path(out_path), fingerprint


def verify_snapshot(archive, manifest: dict, top: str = "train_data") -> str:
    """Extract to a temporary folder and return the fingerprint of the manifest's trials there."""
    with tempfile.TemporaryDirectory() as tmp:
        with tarfile.open(archive, "r:gz") as tar:
            tar.extractall(tmp, filter="data")
        return manifest_fingerprint(Path(tmp) / top, manifest)

"""The on-disk dataset format, written by the generator and read by training.

Why this format: numpy's compressed ``.npz`` for images (depth compresses
well, loads without pickle via ``allow_pickle=False``) and append-only JSON
lines for trials (one fsync'd line per finished trial, so a killed run loses
only trials in flight and a rerun can skip what is done). Both are readable
without this package.

Layout (format version 1)::

    <root>/dataset.json             format, version, generator settings
    <root>/scenes/<scene_id>.npz    one rendered scene per object x modulus
    <root>/trials/<scene_id>.jsonl  one JSON record per grasp trial (.jsonl.gz once sealed: complete,
                                    compressed, read the same way, never appended to)
    <root>/card.md                  generated dataset card

Scene arrays: ``depth_m`` (float32 HxW, metres along the optical axis),
``youngs_modulus_pa`` (float32 HxW, 0 on background), ``object_mask``
(uint8 HxW, 0 background, 1.. object parts), ``camera_k`` (3x3 intrinsics),
``base_T_camera`` (4x4, camera optical frame in the world/base frame),
``meta`` (a JSON string: object name, modulus, Poisson ratio, seed, ...).

Trial records: see TrialRecord; ``rect`` is the grasp rectangle in the
scene image (centre u/v in px, angle in rad in [-pi/2, pi/2] measured from
the image u axis towards v, opening width in px, finger height in px).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from defgg_ros.atomic import append_jsonl, atomic_path, compress_jsonl, read_jsonl, write_json_atomic
from defgg_ros.constants import (  # noqa: F401 - the statuses are part of this format
    SHAKE_POSITIVE_THRESHOLD_MPS2,
    STATUS_EXPLODED,
    STATUS_LIFT_FAILED,
    STATUS_OK,
    STATUS_TIMEOUT,
)
from defgg_ros.grasping.rectangles import GraspRect  # noqa: F401 - the rect of every trial record

FORMAT_NAME = "defgg-dataset"
FORMAT_VERSION = 1
SCENE_ARRAYS = ("depth_m", "youngs_modulus_pa", "object_mask", "camera_k", "base_T_camera")
# Trial outcomes. Only "ok" and "lift_failed" become labels; simulation
# failures are recorded but never used for training.
LABELLED_STATUSES = (STATUS_OK, STATUS_LIFT_FAILED)
# Trials that raised (a bug or damaged input, not a simulation outcome) go to this file in the run's
# folder (generator and evaluation alike) instead of ending the run; the next run retries them.
TRIAL_ERRORS_FILE = "errors.jsonl"


class DatasetError(RuntimeError):
    """A dataset file is missing, truncated, tampered with or of another format."""


def scene_id_for(object_name: str, youngs_modulus_pa: float) -> str:
    """Stable file-name-safe id, e.g. ``box_03__E2e+04``."""
    if "/" in object_name or object_name.startswith("."):
        raise ValueError(f"bad object name {object_name!r}")
    return f"{object_name}__E{youngs_modulus_pa:.0e}"


@dataclass
class TrialRecord:
    trial_id: str
    scene_id: str
    object_name: str
    youngs_modulus_pa: float
    candidate_index: int
    rect: GraspRect
    # World-frame grasp: fingertip centre (m), yaw about z (rad), opening (m).
    position_m: list
    yaw_rad: float
    width_m: float
    status: str
    shake_accels_mps2: list | None = None
    twist_accels_radps2: list | None = None
    grasp_force_n: float = 0.0
    seed: int = 0
    cpu_s: float = 0.0
    sim: dict = field(default_factory=dict)
    note: str = ""

    @property
    def shake_mean_mps2(self) -> float | None:
        if not self.shake_accels_mps2:
            return None
        return float(np.mean(self.shake_accels_mps2))

    @property
    def label(self) -> bool | None:
        """True/False for a labelled trial, None when the sim failed."""
        if self.status == STATUS_LIFT_FAILED:
            return False
        if self.status != STATUS_OK or self.shake_mean_mps2 is None:
            return None
        return self.shake_mean_mps2 >= SHAKE_POSITIVE_THRESHOLD_MPS2

    def to_json(self) -> dict:
        d = asdict(self)
        d["label"] = self.label
        d["shake_mean_mps2"] = self.shake_mean_mps2
        return d

    @classmethod
    def from_json(cls, d: dict) -> TrialRecord:
        d = dict(d)
        d.pop("label", None)
        d.pop("shake_mean_mps2", None)
        d["rect"] = GraspRect(**d["rect"])
        return cls(**d)


@dataclass
class Scene:
    scene_id: str
    depth_m: np.ndarray
    youngs_modulus_pa: np.ndarray
    object_mask: np.ndarray
    camera_k: np.ndarray
    base_T_camera: np.ndarray
    meta: dict

    @property
    def object_name(self) -> str:
        return self.meta["object_name"]


class DatasetWriter:
    """Writes scenes and appends trials; safe to reopen on a partial dataset."""

    def __init__(self, root, generator_settings: dict | None = None):
        self.root = Path(root)
        (self.root / "scenes").mkdir(parents=True, exist_ok=True)
        (self.root / "trials").mkdir(parents=True, exist_ok=True)
        header = self.root / "dataset.json"
        if header.exists():
            check_header(self.root)
        else:
            write_json_atomic(header, {"format": FORMAT_NAME, "version": FORMAT_VERSION,
                                       "generator": generator_settings or {}})

    def has_scene(self, scene_id: str) -> bool:
        return (self.root / "scenes" / f"{scene_id}.npz").exists()

    def write_scene(self, scene: Scene) -> Path:
        path = self.root / "scenes" / f"{scene.scene_id}.npz"
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(
                    f,
                    depth_m=scene.depth_m.astype(np.float32),
                    youngs_modulus_pa=scene.youngs_modulus_pa.astype(np.float32),
                    object_mask=scene.object_mask.astype(np.uint8),
                    camera_k=np.asarray(scene.camera_k, dtype=np.float64),
                    base_T_camera=np.asarray(scene.base_T_camera, dtype=np.float64),
                    meta=np.array(json.dumps(scene.meta, sort_keys=True)),
                )
        return path

    def append_trial(self, trial: TrialRecord) -> None:
        path = trials_path(self.root, trial.scene_id)
        if path.suffix == ".gz":
            raise DatasetError(f"{path}: the scene's trials are sealed (compressed, complete); write a new dataset")
        append_jsonl(path, trial.to_json())

    def finished_trial_ids(self, scene_id: str) -> set:
        return {r["trial_id"] for r in read_jsonl(trials_path(self.root, scene_id))}


def trials_path(root, scene_id: str) -> Path:
    """The trial file of a scene: sealed (.jsonl.gz) when there is one, else the growing .jsonl."""
    plain = Path(root) / "trials" / f"{scene_id}.jsonl"
    sealed = plain.with_name(plain.name + ".gz")
    return sealed if sealed.exists() else plain


def seal_trials(root) -> int:
    """Compress every scene's trial file of a finished dataset (records unchanged, so is the fingerprint);
    returns how many files were sealed."""
    check_header(root)
    paths = sorted((Path(root) / "trials").glob("*.jsonl"))
    for path in paths:
        if path.with_name(path.name + ".gz").exists():
            raise DatasetError(f"{path}: both plain and sealed trial files exist; remove one")
        compress_jsonl(path)
    return len(paths)


def check_header(root) -> dict:
    path = Path(root) / "dataset.json"
    try:
        header = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetError(f"{root}: no dataset.json; not a defgg dataset") from None
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{path}: corrupt ({exc})") from None
    if header.get("format") != FORMAT_NAME or header.get("version") != FORMAT_VERSION:
        raise DatasetError(f"{path}: format {header.get('format')!r} v{header.get('version')!r}, "
                           f"expected {FORMAT_NAME!r} v{FORMAT_VERSION}")
    return header


def read_scene(path) -> Scene:
    """Load one scene shard; raise DatasetError when it is truncated or odd."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in (*SCENE_ARRAYS, "meta") if k not in z.files]
            if missing:
                raise DatasetError(f"{path}: missing arrays {missing}")
            arrays = {k: z[k] for k in SCENE_ARRAYS}
            meta = json.loads(str(z["meta"]))
    except DatasetError:
        raise
    except Exception as exc:  # zipfile/zlib/ValueError on truncated or tampered files
        raise DatasetError(f"{path}: cannot read scene ({type(exc).__name__}: {exc})") from None
    shape = arrays["depth_m"].shape
    if len(shape) != 2 or arrays["youngs_modulus_pa"].shape != shape or arrays["object_mask"].shape != shape:
        raise DatasetError(f"{path}: image arrays disagree in shape")
    if arrays["camera_k"].shape != (3, 3) or arrays["base_T_camera"].shape != (4, 4):
        raise DatasetError(f"{path}: camera arrays have wrong shapes")
    return Scene(scene_id=path.stem, meta=meta, **arrays)


def read_scene_meta(path) -> dict:
    """One scene shard's metadata alone (the card's per-scene facts; the images stay on disk)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            if "meta" not in z.files:
                raise DatasetError(f"{path}: missing arrays ['meta']")
            return json.loads(str(z["meta"]))
    except DatasetError:
        raise
    except Exception as exc:  # zipfile/zlib/ValueError on truncated or tampered files
        raise DatasetError(f"{path}: cannot read scene ({type(exc).__name__}: {exc})") from None


def read_trials(root, scene_id: str) -> list:
    path = trials_path(root, scene_id)
    try:
        records = read_jsonl(path)
    except ValueError as exc:      # a corrupt line inside the file: a clear error, not a traceback
        raise DatasetError(str(exc)) from None
    return trials_of(path, records)


def trials_of(path, records) -> list:
    """TrialRecords of a trial file's records (dicts, already read from path); DatasetError naming the file."""
    try:
        return [TrialRecord.from_json(r) for r in records]
    except (ValueError, TypeError, KeyError) as exc:
        raise DatasetError(f"{path}: {exc}") from None


def list_scene_ids(root) -> list:
    check_header(root)
    return sorted(p.stem for p in (Path(root) / "scenes").glob("*.npz"))


def dataset_fingerprint(root) -> str:
    """sha256 over scene files and trial records (order-independent of writes)."""
    h = hashlib.sha256()
    for scene_id in list_scene_ids(root):
        h.update((Path(root) / "scenes" / f"{scene_id}.npz").read_bytes())
        for r in sorted(read_jsonl(trials_path(root, scene_id)), key=lambda r: r["trial_id"]):
            h.update(json.dumps(r, sort_keys=True).encode())
    return h.hexdigest()[:16]

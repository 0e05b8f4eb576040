"""torch Dataset over the on-disk format (defgg_ros/data/format.py).

One item = one scene (object x modulus) with the ground-truth maps of its
positive trials, optionally augmented. The dataset is being generated while
we train, so a *manifest* ({scene_id: number of trial records}) freezes what a
run uses: the trial files are append-only, so the first n records of a scene
never change, and a resumed run sees exactly the data it started with.

Augmentation randomness comes from (seed, epoch, index) only, so an item is
the same whichever worker or process loads it, and a resumed run repeats an
uninterrupted one bit for bit.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from defgg_ros.constants import NETWORK_INPUT_SIZE_PX
from defgg_ros.data.augment import AugmentConfig, augment_sample
from defgg_ros.data.format import DatasetError, GraspRect, list_scene_ids, read_scene, read_trials
from defgg_ros.data.groundtruth import ground_truth_maps, training_targets
from defgg_ros.data.labels import height_offset_m, is_positive
from defgg_ros.model.preprocess import crop, crop_origin, encode_depth, inpaint_depth
from defgg_ros.stiffness import encode_stiffness_image


def build_manifest(root) -> dict:
    """{scene_id: number of trial records now} for every scene on disk."""
    return {sid: len(read_trials(root, sid)) for sid in list_scene_ids(root)}


def manifest_fingerprint(root, manifest: dict) -> str:
    """sha256 (16 hex) over the scene files and the manifest's trial records."""
    h = hashlib.sha256()
    for sid in sorted(manifest):
        h.update((Path(root) / "scenes" / f"{sid}.npz").read_bytes())
        for trial in read_trials(root, sid)[: manifest[sid]]:
            h.update(json.dumps(trial.to_json(), sort_keys=True).encode())
    return h.hexdigest()[:16]


@dataclass
class SceneSample:
    """A scene cropped to the network input, with its positive rectangles."""

    scene_id: str
    object_name: str
    youngs_modulus_pa: float
    depth_m: np.ndarray          # filled (no holes)
    youngs_modulus_image_pa: np.ndarray
    object_mask: np.ndarray
    camera_k: np.ndarray         # of the crop
    positives: list              # GraspRect in crop pixels
    n_trials: int


def load_scene_sample(root, scene_id: str, n_trials: int | None = None,
                      size_px: int = NETWORK_INPUT_SIZE_PX, label_rule: str = "mean",
                      max_height_offset_m: float | None = None) -> SceneSample:
    """label_rule: which trials are positives (defgg_ros/data/labels.py); max_height_offset_m: if set,
    only trials whose TCP was within it of the executor's height for their pixel (height_offset_m)."""
    scene = read_scene(Path(root) / "scenes" / f"{scene_id}.npz")
    trials = read_trials(root, scene_id)
    trials = trials if n_trials is None else trials[:n_trials]
    if max_height_offset_m is not None:
        trials = [t for t in trials if abs(height_offset_m(t, scene.depth_m)) <= max_height_offset_m]
    try:
        u0, v0 = crop_origin(scene.depth_m.shape, scene.object_mask, size_px)
        depth = inpaint_depth(crop(scene.depth_m, (u0, v0), size_px))
    except ValueError as exc:
        raise DatasetError(f"scene {scene_id}: {exc}") from None
    k = scene.camera_k.copy()
    k[0, 2] -= u0
    k[1, 2] -= v0
    positives = [GraspRect(t.rect.center_u_px - u0, t.rect.center_v_px - v0, t.rect.angle_rad,
                           t.rect.width_px, t.rect.finger_height_px) for t in trials if is_positive(t, label_rule)]
    return SceneSample(scene_id=scene_id, object_name=scene.object_name,
                       youngs_modulus_pa=float(scene.meta.get("youngs_modulus_pa", np.max(scene.youngs_modulus_pa))),
                       depth_m=depth, youngs_modulus_image_pa=crop(scene.youngs_modulus_pa, (u0, v0), size_px).copy(),
                       object_mask=crop(scene.object_mask, (u0, v0), size_px).copy(), camera_k=k,
                       positives=positives, n_trials=len(trials))


class GraspDataset(torch.utils.data.Dataset):
    """Items: {"x": C x H x W, "y": 4 x H x W, "index": scene index}.

    scene_ids: the scenes to use (e.g. one split); manifest limits their
    trials; scenes without a positive trial are skipped (the paper trains on
    positive grasps only). augment=None gives the plain scenes.
    """

    def __init__(self, root, scene_ids, manifest: dict | None = None, uses_stiffness: bool = True,
                 augment: AugmentConfig | None = None, samples_per_scene: int = 1, seed: int = 0,
                 label_rule: str = "mean", max_height_offset_m: float | None = None):
        self.root = Path(root)
        self.uses_stiffness = uses_stiffness
        self.augment = augment
        self.samples_per_scene = int(samples_per_scene)
        self.seed = int(seed)
        self.epoch = 0
        samples = [load_scene_sample(root, sid, None if manifest is None else manifest[sid], label_rule=label_rule,
                                     max_height_offset_m=max_height_offset_m) for sid in scene_ids]
        self.samples = [s for s in samples if s.positives]
        self.skipped_scene_ids = [s.scene_id for s in samples if not s.positives]

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.samples) * self.samples_per_scene

    def arrays(self, index: int):
        """(depth_m, moduli_pa, mask, positives) of item `index`, augmented if configured."""
        s = self.samples[index // self.samples_per_scene]
        if self.augment is None:
            return s.depth_m, s.youngs_modulus_image_pa, s.object_mask, s.positives
        rng = np.random.default_rng([self.seed, self.epoch, index])
        return augment_sample(s.depth_m, s.youngs_modulus_image_pa, s.object_mask, s.positives, rng, self.augment)

    def __getitem__(self, index: int) -> dict:
        if not 0 <= index < len(self):
            raise IndexError(index)
        depth, moduli, _, rects = self.arrays(index)
        channels = [encode_depth(depth)]
        if self.uses_stiffness:
            channels.append(encode_stiffness_image(moduli))
        targets = training_targets(*ground_truth_maps(rects, depth.shape))
        return {"x": torch.from_numpy(np.stack(channels)), "y": torch.from_numpy(targets),
                "index": index // self.samples_per_scene}

"""A small, learnable synthetic dataset written in the real on-disk format.

For tests and smoke runs only: no physics. Each object is a box seen from
above at the real camera (fx = 385 px, 0.40 m above the table, 300x300).
Labels follow a rule that needs the stiffness input, in the spirit of the
paper's finding (pinch soft objects, cage stiff ones):

* every positive grasp closes across the box's short side;
* stiff boxes (E >= SOFT_STIFF_BOUNDARY_PA): positives near the centre, with
  an opening wider than the box (caging);
* soft boxes: positives near the two ends, with an opening narrower than the
  box (pinching);
* grasps along the long side are negatives.

So a depth-only network cannot fit both rules; a depth + stiffness one can.
"""
from __future__ import annotations

import math

import numpy as np

from defgg_ros.constants import (
    CAMERA_FX_PX,
    CAMERA_FY_PX,
    CAMERA_HEIGHT_ABOVE_TABLE_M,
    FINGER_PAD_WIDTH_M,
    NETWORK_INPUT_SIZE_PX,
    POISSON_RATIO,
    TRAINING_YOUNGS_MODULI_PA,
)
from defgg_ros.data.format import STATUS_OK, DatasetWriter, GraspRect, Scene, TrialRecord, scene_id_for
from defgg_ros.data.groundtruth import wrap_angle

SOFT_STIFF_BOUNDARY_PA = 1e6
_HELD_MPS2, _DROPPED_MPS2 = 40.0, 10.0  # per-direction shake results giving a clear label


def synthetic_camera_k(size_px: int = NETWORK_INPUT_SIZE_PX) -> np.ndarray:
    c = (size_px - 1) / 2.0
    return np.array([[CAMERA_FX_PX, 0.0, c], [0.0, CAMERA_FY_PX, c], [0.0, 0.0, 1.0]])


def _box_scene(rng, name: str, youngs_modulus_pa: float, shape: dict, size_px: int) -> Scene:
    v, u = np.mgrid[0:size_px, 0:size_px].astype(np.float64)
    du, dv = u - shape["cu"], v - shape["cv"]
    along = du * math.cos(shape["yaw"]) + dv * math.sin(shape["yaw"])
    across = -du * math.sin(shape["yaw"]) + dv * math.cos(shape["yaw"])
    inside = (np.abs(along) <= shape["length_px"] / 2) & (np.abs(across) <= shape["width_px"] / 2)
    depth = np.full((size_px, size_px), CAMERA_HEIGHT_ABOVE_TABLE_M, np.float32)
    depth[inside] -= shape["height_m"]
    base_T_camera = np.eye(4)
    base_T_camera[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down
    base_T_camera[2, 3] = CAMERA_HEIGHT_ABOVE_TABLE_M
    return Scene(scene_id=scene_id_for(name, youngs_modulus_pa), depth_m=depth,
                 youngs_modulus_pa=np.where(inside, youngs_modulus_pa, 0.0).astype(np.float32),
                 object_mask=inside.astype(np.uint8), camera_k=synthetic_camera_k(size_px),
                 base_T_camera=base_T_camera,
                 meta={"object_name": name, "youngs_modulus_pa": youngs_modulus_pa,
                       "poisson_ratio": POISSON_RATIO, "synthetic": True, **shape})


def _grasp_label(stiff: bool, offset_frac: float, across: bool) -> bool:
    if not across:
        return False
    return abs(offset_frac) < 0.15 if stiff else abs(offset_frac) > 0.3


def _trials(rng, scene: Scene, shape: dict, n: int) -> list:
    e = scene.meta["youngs_modulus_pa"]
    stiff = e >= SOFT_STIFF_BOUNDARY_PA
    top_m = CAMERA_HEIGHT_ABOVE_TABLE_M - shape["height_m"]
    finger_px = FINGER_PAD_WIDTH_M * CAMERA_FX_PX / top_m
    trials = []
    for i in range(n):
        offset_frac = rng.uniform(-0.45, 0.45)
        across = rng.random() < 0.75
        t = offset_frac * shape["length_px"]
        cu = shape["cu"] + t * math.cos(shape["yaw"])
        cv = shape["cv"] + t * math.sin(shape["yaw"])
        angle = shape["yaw"] + (math.pi / 2 if across else 0.0)
        span = shape["width_px"] if across else shape["length_px"]
        width_px = span + 12.0 if stiff else 0.8 * span
        label = _grasp_label(stiff, offset_frac, across)
        rect = GraspRect(float(cu), float(cv), float(wrap_angle(angle)), float(width_px), float(finger_px))
        trials.append(TrialRecord(
            trial_id=f"{scene.scene_id}__{i:03d}", scene_id=scene.scene_id, object_name=scene.object_name,
            youngs_modulus_pa=e, candidate_index=i, rect=rect, position_m=[0.0, 0.0, 0.0],
            yaw_rad=float(wrap_angle(angle)), width_m=float(width_px * top_m / CAMERA_FX_PX), status=STATUS_OK,
            shake_accels_mps2=[_HELD_MPS2 if label else _DROPPED_MPS2] * 16, seed=i,
            sim={"synthetic": True}, note="synthetic rule-based label"))
    return trials


def write_synthetic_dataset(root, n_objects: int = 8, moduli_pa=TRAINING_YOUNGS_MODULI_PA,
                            trials_per_scene: int = 16, seed: int = 0,
                            size_px: int = NETWORK_INPUT_SIZE_PX) -> DatasetWriter:
    """Write `n_objects` boxes x `moduli_pa` scenes with labelled trials to `root`."""
    rng = np.random.default_rng(seed)
    writer = DatasetWriter(root, {"generator": "synthetic", "seed": seed, "n_objects": n_objects})
    for k in range(n_objects):
        shape = {"cu": size_px / 2 + rng.uniform(-20, 20), "cv": size_px / 2 + rng.uniform(-20, 20),
                 "yaw": rng.uniform(-math.pi, math.pi), "length_px": rng.uniform(70, 120),
                 "width_px": rng.uniform(26, 40), "height_m": rng.uniform(0.03, 0.06)}
        for e in moduli_pa:
            scene = _box_scene(rng, f"synth_box_{k:02d}", float(e), shape, size_px)
            writer.write_scene(scene)
            for trial in _trials(rng, scene, shape, trials_per_scene):
                writer.append_trial(trial)
    return writer

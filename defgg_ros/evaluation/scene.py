"""Render an evaluation scene: one object on the table, seen by the training camera.

The camera is ``defgg_ros.sim.camera.TopDownCamera`` (the same intrinsics and
height as the training scenes, 300x300), centred over the object. The
object's yaw comes from the evaluation seed and its name, so both models see
exactly the same scene and a rerun renders it again identically.
"""
from __future__ import annotations

import hashlib
import math

import numpy as np

from defgg_ros.sim import camera as sim_camera
from defgg_ros.sim import objects as sim_objects
from defgg_ros.sim import world as sim_world

OBJECT_XY_M = (0.0, 0.0)


def object_yaw_rad(object_name: str, seed: int) -> float:
    """A reproducible yaw in [0, pi) per (object, seed): independent of the order of evaluation."""
    digest = hashlib.sha256(f"{object_name}|{seed}".encode()).digest()
    return math.pi * int.from_bytes(digest[:8], "big") / 2**64


def render_scene(client: int, spec, yaw_rad: float, camera: sim_camera.TopDownCamera | None = None) -> dict:
    """Depth (m), true per-pixel modulus (Pa), part mask, K and base_T_camera of `spec` at OBJECT_XY_M.

    The object is rendered as loaded (resting on the table), like the
    generator's scenes: the network has only ever seen undeformed objects.
    """
    camera = camera or sim_camera.TopDownCamera(centre_xy_m=OBJECT_XY_M)
    sim_world.create_world(client, spec.part_moduli_pa())
    loaded = sim_objects.load_object(client, spec, OBJECT_XY_M, yaw_rad)
    images = sim_camera.render_object_images(client, loaded, camera)
    if not np.any(images["object_mask"] > 0):
        raise RuntimeError(f"{spec.name}: object not visible to the camera (nothing rendered)")
    return images


def input_moduli_image(true_moduli_pa: np.ndarray, object_mask: np.ndarray, error_pct: float = 0.0,
                       override_pa: float | None = None) -> np.ndarray:
    """The stiffness input the model is given: the true moduli scaled by (1 + error_pct/100),
    or every object pixel set to `override_pa` (e.g. "assume the object is rigid")."""
    if not -100.0 < error_pct:
        raise ValueError(f"stiffness error must be > -100 %, got {error_pct}")
    out = np.asarray(true_moduli_pa, dtype=np.float32) * np.float32(1.0 + error_pct / 100.0)
    if override_pa is not None:
        out = np.where(np.asarray(object_mask) > 0, np.float32(override_pa), np.float32(0.0))
    return out.astype(np.float32)

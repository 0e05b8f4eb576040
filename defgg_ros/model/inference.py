"""GraspPredictor: checkpoint + images -> ranked grasps (no rclpy, no training code).

Used by the ROS inference node, the evaluation and the demo::

    predictor = GraspPredictor.from_checkpoint("models/defgg_cnn.pt")
    prediction = predictor.predict(depth_m, youngs_modulus_pa, camera_k, object_mask, top_k=3)
    best = prediction.candidates[0]   # GraspCandidate, full-image pixels + camera-frame metres

Images may be any size >= 300x300 (e.g. the cell's 640x480): a 300x300
window is cut around the object mask's bounding box (or the image centre) and
the maps are returned in that window's coordinates with its offset.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from defgg_ros.grasping.config import DEFAULT_POSTPROCESS, PostProcessConfig
from defgg_ros.grasping.geometry import check_camera_k, pixel_to_camera, width_px_to_m
from defgg_ros.grasping.postprocess import GraspMaps, maps_from_network
from defgg_ros.grasping.ranking import CLEARANCE_POOL, rank_grasps  # noqa: F401 - CLEARANCE_POOL: callers
from defgg_ros.model.checkpoint import CheckpointError, load_checkpoint, network_from_checkpoint
from defgg_ros.model.preprocess import (
    InvalidInputError,
    check_depth_image,
    crop,
    crop_origin,
    inpaint_depth,
    network_input,
)
from defgg_ros.model.runtime import compile_for_inference
from defgg_ros.perception.plausibility import check_moduli_plausible
from defgg_ros.stiffness import InvalidYoungsModulus

__all__ = ["GraspPredictor", "GraspPrediction", "GraspCandidate", "CheckpointError",
           "InvalidInputError", "InvalidYoungsModulus"]


@dataclass(frozen=True)
class GraspCandidate:
    """One ranked grasp; pixels are FULL-image coordinates."""

    center_u_px: float
    center_v_px: float
    angle_rad: float            # from image u towards v, in [-pi/2, pi/2]
    width_px: float             # finger opening in pixels
    width_m: float              # opening in metres at the surface depth (depth_m); the labels' width_px is at the
    # TCP's depth (the grasp point's half height), where it is up to ~7 % wider: a metric grasp takes
    # evaluation.planning.plan_world_grasp (and the cell the planner's geometric width)
    quality: float              # in [0, 1]
    depth_m: float              # (inpainted) depth at the grasp centre
    position_camera_m: tuple    # (x, y, z) in the camera optical frame
    youngs_modulus_pa: float    # input modulus at the grasp centre (0 = background)
    object_id: int              # object mask label at the centre, -1 without mask/background
    fingers_clear: bool | None = None   # both fingers land beside the objects (None: not checked)


@dataclass(frozen=True)
class GraspPrediction:
    maps: GraspMaps             # 300x300 maps in crop coordinates (angle and width filtered when read)
    crop_offset_px: tuple       # (u0, v0): full-image pixel of the crop's (0, 0)
    candidates: list            # GraspCandidate, best first

    @property
    def q(self) -> np.ndarray:
        return self.maps.q

    @property
    def angle_rad(self) -> np.ndarray:
        return self.maps.angle_rad

    @property
    def width_px(self) -> np.ndarray:
        return self.maps.width_px

    @property
    def best(self) -> GraspCandidate | None:
        return self.candidates[0] if self.candidates else None


class GraspPredictor:
    """A trained (Def-)GG-CNN with its pre- and post-processing."""

    def __init__(self, network: torch.nn.Module, checkpoint_meta: dict, fingerprint: str,
                 postprocess: PostProcessConfig = DEFAULT_POSTPROCESS, runtime: str = "auto"):
        self.network = network.eval()
        self.uses_stiffness = network.config.input_channels == 2
        self.input_size_px = network.config.input_size_px
        self.checkpoint_meta = checkpoint_meta
        self.fingerprint = fingerprint
        self.postprocess = postprocess
        self._forward, self.runtime = compile_for_inference(self.network, runtime)

    @classmethod
    def from_checkpoint(cls, path, device: str = "cpu", num_threads: int | None = None,
                        postprocess: PostProcessConfig = DEFAULT_POSTPROCESS, runtime: str = "auto"):
        """Load and verify `path`; raise CheckpointError when it cannot be trusted.

        num_threads sets torch's (process-wide) intra-op thread count.
        runtime: "auto" (fastest verified), "eager" or "torchscript".
        """
        if device != "cpu":
            raise ValueError(f"only device='cpu' is supported on this cell, got {device!r}")
        if num_threads is not None:
            torch.set_num_threads(int(num_threads))
        payload = load_checkpoint(path)
        network = network_from_checkpoint(payload, path)
        meta = {k: payload[k] for k in ("network_config", "input_normalization", "data_fingerprint",
                                        "weights_sha256", "meta")}
        meta["path"] = str(path)
        return cls(network, meta, payload["weights_sha256"][:16], postprocess, runtime)

    def raw_maps(self, network_input_chw: np.ndarray) -> np.ndarray:
        """4 x H x W raw outputs for one encoded input (C x H x W)."""
        with torch.inference_mode():
            x = torch.from_numpy(np.ascontiguousarray(network_input_chw, dtype=np.float32))[None]
            return self._forward(x)[0].numpy()

    def predict(self, depth_m, youngs_modulus_pa, camera_k, object_mask=None, top_k: int = 1,
                finger_clearance_opening_m: float = 0.0, contact_angle: bool = False) -> GraspPrediction:
        """Ranked grasps for one scene (see the module docstring and docs/model.md).

        finger_clearance_opening_m > 0 (with an object mask): among the CLEARANCE_POOL best peaks,
        grasps whose fingers, opened this wide, can land beside the masked objects (after a slide
        along the closing line, grasping/finger_clearance.py) come first, slid; then the others.
        contact_angle (with an object mask and an opening): then each returned grasp's angle is
        re-chosen at its centre for square pad contacts (grasping/contact_angle.py), kept only if its
        fingers clear too or the original's did not.
        Up to top_k grasps: the quality map's local maxima, then (when it has fewer) the best pixels
        apart from them (grasping.postprocess.find_peaks, fill), so the first ranks never depend on top_k.

        Raises ValueError subclasses (InvalidInputError, InvalidYoungsModulus)
        for bad shapes, sizes, depth without valid pixels, NaN/negative moduli,
        non-finite intrinsics or an empty mask.
        """
        depth_full = check_depth_image(depth_m)
        moduli = _check_moduli(youngs_modulus_pa, depth_full.shape)
        k = check_camera_k(camera_k)
        mask = _check_mask(object_mask, depth_full.shape)
        if top_k < 1:
            raise InvalidInputError(f"top_k must be >= 1, got {top_k}")
        origin = crop_origin(depth_full.shape, mask, self.input_size_px)
        depth_crop = inpaint_depth(crop(depth_full, origin, self.input_size_px))
        moduli_crop = crop(moduli, origin, self.input_size_px)
        maps = maps_from_network(self.raw_maps(network_input(depth_crop, moduli_crop, self.uses_stiffness)),
                                 self.postprocess)
        mask_crop = None if mask is None else crop(mask, origin, self.input_size_px)
        grasps, clear = rank_grasps(maps, self.postprocess, depth_crop, mask_crop, k[0, 0], top_k,
                                    finger_clearance_opening_m, contact_angle)
        candidates = [dataclasses.replace(self._candidate(g, origin, depth_crop, moduli_crop, mask_crop, k),
                                          fingers_clear=c) for g, c in zip(grasps, clear)]
        return GraspPrediction(maps=maps, crop_offset_px=origin, candidates=candidates)

    @staticmethod
    def _candidate(g, origin, depth_crop, moduli_crop, mask_crop, k) -> GraspCandidate:
        u, v = g.center_u_px + origin[0], g.center_v_px + origin[1]
        z = float(depth_crop[g.center_v_px, g.center_u_px])
        obj = -1 if mask_crop is None else int(mask_crop[g.center_v_px, g.center_u_px]) or -1
        return GraspCandidate(
            center_u_px=float(u), center_v_px=float(v), angle_rad=g.angle_rad, width_px=g.width_px,
            width_m=float(width_px_to_m(g.width_px, z, k[0, 0])), quality=g.quality, depth_m=z,
            position_camera_m=tuple(float(c) for c in pixel_to_camera(u, v, z, k)),
            youngs_modulus_pa=float(moduli_crop[g.center_v_px, g.center_u_px]), object_id=obj)


def _check_moduli(youngs_modulus_pa, shape) -> np.ndarray:
    moduli = np.asarray(youngs_modulus_pa)
    if moduli.shape != shape:
        raise InvalidInputError(f"youngs_modulus_pa shape {moduli.shape} does not match depth {shape}")
    if not np.issubdtype(moduli.dtype, np.number):
        raise InvalidYoungsModulus(f"youngs_modulus_pa must be numeric, got dtype {moduli.dtype}")
    # The plausibility rule of every entry (SetStiffness, topics, requests), checked on the full
    # image so a bad pixel outside the crop is still reported.
    check_moduli_plausible(moduli, "youngs_modulus_pa")
    return moduli.astype(np.float32, copy=False)


def _check_mask(object_mask, shape):
    if object_mask is None:
        return None
    mask = np.asarray(object_mask)
    if mask.shape != shape:
        raise InvalidInputError(f"object_mask shape {mask.shape} does not match depth {shape}")
    if not (np.issubdtype(mask.dtype, np.integer) or mask.dtype == bool):
        raise InvalidInputError(f"object_mask must hold integer labels, got dtype {mask.dtype}")
    if not np.any(mask > 0):
        raise InvalidInputError("object_mask has no object pixel (all zero)")
    return mask.astype(np.int32, copy=False)


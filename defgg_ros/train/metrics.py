"""Validation: loss, the GG-CNN rectangle metric per modulus, stiffness response.

Grasps are ranked by the same post-processing as at inference
(defgg_ros.grasping), so the metric scores what the robot would execute.
"""
from __future__ import annotations

from collections import defaultdict

import numpy as np
import torch

from defgg_ros.constants import FINGER_PAD_WIDTH_M
from defgg_ros.data.format import GraspRect
from defgg_ros.grasping.config import DEFAULT_POSTPROCESS, PostProcessConfig
from defgg_ros.grasping.postprocess import grasps_from_maps, maps_from_network
from defgg_ros.grasping.rectangles import rectangle_match
from defgg_ros.model.preprocess import network_input


def grasp_loss(outputs: torch.Tensor, targets: torch.Tensor, positive_weight: float = 1.0) -> dict:
    """GG-CNN loss: mean squared error of each output map, summed.

    positive_weight > 1 weighs pixels inside positive rectangles (target
    Q > 0) that much more than background pixels; 1.0 is GG-CNN's plain MSE.
    """
    if positive_weight == 1.0:
        weight = None
    else:
        weight = 1.0 + (positive_weight - 1.0) * (targets[:, :1] > 0).to(outputs.dtype)
    per_map = {}
    for i, name in enumerate(("q", "cos", "sin", "width")):
        err = (outputs[:, i:i + 1] - targets[:, i:i + 1]) ** 2
        per_map[name] = err.mean() if weight is None else (weight * err).mean()
    return {"loss": sum(per_map.values()), **per_map}


def raw_outputs(model: torch.nn.Module, x_chw: np.ndarray) -> np.ndarray:
    with torch.inference_mode():
        return model(torch.from_numpy(np.ascontiguousarray(x_chw))[None])[0].numpy()


def predicted_rect(maps, camera_k, depth_m, postprocess: PostProcessConfig = DEFAULT_POSTPROCESS) -> GraspRect:
    """Top-1 grasp as a rectangle; its finger height is the Panda pad size at the grasp depth."""
    g = grasps_from_maps(maps, postprocess, top_k=1)[0]
    z = float(depth_m[g.center_v_px, g.center_u_px])
    return GraspRect(g.center_u_px, g.center_v_px, g.angle_rad, g.width_px, FINGER_PAD_WIDTH_M * camera_k[0, 0] / z)


def rectangle_accuracy(model: torch.nn.Module, samples, uses_stiffness: bool,
                       postprocess: PostProcessConfig = DEFAULT_POSTPROCESS) -> dict:
    """Top-1 rectangle metric over scene samples, overall and per modulus."""
    model.eval()
    hits = defaultdict(list)
    for s in samples:
        raw = raw_outputs(model, network_input(s.depth_m, s.youngs_modulus_image_pa, uses_stiffness))
        rect = predicted_rect(maps_from_network(raw, postprocess), s.camera_k, s.depth_m, postprocess)
        hits[f"{s.youngs_modulus_pa:.0e}"].append(rectangle_match(rect, s.positives))
    per_modulus = {e: {"n": len(h), "accuracy": float(np.mean(h))} for e, h in sorted(hits.items(), key=_by_e)}
    all_hits = [x for h in hits.values() for x in h]
    return {"accuracy": float(np.mean(all_hits)) if all_hits else float("nan"), "n": len(all_hits),
            "per_modulus": per_modulus}


def _by_e(item):
    return float(item[0])


def dataset_loss(model: torch.nn.Module, dataset, batch_size: int = 8, positive_weight: float = 1.0) -> float:
    model.eval()
    total, n = 0.0, 0
    loader = torch.utils.data.DataLoader(dataset, batch_size=batch_size, shuffle=False)
    with torch.inference_mode():
        for batch in loader:
            total += float(grasp_loss(model(batch["x"]), batch["y"], positive_weight)["loss"]) * len(batch["x"])
            n += len(batch["x"])
    return total / max(n, 1)


def stiffness_response(model: torch.nn.Module, samples, moduli_pa,
                       postprocess: PostProcessConfig = DEFAULT_POSTPROCESS) -> dict:
    """How far Q moves when only the stiffness input changes.

    Each sample's object is given each modulus in turn (same depth). Returns,
    per input modulus, the mean |Q - Q_ref| over object pixels and the mean
    top-1 grasp displacement (px) relative to the sample's true modulus.
    """
    model.eval()
    uses_stiffness = model.config.input_channels == 2
    dq, shift = defaultdict(list), defaultdict(list)
    for s in samples:
        obj = s.object_mask > 0
        ref_maps = maps_from_network(raw_outputs(model, network_input(s.depth_m, s.youngs_modulus_image_pa,
                                                                      uses_stiffness)), postprocess)
        ref = grasps_from_maps(ref_maps, postprocess)[0]
        for e in moduli_pa:
            moduli = np.where(obj, e, 0.0).astype(np.float32)
            maps = maps_from_network(raw_outputs(model, network_input(s.depth_m, moduli, uses_stiffness)), postprocess)
            g = grasps_from_maps(maps, postprocess)[0]
            dq[e].append(float(np.abs(maps.q - ref_maps.q)[obj].mean()))
            shift[e].append(float(np.hypot(g.center_u_px - ref.center_u_px, g.center_v_px - ref.center_v_px)))
    return {f"{e:.0e}": {"mean_abs_dq": float(np.mean(dq[e])), "mean_top1_shift_px": float(np.mean(shift[e]))}
            for e in moduli_pa} if samples else {}

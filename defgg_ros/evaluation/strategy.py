"""The strategy figure: where the stiffness-aware model grasps one object at a low and a high modulus.

For each modulus the object is rendered (true stiffness), the model's quality
map and best grasps are drawn, and the best grasp is described by numbers:
its offset from the object's centre (mm), its opening (mm) and the
object's extent along the closing line through the grasp centre. A grasp
whose opening spans the whole object along that line *cages* it; one that
closes on a local feature (rim, edge, lobe) *pinches*.
"""
from __future__ import annotations

import math

import numpy as np

from defgg_ros.evaluation import figures, scene
from defgg_ros.model.preprocess import crop, network_input

# Opening >= this fraction of the object's extent along the closing line = cage.
CAGE_FRACTION = 0.9


def extent_along_line_px(mask: np.ndarray, center_uv, angle_rad: float, max_px: int = 400) -> float:
    """Length (px) of the object's span along the closing line through the grasp centre (outermost pixels)."""
    d = np.array([math.cos(angle_rad), math.sin(angle_rad)])
    ts = np.arange(-max_px, max_px + 1, 0.5)
    pts = np.rint(np.asarray(center_uv, dtype=float)[None] + ts[:, None] * d[None]).astype(int)
    h, w = mask.shape
    ok = (pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0) & (pts[:, 1] < h)
    hit = np.zeros(len(ts), dtype=bool)
    hit[ok] = mask[pts[ok, 1], pts[ok, 0]] > 0
    if not hit.any():
        return 0.0
    return float(ts[hit].max() - ts[hit].min() + 1)


def describe_grasp(candidate, mask: np.ndarray, camera_k: np.ndarray) -> dict:
    vs, us = np.nonzero(mask)
    m_per_px = candidate.depth_m / camera_k[0, 0]
    extent_px = extent_along_line_px(mask, (candidate.center_u_px, candidate.center_v_px), candidate.angle_rad)
    offset_px = math.hypot(candidate.center_u_px - us.mean(), candidate.center_v_px - vs.mean())
    return {"center_uv_px": [candidate.center_u_px, candidate.center_v_px], "angle_rad": candidate.angle_rad,
            "quality": candidate.quality, "width_mm": 1000 * candidate.width_m,
            "offset_from_centre_mm": 1000 * offset_px * m_per_px,
            "object_extent_along_closing_mm": 1000 * extent_px * m_per_px,
            "strategy": "cage" if candidate.width_px >= CAGE_FRACTION * extent_px else "pinch",
            "part_under_centre": candidate.object_id}


def strategy_panels(predictor, eval_object, moduli_pa, client: int, seed: int = 0, top_k: int = 5) -> tuple:
    """(figure panels, per-modulus description) for one object."""
    panels, described = [], {}
    for e in moduli_pa:
        images = scene.render_scene(client, eval_object.spec(e), scene.object_yaw_rad(eval_object.name, seed))
        pred = predictor.predict(images["depth_m"], images["youngs_modulus_pa"], images["camera_k"],
                                 images["object_mask"], top_k=top_k)
        u0, v0 = pred.crop_offset_px
        size = pred.q.shape[0]
        depth_crop = crop(images["depth_m"], (u0, v0), size)
        stiffness = network_input(depth_crop, crop(images["youngs_modulus_pa"], (u0, v0), size), True)[1]
        grasps = [(c.center_u_px - u0, c.center_v_px - v0, c.angle_rad, c.width_px) for c in pred.candidates]
        panels.append({"label": f"E = {e:.0e} Pa", "stiffness": stiffness, "depth_m": depth_crop, "q": pred.q,
                       "grasps": grasps})
        described[f"{e:g}"] = [describe_grasp(c, images["object_mask"], images["camera_k"]) for c in pred.candidates]
    return panels, described


def write_strategy_figure(panels, described, path, object_name: str, model_name: str) -> None:
    best = "; ".join(f"E={e}: {d[0]['strategy']}, width {d[0]['width_mm']:.0f} mm, "
                     f"{d[0]['offset_from_centre_mm']:.0f} mm off centre" for e, d in described.items() if d)
    figures.strategy_figure(panels, path, f"{model_name} on {object_name}: {best}")

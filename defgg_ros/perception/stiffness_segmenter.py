"""Depth -> (stiffness image, labels) with the current assignments (no rclpy).

The one object the segmentation node and the grasp inference node (for
PlanGrasp requests that carry `objects`) both use, so a request and the
live stream are segmented identically.
"""
import json
from dataclasses import dataclass, field

import numpy as np

from defgg_ros.perception.segmentation import (
    OBJECT_MAX_HEIGHT_M,
    OBJECT_MIN_AREA_PX,
    OBJECT_MIN_HEIGHT_M,
    SegmentationResult,
    segment_objects,
)
from defgg_ros.perception.stiffness_assignment import (
    StiffnessEntry,
    assign_stiffness,
    check_plausible_modulus,
    make_entry,
)
from defgg_ros.perception.tabletop import TabletopConfig, perceive

# Objects nobody described get a mid-range modulus: 2e6 Pa (firm rubber) is
# the geometric middle of the paper's soft moduli (2e4..2e9 Pa in decades),
# so an unknown object is neither treated as a sponge nor as wood.
DEFAULT_YOUNGS_MODULUS_PA = 2e6


@dataclass(frozen=True)
class SegmenterConfig:
    default_youngs_modulus_pa: float = DEFAULT_YOUNGS_MODULUS_PA
    entries: tuple[StiffnessEntry, ...] = ()
    min_height_m: float = OBJECT_MIN_HEIGHT_M
    min_area_px: int = OBJECT_MIN_AREA_PX
    background_depth_m: np.ndarray | None = field(default=None, compare=False)
    max_height_m: float = OBJECT_MAX_HEIGHT_M
    # Tabletop segmentation in the robot frame (perception/tabletop.py) when both are set and no
    # empty-scene capture is in use: touching objects apart, the workspace box, the self-filter.
    tabletop: TabletopConfig | None = None
    base_T_camera: np.ndarray | None = field(default=None, compare=False)

    def __post_init__(self):
        check_plausible_modulus(self.default_youngs_modulus_pa, "default Young's modulus")
        if not (np.isfinite(self.min_height_m) and 0 < self.min_height_m < self.max_height_m):
            raise ValueError(f"need 0 < min_height_m < max_height_m, got {self.min_height_m}, {self.max_height_m}")
        if int(self.min_area_px) < 1:
            raise ValueError(f"min_area_px must be >= 1, got {self.min_area_px}")


@dataclass(frozen=True)
class SegmenterOutput:
    youngs_modulus_pa: np.ndarray   # HxW float32, 0 = background
    labels: np.ndarray              # HxW uint8, 0 = background
    segmentation: SegmentationResult
    per_object: dict                # label -> (entry name, Pa) of the whole-object assignment


def run_segmenter(config: SegmenterConfig, depth_m: np.ndarray, camera_k, robot_mask=None,
                  base_T_camera=None) -> SegmenterOutput:
    """Segment float32 metres depth and paint the moduli; raises ValueError subclasses.
    base_T_camera (4x4) overrides config.base_T_camera (the node's TF lookup)."""
    pose = base_T_camera if base_T_camera is not None else config.base_T_camera
    if config.tabletop is not None and pose is not None and config.background_depth_m is None:
        result = tabletop_segmentation(config.tabletop, depth_m, camera_k, pose, robot_mask)
    else:
        result = segment_objects(depth_m, camera_k, config.background_depth_m,
                                 config.min_height_m, int(config.min_area_px), config.max_height_m)
    image, per_object = assign_stiffness(result.labels, result.centroids_px, config.entries,
                                         config.default_youngs_modulus_pa)
    return SegmenterOutput(image, result.labels, result, per_object)


def tabletop_segmentation(tabletop: TabletopConfig, depth_m, camera_k, base_T_camera, robot_mask=None):
    """perception/tabletop.py's objects as a SegmentationResult (labels, heights, centroids, areas)."""
    view = perceive(depth_m, camera_k, base_T_camera, tabletop, robot_mask)
    centroids, areas = {}, {}
    for label in view.object_ids:
        vs, us = np.nonzero(view.labels == label)
        if vs.size:
            centroids[int(label)] = (float(us.mean()), float(vs.mean()))
            areas[int(label)] = int(vs.size)
    return SegmentationResult(view.labels, view.height_m, tuple(sorted(centroids)), centroids, areas, None)


def entries_from_dicts(items) -> tuple[StiffnessEntry, ...]:
    """[{name, youngs_modulus_pa, roi: [x, y, w, h], region_only}] -> validated entries."""
    if not isinstance(items, list):
        raise ValueError(f"objects must be a list of mappings, got {type(items).__name__}")
    entries = []
    for index, item in enumerate(items):
        if not isinstance(item, dict) or "youngs_modulus_pa" not in item:
            raise ValueError(f"objects[{index}] must be a mapping with at least youngs_modulus_pa, got {item!r}")
        unknown = set(item) - {"name", "youngs_modulus_pa", "roi", "region_only"}
        if unknown:
            raise ValueError(f"objects[{index}] has unknown keys {sorted(unknown)}")
        entries.append(make_entry(item.get("name", f"object{index}"), item["youngs_modulus_pa"],
                                  item.get("roi", (0, 0, 0, 0)), bool(item.get("region_only", False))))
    return tuple(entries)


def entries_from_json(text: str) -> tuple[StiffnessEntry, ...]:
    """The `objects_json` parameter form (a JSON list of entry mappings)."""
    try:
        items = json.loads(text) if text.strip() else []
    except json.JSONDecodeError as exc:
        raise ValueError(f"objects_json is not valid JSON: {exc}") from exc
    return entries_from_dicts(items)


def entries_to_dicts(entries) -> list[dict]:
    return [{"name": e.name, "youngs_modulus_pa": e.youngs_modulus_pa,
             "roi": [e.roi.x_offset_px, e.roi.y_offset_px, e.roi.width_px, e.roi.height_px],
             "region_only": e.region_only} for e in entries]

"""The stiffness entries' parameter form (no rclpy): `objects_json` <-> StiffnessEntry tuples, the default.

The segmentation node (the cell's only perceiver) assigns them to the objects it perceives
(planning/perceived_frame.perceive_frame).
"""
import json

from defgg_ros.perception.stiffness_assignment import StiffnessEntry, check_plausible_modulus, make_entry

# Objects nobody described get a mid-range modulus: 2e6 Pa (firm rubber) is
# the geometric middle of the paper's soft moduli (2e4..2e9 Pa in decades),
# so an unknown object is neither treated as a sponge nor as wood.
DEFAULT_YOUNGS_MODULUS_PA = 2e6


def check_plausible_default(youngs_modulus_pa: float) -> float:
    """The default modulus, or ValueError when it is not a plausible one."""
    return float(check_plausible_modulus(youngs_modulus_pa, "default Young's modulus"))


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

"""Young's modulus per object -> stiffness image (no rclpy).

Entries mirror defgg_interfaces/ObjectStiffness: a name, a modulus and an
ROI in depth-image pixels (width/height 0 = the whole image).
- region_only = False: every object whose mask centroid is inside the ROI
  takes the modulus (later entries override earlier ones).
- region_only = True: only that object's pixels inside the ROI take it —
  how a multi-material object (a hard handle on a soft body) is expressed.
  Region entries are applied after all whole-object entries.
Objects no entry addresses take the default modulus. Background stays 0.
"""
from dataclasses import dataclass

import numpy as np

from defgg_ros.perception.plausibility import (  # noqa: F401 - the limits are re-exported for callers
    PLAUSIBLE_YOUNGS_MODULUS_MAX_PA,
    PLAUSIBLE_YOUNGS_MODULUS_MIN_PA,
    check_moduli_plausible,
)
from defgg_ros.stiffness import InvalidYoungsModulus, check_youngs_modulus


@dataclass(frozen=True)
class Roi:
    """Pixel rectangle; width_px == 0 or height_px == 0 means the whole image."""

    x_offset_px: int = 0
    y_offset_px: int = 0
    width_px: int = 0
    height_px: int = 0

    @property
    def whole_image(self) -> bool:
        return self.width_px == 0 or self.height_px == 0

    def contains(self, u_px: float, v_px: float) -> bool:
        if self.whole_image:
            return True
        return (self.x_offset_px <= u_px < self.x_offset_px + self.width_px
                and self.y_offset_px <= v_px < self.y_offset_px + self.height_px)

    def pixel_mask(self, shape: tuple[int, int]) -> np.ndarray:
        mask = np.zeros(shape, dtype=bool)
        if self.whole_image:
            mask[:] = True
        else:
            mask[self.y_offset_px:self.y_offset_px + self.height_px,
                 self.x_offset_px:self.x_offset_px + self.width_px] = True
        return mask

    def overlaps(self, width_px: int, height_px: int) -> bool:
        return self.whole_image or (self.x_offset_px < width_px and self.y_offset_px < height_px)


@dataclass(frozen=True)
class StiffnessEntry:
    name: str
    youngs_modulus_pa: float
    roi: Roi = Roi()
    region_only: bool = False


def check_plausible_modulus(youngs_modulus_pa, what: str = "Young's modulus") -> float:
    """Finite, > 0 and physically plausible, else InvalidYoungsModulus."""
    try:
        value = check_youngs_modulus(youngs_modulus_pa)
    except InvalidYoungsModulus as exc:
        raise InvalidYoungsModulus(f"{what}: {exc}") from exc
    check_moduli_plausible(value, what, background_allowed=False)   # the rule of every stiffness entry
    return value


def make_entry(name: str, youngs_modulus_pa, roi_xywh=(0, 0, 0, 0), region_only: bool = False) -> StiffnessEntry:
    """Validated StiffnessEntry; raises InvalidYoungsModulus or ValueError."""
    value = check_plausible_modulus(youngs_modulus_pa, f"object {name!r}")
    xywh = [int(x) for x in roi_xywh]
    if len(xywh) != 4 or any(x < 0 for x in xywh):
        raise ValueError(f"object {name!r}: roi must be 4 non-negative integers (x, y, w, h), got {roi_xywh!r}")
    roi = Roi(*xywh)
    if region_only and roi.whole_image:
        raise ValueError(f"object {name!r}: region_only needs a roi with width and height > 0")
    return StiffnessEntry(str(name), value, roi, bool(region_only))


def check_entries_fit_image(entries, width_px: int, height_px: int) -> None:
    """Raise ValueError for an ROI that lies completely outside a width x height image."""
    for entry in entries:
        if not entry.roi.overlaps(width_px, height_px):
            raise ValueError(f"object {entry.name!r}: roi {entry.roi} lies outside the {width_px}x{height_px} image")


def assign_stiffness(labels: np.ndarray, centroids_px: dict, entries, default_youngs_modulus_pa: float):
    """Stiffness image (float32 Pa, 0 = background) and label -> (name, Pa) of whole-object entries."""
    default = check_plausible_modulus(default_youngs_modulus_pa, "default Young's modulus")
    per_object = {label: ("default", default) for label in centroids_px}
    for entry in entries:
        if entry.region_only:
            continue
        for label, (u, v) in centroids_px.items():
            if entry.roi.contains(u, v):
                per_object[label] = (entry.name, entry.youngs_modulus_pa)
    lut = np.zeros(256, dtype=np.float32)
    for label, (_, value) in per_object.items():
        lut[label] = value
    image = lut[labels]
    objects = labels > 0
    for entry in entries:
        if entry.region_only:
            image[objects & entry.roi.pixel_mask(labels.shape)] = entry.youngs_modulus_pa
    return image, per_object

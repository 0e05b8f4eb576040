"""Where the next object goes in the bin: a grid of slots over the bin's floor, remembered across goals.

With one place point every object lands on the one before (issue 48: the third pick's lowering pushed into the
stack with 33.4 N and knocked objects out of the bin). The executor keeps one BinSlots: a goal with an empty
place pose takes the first free slot, and the slot counts as used once the hand opened there. `reset()` (the
executor's reset_bin service) frees them all after someone emptied the bin. Pure: no ROS.
"""
import math
from dataclasses import dataclass

import numpy as np


class BinFull(RuntimeError):
    """Every slot holds an object placed since the last reset."""


@dataclass(frozen=True)
class BinArea:
    """The bin's inner floor in the base frame (m), the distance between slot centres and the least distance of a
    slot centre from a wall."""

    x_min_m: float
    x_max_m: float
    y_min_m: float
    y_max_m: float
    pitch_m: float
    wall_margin_m: float

    @classmethod
    def from_list(cls, area_m, pitch_m: float, wall_margin_m: float) -> "BinArea":
        values = [float(v) for v in area_m]
        if len(values) != 4 or not all(math.isfinite(v) for v in values):
            raise ValueError(f"bin_inner_m must be 4 finite numbers [x_min, x_max, y_min, y_max], got {area_m}")
        area = cls(*values, float(pitch_m), float(wall_margin_m))
        if not (math.isfinite(area.pitch_m) and area.pitch_m > 0):
            raise ValueError(f"bin_slot_pitch_m must be > 0, got {pitch_m}")
        if not (math.isfinite(area.wall_margin_m) and area.wall_margin_m >= 0):
            raise ValueError(f"bin_wall_margin_m must be >= 0, got {wall_margin_m}")
        if min(area.x_max_m - area.x_min_m, area.y_max_m - area.y_min_m) < 2 * area.wall_margin_m:
            raise ValueError(f"bin_inner_m {values} has no room for a slot {wall_margin_m} m from every wall "
                             "(bin_wall_margin_m)")
        return area

    def contains(self, x_m: float, y_m: float) -> bool:
        return self.x_min_m <= x_m <= self.x_max_m and self.y_min_m <= y_m <= self.y_max_m


def slot_centres(area: BinArea) -> list:
    """(x, y) of each slot, row by row: as many as fit along each side at pitch_m with every centre at least
    wall_margin_m from the walls, centred in the bin."""
    def axis(low: float, high: float) -> np.ndarray:
        room = high - low - 2 * area.wall_margin_m
        count = int(math.floor(room / area.pitch_m + 1e-9)) + 1
        first = (low + high) / 2 - area.pitch_m * (count - 1) / 2
        return first + area.pitch_m * np.arange(count)

    return [(float(x), float(y)) for x in axis(area.x_min_m, area.x_max_m) for y in axis(area.y_min_m, area.y_max_m)]


class BinSlots:
    def __init__(self, area: BinArea):
        self.area = area
        self.centres = slot_centres(area)
        self._used: set = set()

    @property
    def used(self) -> int:
        return len(self._used)

    def next_free(self) -> int:
        """The index of the first free slot (BinFull when none is)."""
        for index in range(len(self.centres)):
            if index not in self._used:
                return index
        raise BinFull(f"the bin is full: all {len(self.centres)} slots hold an object placed since the last reset")

    def mark_used(self, index: int) -> None:
        self._used.add(int(index))

    def reset(self) -> int:
        """Free every slot; returns how many were used."""
        count, self._used = len(self._used), set()
        return count


# --- the recovery's drop zone -----------------------------------------------------------------------------
def check_drop_xy(drop_xy_m, workspace_box_m, keep_out_radius_m: float) -> tuple:
    """(x, y) of a recovery's put-down point, ValueError unless it lies inside the workspace box [x_min, x_max,
    y_min, y_max] (where the camera's objects are picked from) and at least keep_out_radius_m from the base axis."""
    x, y = (float(v) for v in drop_xy_m)
    x_min, x_max, y_min, y_max = (float(v) for v in workspace_box_m)
    if not (x_min <= x <= x_max and y_min <= y <= y_max):
        raise ValueError(f"recovery_drop_xy_m ({x:.3f}, {y:.3f}) is outside workspace_box_m {list(workspace_box_m)}: "
                         "an object put down there could not be picked again")
    if math.hypot(x, y) < keep_out_radius_m:
        raise ValueError(f"recovery_drop_xy_m ({x:.3f}, {y:.3f}) is {math.hypot(x, y):.3f} m from the base axis, "
                         f"inside base_keep_out_radius_m ({keep_out_radius_m:.3f} m)")
    return x, y


def default_drop_xy(observation_tcp_xy_m, workspace_box_m, keep_out_radius_m: float) -> tuple:
    """The point of the workspace box nearest the observation pose's TCP (x, y), pushed out along its bearing from
    the base to keep_out_radius_m when closer (then back into the box): from there the arm sees it and reaches it
    in a short motion. ValueError when no such point exists (check_drop_xy)."""
    x_min, x_max, y_min, y_max = (float(v) for v in workspace_box_m)
    x = min(max(float(observation_tcp_xy_m[0]), x_min), x_max)
    y = min(max(float(observation_tcp_xy_m[1]), y_min), y_max)
    radius = math.hypot(x, y)
    if radius < keep_out_radius_m:
        scale = (keep_out_radius_m + 1e-6) / radius if radius > 0 else 0.0   # 1 um: out, despite rounding
        x, y = (x * scale, y * scale) if radius > 0 else (keep_out_radius_m + 1e-6, 0.0)
        x, y = min(max(x, x_min), x_max), min(max(y, y_min), y_max)
    return check_drop_xy((x, y), workspace_box_m, keep_out_radius_m)

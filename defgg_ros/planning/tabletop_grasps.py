"""Grasps on every object of a tabletop view, each one geometrically feasible (no rclpy).

    grasps = plan_tabletop_grasps(view, predictor, youngs_modulus_pa_image, top_k=5)

The network runs once on the view's height map (perception/tabletop.py) seen as a virtual top-down
depth image at its training pixel scale, so one forward pass covers every object in the workspace
and its width map is in training pixels whatever the camera. Per object, its best quality peaks
are checked, and the first one that passes every rule below becomes the object's grasp; the
objects are then ranked by quality, one grasp per object first (top-5 = five distinct objects when
five are graspable), then further grasps on the same objects.

Feasibility, in metres in the robot's frame, checked against what the camera saw (FreeSpace: a
point is free when its camera ray reaches a surface behind it; points hidden behind objects, off
the image or without a return are not):
- the fingertips go down to `tip height` (the executor's rule: half the height seen at the grasp
  centre, grasping/geometry.tcp_height_m, minus the fingertip's offset below the TCP);
- the object's extent along the closing line is the run of points at the tip height through the
  centre that are not free (the object, a touching neighbour, or its hidden far side), over the
  band the pads sweep; the opening is that extent plus CLEARANCE_M on each side (geometric, so the
  same object gets the same opening at any resolution; the network's width is kept for reference),
  and must fit the hand's GRIPPER_MAX_WIDTH_M: so no grasp on a face wider than the gripper (a
  cereal box's top);
- both finger pads (thickness x pad width) must land in free space at the tip height (objects,
  neighbours, the robot, unseen space are not) over their whole sweep: from just outside the opening
  out to the executor's pre-grasp opening (control/gripper_rule.pre_grasp_opening_m: the opening + 10 mm,
  at most 80 mm; the hand descends opened that wide);
- the closing direction: the feasible one with the narrowest extent (within OPENING_TIE_M), ties
  in this order: across the object's faces (the axes of its footprint's minimum-area rectangle,
  the one nearer the network's angle first), the network's angle, 15 degree steps away from it;
  the centre moves to the middle of the object's extent.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from defgg_ros.constants import (
    CAMERA_HEIGHT_ABOVE_TABLE_M,
    FINGER_PAD_WIDTH_M,
    GRIPPER_MAX_WIDTH_M,
    PANDA_FINGER_THICKNESS_M,
    PANDA_FINGERTIP_BELOW_TCP_M,
)
from defgg_ros.control.gripper_rule import pre_grasp_opening_m
from defgg_ros.control.kinematics import MIN_TCP_HEIGHT_ABOVE_TABLE_M, WorkspaceError, check_workspace
from defgg_ros.grasping.geometry import tcp_height_m
from defgg_ros.grasping.postprocess import find_peaks, maps_from_network
from defgg_ros.model.preprocess import network_input
from defgg_ros.perception.tabletop import CELL_M, TabletopView, fill_holes, partly_seen_objects
from defgg_ros.planning.contact_radii import PadContacts, perceived_pad_contacts
from defgg_ros.planning.section_outline import SECTION_CELL_M, perceived_section

# Free space the fingers need between the object and each pad while closing.
CLEARANCE_M = 0.006
# A cell counts as material between (or under) the fingers when it stands this much above the tip.
TIP_MARGIN_M = 0.003
ANGLE_STEPS = 12                      # closing directions tried: 180 / 12 = 15 degrees apart
PEAKS_PER_OBJECT = 3
DISTINCT_CELLS = 5
DISTINCT_ANGLE_DEG = 20.0
MAX_HALF_EXTENT_CELLS = int(math.ceil(GRIPPER_MAX_WIDTH_M / CELL_M))
PAD_SAMPLES = 5
PAD_BLOCKED_FRACTION = 0.0
# Pad positions sampled between a grasp's opening and the executor's wider pre-grasp opening (the sweep of
# the closing pads): at most (80 - 12) / 2 mm / 12 = 2.8 mm apart, under the pads' 3.5 mm sample spacing.
SWEEP_SAMPLES = 12
# Samples along the closing line, in height-map cells (half a cell: the extent to ~0.5 mm).
LINE_STEP_CELLS = 0.5
# Closing directions whose extents differ by less than this count as equally narrow.
OPENING_TIE_M = 0.003
# Why an object got no grasp (TabletopPlan.rejected), in the order the tests run: the object is lower than
# the fingertips reach under the centre; wider than the hand along every direction; a pad would land on
# something (or the grasp's middle is off the object); the grasp lies outside the workspace box; the arm
# cannot reach it top-down. NO_PEAK: the network's quality has no peak on it.
TOO_LOW, WIDTH, COLLISION, WORKSPACE, REACH, NO_PEAK = "too low", "width", "collision", "workspace", "reach", \
    "no quality peak"
REJECTIONS = (NO_PEAK, TOO_LOW, WIDTH, COLLISION, WORKSPACE, REACH)
# A point is free when the surface seen along its ray lies this far behind it, plus three times the
# camera's depth noise at that distance (TabletopView.depth_noise) on surfaces other than the table.
CARVING_TOLERANCE_M = 0.002
MEDIAN_WINDOW_PX = 5
MEDIAN_NOISE_SHARE = 0.63


@dataclass(frozen=True)
class TabletopGrasp:
    object_id: int
    quality: float
    position_base_m: tuple       # (x, y, z): the object's surface at the grasp centre, robot base frame
    closing_direction_base: tuple  # unit (x, y, z) the fingers close along (horizontal on the table)
    approach_direction_base: tuple  # unit, towards the table (minus the table normal)
    width_m: float               # opening to command: extent + 2 clearance (<= the gripper's maximum)
    extent_m: float              # the object's extent along the closing line (what is between the fingers)
    network_width_m: float       # the network's width at the peak (training pixels x CELL_M), for reference
    youngs_modulus_pa: float
    cell_rc: tuple               # (row, col) in the height map
    # The smoothed quality at the peak before its clip to [0, 1]: what grasps are ranked on (the clipped
    # quality ties at 1.0 wherever the network overshoots; docs/model.md "Post-processing").
    rank_quality: float = float("nan")
    # The pads' contacts (a PadContacts, or a tuple of radii: all point contacts), or what makes them when first
    # read (a search makes grasps at every peak it checks, ~1-3 ms each under load; only the grasps a request
    # returns need their contacts). Made once for both contact_radii_m and contact_line_lengths_m.
    pad_contacts_source: object = field(default=PadContacts(), compare=False, repr=False)
    # The section the pads squeeze ((mask, heights) on SECTION_CELL_M cells, planning/section_outline.py), or what
    # makes it when first read (as the contacts: only the grasps a request returns); None: not perceived.
    section_source: object = field(default=None, compare=False, repr=False)

    @functools.cached_property
    def pad_contacts(self) -> PadContacts:
        source = self.pad_contacts_source
        value = source() if callable(source) else source
        if isinstance(value, PadContacts):
            return PadContacts(tuple(value.radii_m), tuple(value.line_lengths_m))
        return PadContacts(radii_m=tuple(value))

    @functools.cached_property
    def section_heights_m(self) -> np.ndarray | None:
        """The object's height above the table (m) on the section's cells (rows across the closing direction, the
        grasp line the middle row; columns along it; 0: not the object): the squeeze's section law. None: not
        perceived or nothing of the object at the fingertips' height."""
        if self.section_source is None:
            return None
        mask, heights = self.section_source() if callable(self.section_source) else self.section_source
        return heights.astype(np.float32) if mask.any() else None

    @property
    def contact_radii_m(self) -> tuple:
        """Per pad, the pad on the -closing side first: the radius (m) of the sphere standing for the object's
        surface where the pad touches it (at a line contact the curved direction's; planning/contact_radii.py,
        from the height map); (): flat faces, the squeeze's flat law (docs/squeeze.md)."""
        return self.pad_contacts.radii_m

    @property
    def contact_line_lengths_m(self) -> tuple:
        """Per pad, in contact_radii_m's order: 0 a point contact, > 0 the length (m) of the line the pad touches
        where the surface is straight one way; (): all point contacts (or flat faces)."""
        return self.pad_contacts.line_lengths_m


def virtual_depth(view: TabletopView) -> np.ndarray:
    """The height map as the top-down depth image the network was trained on (camera 0.40 m up)."""
    return (CAMERA_HEIGHT_ABOVE_TABLE_M - view.grid_height_m).astype(np.float32)


def grid_moduli(view: TabletopView, youngs_modulus_pa=None, default_pa: float = 2e6, cells=None) -> np.ndarray:
    """Young's modulus per height-map cell: the modulus of the pixel that gave the cell its height
    (multi-material objects keep their parts), holes and pixels without one take their object's median.
    cells: label_cells(view.grid_labels), when the caller has them."""
    labels = view.grid_labels
    out = np.zeros(labels.shape, np.float32)
    if youngs_modulus_pa is None:
        out[labels > 0] = default_pa
        return out
    flat = np.asarray(youngs_modulus_pa, np.float32).reshape(-1)
    cells = label_cells(labels) if cells is None else cells
    pixel = view.grid_pixel.reshape(-1)[cells.index]
    values = np.where(pixel >= 0, flat[np.maximum(pixel, 0)], np.float32(0.0))
    for start, end in zip(cells.starts, cells.ends):
        mine = values[start:end]                 # a view: filled in place
        known = mine[mine > 0]
        mine[mine <= 0] = float(np.median(known)) if known.size else default_pa
    out.reshape(-1)[cells.index] = values
    return out


@dataclass(frozen=True)
class LabelCells:
    """The labelled cells of a label image grouped by label: their flat indices sorted by label (a
    stable radix sort of uint8, so each label's cells stay in raster order) and each label's
    [start, end) among them."""
    index: np.ndarray
    labels: np.ndarray
    starts: np.ndarray
    ends: np.ndarray


def label_cells(labels: np.ndarray) -> LabelCells:
    flat = labels.reshape(-1)
    index = np.flatnonzero(flat)
    values = flat[index]
    order = np.argsort(values, kind="stable")
    index, values = index[order], values[order]
    starts = np.flatnonzero(np.concatenate([[True], values[1:] != values[:-1]])) if index.size else index
    return LabelCells(index, values[starts], starts, np.append(starts[1:], index.size).astype(np.int64))


def label_boxes(labels: np.ndarray, cells: LabelCells | None = None) -> dict:
    """label -> (row slice, column slice) of its bounding box: each label's first and last cell (raster
    order) its first and last row, a reduceat its columns."""
    cells = label_cells(labels) if cells is None else cells
    if cells.index.size == 0:
        return {}
    rows, cols = np.divmod(cells.index, labels.shape[1])
    c0, c1 = np.minimum.reduceat(cols, cells.starts), np.maximum.reduceat(cols, cells.starts)
    return {int(label): (slice(int(rows[a]), int(rows[b - 1]) + 1), slice(int(lo), int(hi) + 1))
            for label, a, b, lo, hi in zip(cells.labels, cells.starts, cells.ends, c0, c1)}


@dataclass(frozen=True)
class TabletopPlan:
    grasps: list                 # TabletopGrasp, best first
    quality_grid: np.ndarray     # the network's quality map over the height map
    # label -> why the search found no grasp on it (REJECTIONS: the furthest test its peaks reached), for the
    # objects it tried without success (a search that found top_k grasps early does not try the rest).
    rejected: dict = field(default_factory=dict)

    def rejection_summary(self) -> str:
        """'object 1: too low, object 3: width' (empty when nothing was rejected)."""
        return ", ".join(f"object {label}: {why}" for label, why in sorted(self.rejected.items()))

    def quality_image(self, view: TabletopView) -> np.ndarray:
        """The quality map seen from the camera (depth-sized, 0 off the objects' cells)."""
        out = np.zeros(view.pixel_cell.shape, np.float32)
        on = view.pixel_cell >= 0
        out[on] = self.quality_grid.reshape(-1)[view.pixel_cell[on]]
        return out


def plan_tabletop_grasps(view: TabletopView, predictor, youngs_modulus_pa=None, top_k: int = 1,
                         default_pa: float = 2e6) -> list:
    """Up to top_k feasible grasps, one per object first (module docstring); [] when none is feasible."""
    return plan_tabletop(view, predictor, youngs_modulus_pa, top_k, default_pa).grasps


def plan_tabletop(view: TabletopView, predictor, youngs_modulus_pa=None, top_k: int = 1,
                  default_pa: float = 2e6, targets=None) -> TabletopPlan:
    """plan_tabletop_grasps with the quality map (for display). targets: the object labels to grasp
    (None = all); the others are still obstacles. The same as search_tabletop(prepare_tabletop(...))."""
    return search_tabletop(prepare_tabletop(view, predictor, youngs_modulus_pa, default_pa), top_k, targets)


@dataclass(frozen=True)
class TabletopNetworkView:
    """What planning needs from one view that does not depend on the request (prepare_tabletop): the
    network's maps over the height map, each object's box and best quality, the moduli per cell and
    the free space. Read-only once made: several searches (any top_k, targets) may share it."""
    view: TabletopView
    maps: object                 # grasping.postprocess.GraspMaps over the height map
    moduli: np.ndarray           # R x C Young's modulus per cell (grid_moduli)
    boxes: dict                  # label -> (row slice, column slice) in the height map
    best_q: dict                 # label -> the object's best unclipped quality on its own cells (orders the objects)
    space: FreeSpace | None
    min_distance_px: int
    q_threshold: float
    partly_seen: frozenset = frozenset()   # objects cut by the image border or the left band (perception)
    # (label, (row, col)) -> the peak's grasp or None: a peak's feasibility does not depend on the search
    # (top_k, targets), so a frame's searches share it (the worker's top_k 1 and a client's top_k 5).
    peak_grasps: dict = field(default_factory=dict, compare=False, repr=False)


def prepare_tabletop(view: TabletopView, predictor, youngs_modulus_pa=None, default_pa: float = 2e6,
                     checkpoint=None) -> TabletopNetworkView:
    """The request-independent part of plan_tabletop: moduli per cell, the network on the height map, the
    free space. checkpoint: called between stages (perception on arrival pauses there while a request runs)."""
    d, threshold = predictor.postprocess.peak_min_distance_px, predictor.postprocess.q_threshold
    if not view.object_ids:
        return TabletopNetworkView(view, None, np.zeros(view.grid_height_m.shape, np.float32), {}, {}, None,
                                   d, threshold)
    cells = label_cells(view.grid_labels)
    boxes = label_boxes(view.grid_labels, cells)
    moduli = grid_moduli(view, youngs_modulus_pa, default_pa, cells)
    x = network_input(virtual_depth(view), moduli, predictor.uses_stiffness)
    raw = predictor.raw_maps(x)        # torch releases the interpreter here: no checkpoint before it
    if checkpoint is not None:
        checkpoint()
    maps = maps_from_network(raw, predictor.postprocess)
    best_q = {label: float(maps.q_unclipped[boxes[label]][view.grid_labels[boxes[label]] == label].max())
              for label in view.object_ids if label in boxes}
    return TabletopNetworkView(view, maps, moduli, boxes, best_q, FreeSpace(view), d, threshold,
                               frozenset(partly_seen_objects(view)))


def search_tabletop(prepared: TabletopNetworkView, top_k: int = 1, targets=None) -> TabletopPlan:
    """The request's part of plan_tabletop: each object's feasible grasps, objects in quality order, those
    seen whole before those cut by the image's edge (prepared.partly_seen)."""
    view, maps = prepared.view, prepared.maps
    if maps is None:
        return TabletopPlan([], np.zeros(view.grid_height_m.shape, np.float32))
    labels = view.object_ids if targets is None else [t for t in view.object_ids if t in targets]
    labels = [label for label in labels if label in prepared.boxes]
    rejected = {}
    whole = _grasps_by_object(prepared, [lab for lab in labels if lab not in prepared.partly_seen], top_k, rejected)
    cut = _grasps_by_object(prepared, [lab for lab in labels if lab in prepared.partly_seen], top_k - len(whole),
                            rejected) if len(whole) < top_k else {}
    ranked = []
    for group in (whole, cut):
        ranked += sorted((g[0] for g in group.values()), key=lambda g: -g.rank_quality)
    for group in (whole, cut):
        ranked += sorted((g for gs in group.values() for g in gs[1:]), key=lambda g: -g.rank_quality)
    return TabletopPlan(ranked[:top_k], maps.q, rejected)


def _grasps_by_object(prepared: TabletopNetworkView, labels, top_k: int, rejected: dict) -> dict:
    """label -> its feasible grasps (best first) for the objects a search for top_k grasps needs; rejected
    gets label -> why for those tried without a grasp."""
    best_q = prepared.best_q
    per_object = {}
    # Objects in the order of their best quality: a grasp on an object never scores above its best
    # peak, so once top_k objects have a grasp better than the next object's best peak, stop (both on the
    # quality before its clip: on the clipped one a grasp at 1.0 never beat a best peak above 1).
    for label in sorted(labels, key=lambda lab: -best_q[lab]):
        firsts = sorted((g[0].rank_quality for g in per_object.values()), reverse=True)
        if len(firsts) >= top_k and firsts[top_k - 1] >= best_q[label]:
            break
        found = _object_grasps(prepared, label, top_k)
        if isinstance(found, str):
            rejected[label] = found
        else:
            per_object[label] = found
    return per_object


def _object_grasps(prepared: TabletopNetworkView, label: int, top_k: int) -> list:
    """An object's feasible grasps, best first: its quality peaks in order, the first feasible one,
    then (for top_k > 1) distinct alternatives; or why none is feasible (REJECTIONS)."""
    view, maps, box = prepared.view, prepared.maps, prepared.boxes[label]
    peaks = find_peaks(maps.q_unclipped[box], prepared.min_distance_px, prepared.q_threshold,
                       view.grid_labels[box] == label, top_k=max(PEAKS_PER_OBJECT, top_k), fill=True)
    cells = [(r + box[0].start, c + box[1].start) for r, c in peaks]
    memo = prepared.peak_grasps
    todo = [cell for cell in cells if (label, cell) not in memo]
    if todo:
        # Every new peak's centre lines in one free-space pass, their feasibility in one more: a wide
        # object's peaks all end there, and the per-call overhead, not the arithmetic, is what costs.
        at = [maps.at_pixel(row, col) for row, col in todo]
        probes = _centre_lines(view, prepared.space, todo, [angle for angle, _ in at],
                               object_face_angles(view, label, box))
        reasons = []
        grasps = _feasible_at_peaks(view, label, todo, probes, [width_px * CELL_M for _, width_px in at],
                                    [(float(maps.q[row, col]), float(maps.q_unclipped[row, col])) for row, col in todo],
                                    prepared.moduli, prepared.space, reasons)
        # A peak's memo entry: its grasp, or why it has none.
        memo.update(((label, cell), grasp if grasp is not None else why)
                    for cell, grasp, why in zip(todo, grasps, reasons))
    found = []
    for cell in cells:
        grasp = memo[(label, cell)]
        if isinstance(grasp, TabletopGrasp) and all(_distinct(grasp, other) for other in found):
            found.append(grasp)
            if len(found) >= top_k:
                break
    if not found:
        return max((memo[(label, cell)] for cell in cells), key=REJECTIONS.index, default=NO_PEAK)
    return sorted(found, key=lambda g: -g.rank_quality)


def _distinct(a: TabletopGrasp, b: TabletopGrasp) -> bool:
    """Two grasps of one object are alternatives when their centres or closing directions differ
    (peaks on one chord slide to the same middle)."""
    apart = max(abs(a.cell_rc[0] - b.cell_rc[0]), abs(a.cell_rc[1] - b.cell_rc[1])) >= DISTINCT_CELLS
    cos = abs(float(np.dot(a.closing_direction_base, b.closing_direction_base)))
    return apart or cos < math.cos(math.radians(DISTINCT_ANGLE_DEG))


def _tip_height_m(surface_height_m: float, config=None) -> float:
    """The fingertips' height above the table for a grasp on a surface this high, by the executor's
    grasp_height_rule (TabletopConfig: half_height, or below_surface by grasp_depth_below_surface_m; both with
    the TCP at least MIN_TCP_HEIGHT_ABOVE_TABLE_M up, as control/pick_place.py does)."""
    if config is not None and config.grasp_height_rule == "below_surface":
        tcp = max(surface_height_m - config.grasp_depth_below_surface_m, MIN_TCP_HEIGHT_ABOVE_TABLE_M)
    else:
        tcp = tcp_height_m(surface_height_m, 0.0)
    return tcp - PANDA_FINGERTIP_BELOW_TCP_M


class FreeSpace:
    """Is a point of the robot frame seen to be empty? Its camera ray must reach a surface behind it
    (space carving): a point the camera cannot see (behind an object, off the image, no return) is
    not free. Read on the depth as perception read it (every stride-th pixel, holes filled: fill_holes;
    a 1280x720 frame at 640x360, ~1.6 mm per pixel at 0.5 m). For an object's
    extent each pixel reads as the farthest of its 3x3 neighbourhood (lenient: mixed, flying pixels at
    the edge are not surface, the outline is found to a pixel at every resolution; the clearance
    covers that pixel); for the finger pads as the nearest (strict: a pad touching an edge is blocked)."""

    def __init__(self, view: TabletopView):
        if view.filled_depth_m is not None:
            depth, self.k = view.filled_depth_m, view.filled_k
        else:
            depth, self.k = fill_holes(view.depth_m), view.camera_k
        depth = np.asarray(depth, np.float32)
        # The noise allowance baked into the depth (a point is free when its ray's surface minus three sigma of
        # the camera's noise lies CARVING_TOLERANCE_M behind it); where perception read the table, the plane's
        # own depth without noise: the table is never an obstacle (the descent stops above it), so its noise
        # must not block the pads of a low object's grasp (issue 47: 6.7 mm at 0.72 m with a D435).
        sensor_fx = float(view.camera_k[0, 0])   # the noise is the sensor's, not the read stride's
        if MEDIAN_WINDOW_PX > 1:
            # The median of a window: the surface with its i.i.d. noise mostly gone (MEDIAN_NOISE_SHARE is left)
            # and its edges where they were (a shift of at most half the window).
            finite = np.isfinite(depth)
            median = cv2.medianBlur(np.where(finite, depth, 0).astype(np.float32), MEDIAN_WINDOW_PX)
            depth = np.where(finite & (median > 0), median, depth)
        depth = depth - 3.0 * MEDIAN_NOISE_SHARE * view.depth_noise.sigma_m(depth, sensor_fx).astype(np.float32)
        if view.processed_table_depth_m is not None and view.processed_table_depth_m.shape == depth.shape:
            table = np.isfinite(view.processed_table_depth_m)
            depth[table] = view.processed_table_depth_m[table]
        finite = np.isfinite(depth)
        kernel = np.ones((3, 3), np.uint8)
        if finite.all():     # the usual case after fill_holes (only a row without any return stays NaN)
            self.depth, self.strict_depth = cv2.dilate(depth, kernel), cv2.erode(depth, kernel)
        else:
            self.depth = np.where(finite, cv2.dilate(np.where(finite, depth, 0), kernel), 0.0)
            self.strict_depth = np.where(finite, cv2.erode(np.where(finite, depth, np.inf), kernel), 0.0)
        camera_T_base = np.linalg.inv(view.base_T_camera)
        self.rotation, self.translation = camera_T_base[:3, :3], camera_T_base[:3, 3]

    def free(self, points_base: np.ndarray, strict: bool = False) -> np.ndarray:
        depth = self.strict_depth if strict else self.depth
        x, y, z = (_rotate_row(points_base, self.rotation[i]) + self.translation[i] for i in range(3))
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.rint(self.k[0, 0] * x / z + self.k[0, 2]).astype(np.int64)
            v = np.rint(self.k[1, 1] * y / z + self.k[1, 2]).astype(np.int64)
        h, w = depth.shape
        seen = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        # Every point reads a pixel (clipped into the image: no boolean gathers); unseen ones are masked.
        np.clip(u, 0, w - 1, out=u)
        np.clip(v, 0, h - 1, out=v)
        v *= w
        v += u
        observed = depth.reshape(-1).take(v)
        return seen & (observed > z + CARVING_TOLERANCE_M)


def _rotate_row(points: np.ndarray, row: np.ndarray) -> np.ndarray:
    """points (N x 3) . row, written out: N x 3 @ 3 x 3 goes to multi-threaded BLAS, slow on busy cores."""
    return points[:, 0] * row[0] + points[:, 1] * row[1] + points[:, 2] * row[2]


def object_face_angles(view: TabletopView, label: int, box=None) -> tuple:
    """The two closing directions across an object's faces (map angles, from columns towards rows):
    the axes of its cells' minimum-area rectangle. Pads meeting a face squarely hold; the network's
    regressed angle is noise on square tops (the two right directions average out)."""
    box = box or (slice(None), slice(None))
    mine = view.grid_labels[box] == label
    if np.count_nonzero(mine) < 5:
        return ()
    # Each row's first and last cell: every other cell lies between them, so the hull (all that the
    # rectangle depends on) is the same, from ~2 sqrt(n) points instead of n.
    rows = np.flatnonzero(mine.any(axis=1))
    first = np.argmax(mine[rows], axis=1)
    last = mine.shape[1] - 1 - np.argmax(mine[rows, ::-1], axis=1)
    outline = np.stack([np.concatenate([first, last]), np.concatenate([rows, rows])], axis=1)
    (_, _), (_, _), degrees = cv2.minAreaRect(outline.astype(np.float32))
    a = math.radians(degrees)
    return (a, a + math.pi / 2)


def candidate_angles(angle_rad: float, face_angles=()) -> np.ndarray:
    """Closing directions to try, in order: the faces' normals nearest the network's angle first, then
    the network's angle and 15 degree steps away from it."""
    def off(a):
        d = (a - angle_rad) % math.pi
        return min(d, math.pi - d)
    faces = sorted(face_angles, key=off)
    steps = sorted(range(ANGLE_STEPS), key=lambda k: min(k, ANGLE_STEPS - k))
    return np.array(list(faces) + [angle_rad + k * math.pi / ANGLE_STEPS for k in steps])


def feasible_grasp(view: TabletopView, label: int, row: int, col: int, angle_rad: float, network_width_m: float,
                   quality: float, moduli: np.ndarray, space: FreeSpace, face_angles=(),
                   rank_quality: float | None = None) -> TabletopGrasp | None:
    """The grasp at cell (row, col) with the first feasible closing direction of candidate_angles
    (map angles: from columns towards rows), or None when no direction is feasible. rank_quality: the
    quality before its clip (default: quality)."""
    probes = _centre_lines(view, space, [(row, col)], [angle_rad], face_angles)
    qualities = [(quality, quality if rank_quality is None else rank_quality)]
    return _feasible_at_peaks(view, label, [(row, col)], probes, [network_width_m], qualities, moduli, space)[0]


# Samples along a closing line, in cells from the centre: a run longer than the widest fitting extent
# is not needed to the end, so they reach that far each side.
_REACH = int(math.ceil((GRIPPER_MAX_WIDTH_M - 2 * CLEARANCE_M) / CELL_M / LINE_STEP_CELLS)) + 2
_STEPS = np.arange(-_REACH, _REACH + 1) * LINE_STEP_CELLS


def _centre_lines(view: TabletopView, space: FreeSpace, cells, angles, face_angles) -> list:
    """Per grasp centre (row, col) with the network's angle there: (fingertip level, closing
    directions (A x 2, candidate_angles order), free samples along each direction's centre line
    (A x S)), all centres' samples in one free-space pass."""
    levels = [_tip_height_m(float(view.grid_height_m[r, c]), view.config) + TIP_MARGIN_M for r, c in cells]
    directions = np.stack([np.stack([np.sin(phis), np.cos(phis)], axis=1)        # (row, col) per cell step
                           for phis in (candidate_angles(a, face_angles) for a in angles)])
    centres = np.asarray(cells, float)
    lines = centres[:, None, None, :] + _STEPS[None, None, :, None] * directions[:, :, None, :]   # P x A x S x 2
    heights = np.repeat(np.asarray(levels, float), lines[0, ..., 0].size)
    free = space.free(_points(view, lines.reshape(-1, 2), heights)).reshape(lines.shape[:3])
    return [(level, d, f) for level, d, f in zip(levels, directions, free)]


def _feasible_at_peaks(view, label, cells, probes, network_widths_m, qualities, moduli, space, reasons=None) -> list:
    """feasible_grasp at each peak (cells: (row, col) each, probes: their _centre_lines, qualities: (clipped,
    before the clip) each), all peaks in one pass: per peak its grasp or None. reasons: a list that gets, per
    peak, the last test its best direction failed (REJECTIONS; None for a grasp)."""
    levels = np.array([probe[0] for probe in probes])
    directions = np.stack([probe[1] for probe in probes])                # P x A x 2
    n_peaks, n_dirs = directions.shape[:2]
    steps = _STEPS
    centres = np.asarray(cells, float)                                   # P x 2
    # Three lines across the band the pads sweep (centre and both pad edges): what lies between the
    # fingers anywhere in that band must fit, so a box's corner is not taken for a narrow object. The
    # centre line first for every direction; the edge lines only where the centre line's run fits.
    free_centre = np.stack([probe[2] for probe in probes]).reshape(n_peaks * n_dirs, 1, steps.size)
    ok0, low0, high0 = band_extents(~free_centre)
    fits0 = ok0 & ((high0 - low0 + 1) * LINE_STEP_CELLS * CELL_M + 2 * CLEARANCE_M <= GRIPPER_MAX_WIDTH_M)
    result = [None] * n_peaks
    # Why a peak fails, from the first test on: nothing at the fingertips' level under the centre in any
    # direction (the object is lower than the fingertips reach), then wider than the hand.
    centre_occupied = (~free_centre[:, 0, steps.size // 2]).reshape(n_peaks, n_dirs).any(axis=1)
    why = [TOO_LOW if not occupied else WIDTH for occupied in centre_occupied]
    if reasons is not None:
        reasons[:] = why
    if not fits0.any():      # no centre line fits: nothing below can (ok &= fits0)
        return result
    flat_dirs = directions.reshape(-1, 2)
    across = np.stack([-flat_dirs[:, 1], flat_dirs[:, 0]], axis=1)
    offsets = np.array([-0.5, 0.5]) * FINGER_PAD_WIDTH_M / CELL_M
    peak_of = np.repeat(np.arange(n_peaks), n_dirs)                    # P*A: each direction's peak
    free = np.ones((n_peaks * n_dirs, 3, steps.size), bool)
    free[:, 0] = free_centre[:, 0]
    idx = np.flatnonzero(fits0)
    edges = (centres[peak_of[idx], None, None, :] + offsets[None, :, None, None] * across[idx, None, None, :]
             + steps[None, None, :, None] * flat_dirs[idx, None, None, :])        # a x 2 x S x 2
    heights = np.repeat(levels[peak_of[idx]], 2 * steps.size)
    free[idx, 1:] = space.free(_points(view, edges.reshape(-1, 2), heights)).reshape(idx.size, 2, steps.size)
    ok, lows, highs = band_extents(~free)
    extents = (highs - lows + 1) * LINE_STEP_CELLS * CELL_M
    ok &= fits0 & (extents + 2 * CLEARANCE_M <= GRIPPER_MAX_WIDTH_M)
    # Per peak: the narrowest fitting direction first (the most room in the hand, and the same choice at
    # every resolution); among near-equal ones, the candidate order (faces, then the network's angle). The
    # first whose middle is on the object and whose pads are free wins (all checked in one pass).
    cand = np.flatnonzero(ok)
    if cand.size == 0:
        return result
    for p in np.unique(peak_of[cand]):
        why[p] = COLLISION          # fits the hand: from here a pad on something, or the middle off the object
    direction_index = cand % n_dirs
    cand = cand[np.lexsort((direction_index, np.rint(extents[cand] / OPENING_TIE_M), peak_of[cand]))]
    widths = extents[cand] + 2 * CLEARANCE_M           # geometric: the same object, the same opening
    mid = centres[peak_of[cand]] + ((lows[cand] + highs[cand]) / 2.0 * LINE_STEP_CELLS)[:, None] * flat_dirs[cand]
    rc = np.rint(mid).astype(np.int64)
    rows_n, cols_n = view.grid_labels.shape
    on = (rc[:, 0] >= 0) & (rc[:, 0] < rows_n) & (rc[:, 1] >= 0) & (rc[:, 1] < cols_n)
    on[on] = view.grid_labels[rc[on, 0], rc[on, 1]] == label
    if on.any():
        pre_open = np.array([pre_grasp_opening_m(w) for w in widths[on]])
        on[on] = _pads_free(view, space, levels[peak_of[cand[on]]], mid[on], flat_dirs[cand[on]], widths[on],
                            pre_open)
    for k in np.flatnonzero(on):
        p = int(peak_of[cand[k]])
        if result[p] is None:
            r, c = int(rc[k, 0]), int(rc[k, 1])
            grasp = _grasp(view, label, qualities[p], r, c, flat_dirs[cand[k]], float(widths[k]),
                           float(extents[cand[k]]), network_widths_m[p], float(moduli[r, c]))
            outside = _out_of_workspace_or_reach(view, grasp)
            if outside is None:
                result[p] = grasp
            elif REJECTIONS.index(outside) > REJECTIONS.index(why[p]):
                why[p] = outside
    if reasons is not None:
        reasons[:] = [None if g is not None else w for g, w in zip(result, why)]
    return result


def _out_of_workspace_or_reach(view: TabletopView, grasp: TabletopGrasp):
    """WORKSPACE when the grasp's centre lies outside the view's workspace box, REACH when the arm cannot
    take its top-down TCP pose there (control/kinematics.check_workspace), else None."""
    x, y, z = grasp.position_base_m
    config = view.config
    if config is not None:
        ws = config.workspace
        if not (ws.x_m[0] <= x <= ws.x_m[1] and ws.y_m[0] <= y <= ws.y_m[1]):
            return WORKSPACE
    table_z = float(view.table_z_at(x, y))
    try:
        # Reach and the base's keep-out only: the TCP's height above the table is the height rule's (at its
        # floor it equals check_workspace's minimum, which rounding would then refuse at random).
        check_workspace((x, y, tcp_height_m(z, table_z)), table_z, min_height_m=0.0)
    except WorkspaceError:
        return REACH
    return None


def _points(view: TabletopView, cells_rc: np.ndarray, height_m) -> np.ndarray:
    """Base-frame points at height_m (one, or one per cell) above the table over (fractional) height-map cells."""
    x, y = view.cell_xy_m(cells_rc[:, 0], cells_rc[:, 1])
    return np.stack([x, y, view.table_z_at(x, y) + height_m], axis=1)


def band_extents(occupied: np.ndarray):
    """Per closing direction, (low, high) signed sample steps from the centre (the middle sample) to
    the ends of what lies between the fingers, over the band's lines (A x L x S occupied samples):
    each line's occupied run through the middle (a one-sample gap is bridged: noise); the centre
    line (index 0) must have one, the edge lines add theirs when they have one. A direction is
    unusable (ok False) when the centre is free or a run reaches past the sampled width."""
    a, l, n = occupied.shape
    centre = n // 2
    free = ~occupied
    gap = free & np.concatenate([free[..., 1:], np.ones((a, l, 1), bool)], axis=2)   # two free in a row
    gap_back = free & np.concatenate([np.ones((a, l, 1), bool), free[..., :-1]], axis=2)
    after, before = gap[..., centre:], gap_back[..., :centre + 1][..., ::-1]
    has_after, has_before = after.any(axis=2), before.any(axis=2)
    high = np.argmax(after, axis=2) - 1
    low = -(np.argmax(before, axis=2) - 1)
    through = occupied[..., centre]
    complete = through & has_after & has_before
    ok = complete[:, 0] & np.all(complete | ~through, axis=1)
    low = np.where(through, low, 0).min(axis=1)
    high = np.where(through, high, 0).max(axis=1)
    return ok, low, high


def _extent_cells(occupied: np.ndarray):
    """band_extents for one line: (low, high) or (None, None)."""
    ok, low, high = band_extents(np.asarray(occupied, bool)[None, None, :])
    return (int(low[0]), int(high[0])) if ok[0] else (None, None)


def _pads_free(view, space: FreeSpace, level_m, centres, directions, widths_m, opening_m=0.0) -> np.ndarray:
    """Per grasp (n centres in cells, unit closing directions, openings in m): both pads (thickness
    along the closing line just outside the opening, pad width across it) over free space at the
    fingertips' level (level_m: one for all, or one per grasp; PAD_BLOCKED_FRACTION of a pad's samples
    may fail). opening_m > a grasp's opening: the hand descends opened that wide (the executor's
    pre-grasp opening) and closes to the grasp's opening, so the pads' whole sweep between the two
    must be free too (SWEEP_SAMPLES more positions along the line, checked only where the pads at the
    opening are free: most candidates fail there, and the sweep's samples would double a search); one opening_m
    for all or one per grasp."""
    centres, directions = np.asarray(centres, float), np.asarray(directions, float)
    level_m = np.broadcast_to(np.asarray(level_m, float), (len(centres),))
    opening_m = np.broadcast_to(np.asarray(opening_m, float), (len(centres),))
    half = np.asarray(widths_m, float)[:, None] / 2
    free = _pad_samples_free(view, space, level_m, centres, directions,
                             half + np.linspace(0.0, PANDA_FINGER_THICKNESS_M, PAD_SAMPLES))
    if free.any() and (opening_m[free] > 0.0).any():
        sweep = np.linspace(0.0, 1.0, SWEEP_SAMPLES + 1)[1:] * np.maximum(opening_m[free, None] / 2 - half[free], 0.0)
        free[free] = _pad_samples_free(view, space, level_m[free], centres[free], directions[free],
                                       half[free] + PANDA_FINGER_THICKNESS_M + sweep)
    return free


def _pad_samples_free(view, space: FreeSpace, level_m, centres, directions, along_m) -> np.ndarray:
    """_pads_free's test for pads at the given distances along the closing line (n x K m from each centre),
    PAD_SAMPLES across the pad's width at each."""
    n, n_along = along_m.shape
    across = np.stack([-directions[:, 1], directions[:, 0]], axis=1)
    s_across = np.linspace(-FINGER_PAD_WIDTH_M / 2, FINGER_PAD_WIDTH_M / 2, PAD_SAMPLES) / CELL_M
    # Sample k = (across index) * n_along + (along index), as np.meshgrid(along, across) orders them.
    a = np.broadcast_to(along_m[:, None, :] / CELL_M, (n, PAD_SAMPLES, n_along)).reshape(n, -1, 1)
    b = np.repeat(s_across, n_along)[None, :, None]
    pads = [centres[:, None, :] + side * a * directions[:, None, :] + b * across[:, None, :] for side in (-1.0, 1.0)]
    points = np.stack(pads, axis=1).reshape(-1, 2)                            # n x 2 pads x samples
    free = space.free(_points(view, points, np.repeat(level_m, 2 * PAD_SAMPLES * n_along)), strict=True)
    return np.all(np.mean(~free.reshape(n, 2, -1), axis=2) <= PAD_BLOCKED_FRACTION, axis=1)


def _grasp(view, label, qualities, r, c, direction, width, extent_m, network_width_m, modulus) -> TabletopGrasp:
    """qualities: (the clipped quality it reports, the quality before the clip it is ranked on)."""
    x, y = view.cell_xy_m(r, c)
    z = float(view.table_z_at(x, y)) + float(view.grid_height_m[r, c])
    normal = np.asarray(view.table_normal, float)
    closing = np.array([direction[0], direction[1], 0.0])      # rows = +x, columns = +y
    closing -= normal * (closing @ normal)
    closing /= np.linalg.norm(closing)
    quality, rank_quality = qualities
    tip_m = _tip_height_m(float(view.grid_height_m[r, c]), view.config)
    return TabletopGrasp(object_id=int(label), quality=float(quality), position_base_m=(float(x), float(y), z),
                         closing_direction_base=tuple(closing.tolist()),
                         approach_direction_base=tuple((-normal).tolist()), width_m=float(width),
                         extent_m=float(extent_m), network_width_m=float(network_width_m),
                         youngs_modulus_pa=float(modulus), cell_rc=(int(r), int(c)),
                         rank_quality=float(rank_quality),
                         pad_contacts_source=functools.partial(
                             perceived_pad_contacts, view.grid_height_m, view.grid_labels, label, (r, c),
                             tuple(direction), tip_m, extent_m),
                         section_source=functools.partial(
                             perceived_section, view.grid_height_m, view.grid_labels, label, (r, c),
                             tuple(direction), tip_m, SECTION_CELL_M))


def base_T_grasp(grasp: TabletopGrasp) -> np.ndarray:
    """4x4 grasp pose in the base frame: z = approach (down onto the table), x = closing direction."""
    z = np.asarray(grasp.approach_direction_base)
    x = np.asarray(grasp.closing_direction_base)
    out = np.eye(4)
    out[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    out[:3, 3] = grasp.position_base_m
    return out


def image_projection(grasp: TabletopGrasp, base_T_camera, camera_k) -> dict:
    """Where the grasp appears in the depth image: centre (u, v) px, closing angle from u towards v,
    opening in pixels at the grasp's depth, and the centre in the camera frame (m)."""
    camera_T_base = np.linalg.inv(np.asarray(base_T_camera, float))
    p = np.asarray(grasp.position_base_m)
    ends = [p + s * np.asarray(grasp.closing_direction_base) * grasp.width_m / 2 for s in (-1, 1)]
    cam = [camera_T_base[:3, :3] @ q + camera_T_base[:3, 3] for q in (p, *ends)]
    k = np.asarray(camera_k, float)
    uv = [(k[0, 0] * q[0] / q[2] + k[0, 2], k[1, 1] * q[1] / q[2] + k[1, 2]) for q in cam]
    du, dv = uv[2][0] - uv[1][0], uv[2][1] - uv[1][1]
    angle = math.atan2(dv, du)
    if angle > math.pi / 2:
        angle -= math.pi
    elif angle < -math.pi / 2:
        angle += math.pi
    return {"u_px": float(uv[0][0]), "v_px": float(uv[0][1]), "angle_rad": float(angle),
            "width_px": float(math.hypot(du, dv)), "position_camera_m": tuple(float(c) for c in cam[0])}

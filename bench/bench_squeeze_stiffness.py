"""Stiffness by squeezing in the simulated cell (issue 49 item 4): how close defgg_ros/squeeze.py's modulus
estimate comes to the true Young's modulus of the cell's FEM objects, and how repeatable it is.

  .venv/bin/python bench/bench_squeeze_stiffness.py [--repeats 1 | --yaws 0.3] [--moduli 2e4 2e5 2e6 2e9]
      [--objects tuning | held_out | NAME ...] [--readings FILE.jsonl] [--calibrate]

Jig (not the executor's sequence): the arm is set at a top-down grasp at half the object's height, then the
hand grasps at squeeze.GENTLE_FORCES_N, then at FIRM_FORCES_N while squeeze.needs_firmer says the compression
is not resolved; the opening is read 0.2 s after each grasp stopped. Each repeat turns the object (yaw 0, 0.3,
0.6 rad ...). Objects: the four boxes of the cell's regular FEM grid and library shapes (their shipped tet
meshes, as the cell experiment builds them). Two sets: TUNING (boxes and training primitives: what the model's
choices were made on) and HELD_OUT (evaluation objects: common and EGAD-like, never looked at while choosing).

Every squeeze's readings are appended to --readings (JSON lines) and reused on a rerun: the estimate is pure
arithmetic, so the old model (flat pads, nothing taken out), the hand's calibration with the flat law, the new
(hand calibration, Hertz on the surface's contact radii) and "perceived" (Hertz on the radii the cell perceives
from its own camera's depth: planning/contact_radii.py, what the executor gets on the grasp) and "section" (the
perceived section's plane-stress FEM where a pad is not flat: section_model.py, what the executor now does) are
compared on the same readings. --calibrate squeezes the rigid calibration block and
prints the hand's stiffness (squeeze.calibrate_hand), the value sim_bringup/config/sim_cell.yaml carries.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pybullet as p
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.atomic import atomic_path  # noqa: E402
from defgg_ros.constants import (  # noqa: E402
    FINGER_DEPTH_M,
    FINGER_PAD_WIDTH_M,
    MAX_SOFT_BODY_YOUNGS_MODULUS_PA,
    OBJECT_DENSITY_KG_M3,
    PANDA_FINGERTIP_BELOW_TCP_M,
)
from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.perception.tabletop import CELL_M, TabletopConfig, perceive  # noqa: E402
from defgg_ros.planning.contact_radii import (  # noqa: E402
    PadContacts,
    contact_radius_m,
    perceived_pad_contacts,
    surface_pad_contact,
)
from defgg_ros.planning.section_outline import SECTION_CELL_M, perceived_section  # noqa: E402
from defgg_ros.section_model import SectionError, section_curve  # noqa: E402
from defgg_ros.sim import meshes  # noqa: E402
from defgg_ros.sim import objects as sim_objects  # noqa: E402
from defgg_ros.sim.cell import gripper as cell_gripper  # noqa: E402
from defgg_ros.sim.cell.objects import centred_surface_mesh  # noqa: E402
from defgg_ros.sim.cell.sim_cell import SimCell  # noqa: E402
from defgg_ros.sim.meshes import save_tet_mesh_file  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402
from defgg_ros.squeeze import (  # noqa: E402
    FIRM_FORCES_N,
    GENTLE_FORCES_N,
    MODEL_FACTOR,
    HandCalibration,
    SqueezeError,
    SqueezeReading,
    calibrate_hand,
    estimate_modulus,
    gentle_step_ratios,
    needs_firmer,
    without_settling_step,
)

WIDTH_RESOLUTION_M = 1e-5       # the simulated hand's opening is exact to well below this
# (size along the closing axis, across it, height) m, FEM cell size m
BOXES = {"cube_5cm": ((0.05, 0.05, 0.05), 0.025), "slab_4x6x3": ((0.04, 0.06, 0.03), 0.02),
         "block_6x4.5x4": ((0.06, 0.045, 0.04), 0.03), "thin_3x5x5": ((0.03, 0.05, 0.05), 0.025)}
TUNING = (*BOXES, "sphere", "cylinder_tall", "ellipsoid")
HELD_OUT = ("common_ball", "common_pear", "common_toy_bone", "egad_test_02_c1", "egad_test_05_c2", "egad_test_11_c3",
            "egad_test_00_c1", "egad_test_04_c2")
CALIBRATION_BLOCK = "cube_5cm"      # a steel block's stand-in: the 5 cm cube as a rigid body (2e9 Pa)
CALIBRATION_YAWS_RAD = (0.0, 0.3, 0.6, 0.9)
KIN = PandaKinematics()
MESHES = Path("/tmp/bench_squeeze_meshes")
HAND_DRIVES = ("pressing", "speed-driven")
# Wall time of each section model (section_curve) this run, s: what the executor's squeeze waits on at most.
SECTION_MODEL_S: list = []


# Where a library shape's body comes from: "shipped", its shipped tet mesh as it is (the same body on every machine,
# the labels' discretization; since 2026-11-30), or "fTetWild", its surface re-meshed by fTetWild on this machine
# (not deterministic: the rows stored before 2026-11-30 were squeezed so, each on its own machine's mesh).
MESH_SOURCES = ("shipped", "fTetWild")


def _library_nodes(name: str):
    """The shipped tet mesh's nodes and tets, turned across when longer than the hand opens (the toy bone)."""
    tet = sim_objects.get_shape(name).union_tet
    nodes = tet.nodes_m
    extent = np.ptp(nodes, axis=0)
    if extent[0] > 0.075 > extent[1]:   # closed across it
        nodes = nodes @ trimesh.transformations.rotation_matrix(math.pi / 2, (0, 0, 1))[:3, :3].T
    return nodes, tet.tets


def scene_object(name: str, modulus_pa: float, yaw_rad: float, mesh_source: str = "shipped"):
    """The soft_box scene's object replaced by `name` (a box of BOXES or a library shape: its shipped tet mesh, or
    its surface for fTetWild)."""
    base = load_scene(ROOT / "sim_bringup" / "scenes" / "soft_box.yaml").objects[0]
    if name in BOXES:
        size_m, cell_m = BOXES[name]
        return replace(base, name=name, youngs_modulus_pa=modulus_pa, size_m=tuple(size_m), fem_cell_size_m=cell_m,
                       yaw_rad=yaw_rad, mass_kg=0.05)
    nodes, tets = _library_nodes(name)
    path = MESHES / (f"{name}.npz" if mesh_source == "shipped" else f"{name}.obj")
    if not path.exists():
        MESHES.mkdir(parents=True, exist_ok=True)
        if mesh_source == "shipped":
            save_tet_mesh_file(path, nodes, tets)
        else:
            surface = meshes.tet_mesh_of(nodes, tets, f"bench-{name}").surface()
            with atomic_path(path) as tmp:
                surface.export(tmp, file_type="obj")
    mass_kg = round(float(abs(meshes.tet_volumes(nodes, tets).sum())) * OBJECT_DENSITY_KG_M3, 4)
    return replace(base, name=name, shape="mesh", mesh_path=str(path), size_m=(1.0, 1.0, 1.0), yaw_rad=yaw_rad,
                   youngs_modulus_pa=modulus_pa, mass_kg=mass_kg)


def face_m(spec) -> tuple[float, float]:
    """The object's extent across the closing axis and its height (what the depth image gives)."""
    if spec.shape == "box":
        return spec.size_m[1], spec.size_m[2]
    lo, hi = centred_surface_mesh(spec).bounds
    return float(hi[1] - lo[1]), float(hi[2] - lo[2])


def closing_extent_m(spec) -> float:
    """The object's extent along the closing axis (its size along x before the yaw)."""
    if spec.shape == "box":
        return spec.size_m[0]
    lo, hi = centred_surface_mesh(spec).bounds
    return float(hi[0] - lo[0])


def surface_x_along_closing(triangles, ys, zs):
    """x of every crossing of the lines (y, z) along the closing axis with the triangles: (points, triangles), nan
    where a line misses a triangle (barycentric test in the y-z plane)."""
    a, b, c = (triangles[None, :, i, :] for i in range(3))
    q = np.stack([ys, zs], axis=1)[:, None, :]
    v0, v1, v2 = (b - a)[..., 1:], (c - a)[..., 1:], q - a[..., 1:]
    det = v0[..., 0] * v1[..., 1] - v0[..., 1] * v1[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):    # triangles edge-on to the closing axis: det 0
        u = (v2[..., 0] * v1[..., 1] - v2[..., 1] * v1[..., 0]) / det
        v = (v0[..., 0] * v2[..., 1] - v0[..., 1] * v2[..., 0]) / det
        inside = (u >= 0) & (v >= 0) & (u + v <= 1) & (np.abs(det) > 1e-14)
        x = a[..., 0] + u * (b - a)[..., 0] + v * (c - a)[..., 0]
    return np.where(inside, x, np.nan)


def surface_contacts(spec) -> PadContacts:
    """The surface's radius of curvature (and line length, where it is straight one way) where each pad touches it
    (empty: flat faces under both pads).

    From the true surface: rays along the closing axis over the pad's footprint (at half the height) find the
    surface's reach; planning/contact_radii.surface_pad_contact fits its recession d = (y-y*)^2 / (2 R_h) +
    (z-z*)^2 / (2 R_v); a point contact's radius is sqrt(R_h R_v), a line contact's the curved way's, each at most
    half the object's width. Pad on the -x side (the -closing side) first, as Grasp.contact_radii_m."""
    if spec.shape == "box":
        return PadContacts()
    surface = centred_surface_mesh(spec)
    half_width = float(surface.bounds[1][0] - surface.bounds[0][0]) / 2
    ys, zs = np.meshgrid(np.linspace(-FINGER_PAD_WIDTH_M / 2, FINGER_PAD_WIDTH_M / 2, 9),
                         np.linspace(-FINGER_DEPTH_M / 2, FINGER_DEPTH_M / 2, 9))
    hits_x = surface_x_along_closing(surface.triangles, ys.ravel(), zs.ravel())
    pads = []
    for side in (-1.0, 1.0):
        reach = np.max(side * hits_x, axis=1, initial=-np.inf, where=np.isfinite(hits_x))
        pads.append(surface_pad_contact(ys, zs, np.where(np.isfinite(reach), reach, np.nan), half_width))
    if all(flat for _, _, flat in pads):
        return PadContacts()
    lines = tuple(line for _, line, _ in pads)
    return PadContacts(tuple(r for r, _, _ in pads), lines if any(lines) else ())


# How far from the object's position its label is looked for: a ring's position is its hole.
LABEL_SEARCH_M = 0.03


def object_label_near(grid_labels: np.ndarray, centre_rc) -> int:
    """The object label at centre_rc, else the most frequent one within LABEL_SEARCH_M of it (0: none)."""
    row, col = (int(round(v)) for v in centre_rc)
    if grid_labels[row, col]:
        return int(grid_labels[row, col])
    reach = int(math.ceil(LABEL_SEARCH_M / CELL_M))
    rows, cols = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    near = (rows ** 2 + cols ** 2) * CELL_M ** 2 <= LABEL_SEARCH_M ** 2
    window = grid_labels[max(row - reach, 0):row + reach + 1, max(col - reach, 0):col + reach + 1]
    mask = near[:window.shape[0], :window.shape[1]] if row >= reach and col >= reach else np.ones(window.shape, bool)
    labels = window[mask & (window > 0)]
    return int(np.bincount(labels).argmax()) if labels.size else 0


def perceived_contacts(spec) -> tuple[PadContacts, tuple, object]:
    """The contacts the cell perceives (empty: flat faces, the flat law), the point-law radii the executor used
    before line contacts (sqrt(R_h R_v) at every pad) and the section law's curve (None: no section under the
    pads): the object rendered by the cell's own camera
    (SimCell.render_depth, the scene's camera 0.40 m above the table), perceived as the segmentation node does
    (perception/tabletop.perceive), and the jig's grasp (the object's position, closing along its yaw, the
    fingertips at half its height less their offset below the TCP) given to planning/contact_radii: what the
    planner puts on TabletopGrasp. Pad on the -closing side first."""
    scene = load_scene(ROOT / "sim_bringup" / "scenes" / "soft_box.yaml")
    cell = SimCell(replace(scene, objects=[spec]))
    try:
        position, _ = cell.object_poses()[0]
        depth_m, _, _ = cell.render_depth()
        camera_k = cell.camera_k
    finally:
        cell.close()
    base_T_camera = np.eye(4)
    base_T_camera[:3, :3] = np.reshape(p.getMatrixFromQuaternion(scene.base_quat_camera_xyzw), (3, 3))
    base_T_camera[:3, 3] = scene.base_xyz_camera_m
    view = perceive(depth_m, camera_k, base_T_camera, TabletopConfig())
    centre = ((position[0] - view.grid_origin_xy_m[0]) / CELL_M, (position[1] - view.grid_origin_xy_m[1]) / CELL_M)
    label = object_label_near(view.grid_labels, centre)
    if label == 0:
        raise SystemExit(f"{spec.name}: perception found no object within {LABEL_SEARCH_M * 100:.0f} cm of its "
                         "position")
    tip_m = face_m(spec)[1] / 2 - PANDA_FINGERTIP_BELOW_TCP_M
    details = {}
    row, col = (int(round(v)) for v in centre)
    # A grasp centred on a hole (a ring): the outline is searched from the extent's ends, as the planner does.
    extent_m = None if view.grid_labels[row, col] == label else closing_extent_m(spec)
    direction = (math.cos(spec.yaw_rad), math.sin(spec.yaw_rad))
    contacts = perceived_pad_contacts(view.grid_height_m, view.grid_labels, label, centre, direction, tip_m,
                                      extent_m, details=details)
    mask, heights = perceived_section(view.grid_height_m, view.grid_labels, label, centre, direction, tip_m)
    started = time.perf_counter()
    try:
        curve = section_curve(mask, heights, SECTION_CELL_M)
    except SectionError:
        curve = None
    SECTION_MODEL_S.append(time.perf_counter() - started)
    if not details.get("pads"):
        return contacts, (), curve
    point_radii = tuple(contact_radius_m(r_h, r_v, details["half_width_m"]) for r_h, r_v, _ in details["pads"])
    return contacts, (point_radii if contacts.radii_m else ()), curve


@contextlib.contextmanager
def jig(spec):
    """The jig: a cell with `spec` alone, the arm set at a top-down grasp at half its height (closed after use)."""
    scene = load_scene(ROOT / "sim_bringup" / "scenes" / "soft_box.yaml")
    cell = SimCell(replace(scene, objects=[spec]))
    try:
        position, _ = cell.object_poses()[0]
        ik, _ = KIN.top_down_ik((position[0], position[1], face_m(spec)[1] / 2), spec.yaw_rad)
        for joint, q in zip(cell.arm_joints, ik.q_rad):
            p.resetJointState(cell.robot, joint, q, 0.0, physicsClientId=cell.client)
        cell.tracker = type(cell.tracker)(np.asarray(ik.q_rad))
        cell.advance(0.3)
        yield cell
    finally:
        cell.close()


def squeeze_sequence(cell) -> list:
    """The readings of one squeeze in a jig's cell (gentle forces, then firm ones while unresolved)."""
    readings = []
    for force in GENTLE_FORCES_N + FIRM_FORCES_N:
        if force in FIRM_FORCES_N and not needs_firmer(readings, WIDTH_RESOLUTION_M):
            break   # resolved at gentle forces: no need to squeeze harder
        cell.gripper_grasp(0.0, 0.08, 0.08, 0.02, force)
        for _ in range(500):
            if cell.advance(0.01):
                break
        cell.advance(0.2)
        readings.append(SqueezeReading(force, cell.gripper_width_m()))
    return readings


def squeeze_once(spec) -> list:
    """The readings of one squeeze of `spec` in a fresh jig."""
    with jig(spec) as cell:
        return squeeze_sequence(cell)


def row_mesh(row: dict) -> str:
    """A stored row's mesh source: rows without one were squeezed before 2026-11-30 on fTetWild meshes."""
    return row.get("mesh", "fTetWild")


def row_hand(row: dict) -> str:
    """A stored FEM row's hand drive (HAND_DRIVES): rows without one were squeezed by the speed-driven hand."""
    return row.get("hand", "speed-driven")


@contextlib.contextmanager
def hand_drive(drive: str):
    """The simulated hand as `drive`: "pressing" (the cell's: force control on the object) or "speed-driven" (the
    cell's before 2026-11-30: an FEM body was pressed with ~2 N at 0.02 m/s whatever the force; docs/real_cell.md,
    "Grasp force on FEM objects"), for the squeezes made inside."""
    original = cell_gripper.GripperController._check_contact
    if drive == "speed-driven":
        cell_gripper.GripperController._check_contact = lambda self, now_s, width_m: None
    try:
        yield
    finally:
        cell_gripper.GripperController._check_contact = original


def cached_readings(path: Path, name: str, modulus_pa: float, yaw_rad: float, mesh_source: str = "shipped",
                    drive: str = "pressing") -> list:
    """The readings of (name, modulus, yaw) on that mesh source and, for an FEM body, that hand drive from the file,
    else squeezed now and appended. The boxes (the cell's regular grid) are the same on every machine: any row
    serves; a rigid body is pressed with the force by either drive: any row serves."""
    key = {"object": name, "modulus_pa": modulus_pa, "yaw_rad": round(yaw_rad, 3)}
    if name not in BOXES:
        key["mesh"] = mesh_source
    if modulus_pa <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA:     # an FEM body
        key["hand"] = drive
    defaulted = {"mesh": row_mesh, "hand": row_hand}     # fields older rows lack
    if path.exists():
        for line in path.read_text().splitlines():
            row = json.loads(line)
            if all((defaulted[k](row) if k in defaulted else row.get(k)) == v for k, v in key.items()):
                return [SqueezeReading(f, w) for f, w in zip(row["forces_n"], row["widths_m"])]
    with hand_drive(drive):
        readings = squeeze_once(scene_object(name, modulus_pa, yaw_rad, mesh_source))
    with open(path, "a") as out:
        out.write(json.dumps({**key, "forces_n": [r.force_n for r in readings],
                              "widths_m": [r.width_m for r in readings]}) + "\n")
    return readings


def calibration(path: Path) -> HandCalibration:
    """The hand's stiffness from squeezes of the rigid calibration block at a few yaws."""
    squeezes = [cached_readings(path, CALIBRATION_BLOCK, 2e9, yaw) for yaw in CALIBRATION_YAWS_RAD]
    return calibrate_hand(squeezes, f"bench_squeeze_stiffness.py --calibrate: rigid {CALIBRATION_BLOCK} "
                          f"(PyBullet rigid body) at yaws {list(CALIBRATION_YAWS_RAD)} rad")


# The estimates compared on the same readings: the old model (flat pads, nothing taken out), the hand's calibration
# taken out with the flat law (what the executor did without contact radii), "point": the calibration and the
# perceived radii with the point law at every pad (what the executor did before line contacts), "new": the
# calibration and the contacts of the object's surface (line law where it is straight one way), and "perceived":
# the calibration and the contacts the cell perceives (the contact laws: what the executor does with a grasp
# that has no section), "section": the calibration and the perceived section's plane-stress FEM (section_model.py;
# docs/squeeze.md) where a pad touches along a line, the point law at two point contacts (the section law read the
# training sphere and ellipsoid lower as E grew), the flat law where both pads are flat on a body that fills the
# flat law's prism (the training boxes read 2-8x with the FEM: the cell's boxes are FEM grids of 2-3 cm cells,
# stiffer than a continuum), the section law on flat pads otherwise (the training star prism egad_train_08_c5
# met on faces): what the executor does (squeeze.estimate_modulus; the grasp carries its section since 2026-11-30).
VARIANTS = ("old", "hand", "point", "new", "perceived", "section")
BANDED = ("perceived", "section")     # the variants whose one-sigma band and log error are printed


def contacts_of(spec) -> dict:
    """What estimates_of reads of an object: "surface" and "perceived" PadContacts, the perceived "point"-law radii
    and the "section"'s curve (perceived_contacts)."""
    perceived, point, section = perceived_contacts(spec)
    return {"surface": surface_contacts(spec), "perceived": perceived, "point": point, "section": section}


def estimates_of(readings, spec, hand: HandCalibration, contacts: dict, section_on_flat_pads: bool = False) -> dict:
    """Each variant's estimate of one squeeze (SqueezeError: the executor refuses such readings). contacts:
    "surface" and "perceived" PadContacts, "point": the perceived point-law radii, "section": the section's curve.
    section_on_flat_pads: the section law on flat pads too (what chose the flat law there: docs/squeeze.md)."""
    face_w, face_h = face_m(spec)
    kw = {"width_resolution_m": WIDTH_RESOLUTION_M}

    def with_contacts(pads: PadContacts):
        return estimate_modulus(readings, face_w, face_h, hand=hand, contact_radii_m=pads.radii_m or None,
                                contact_line_lengths_m=pads.line_lengths_m or None, **kw)
    return {"old": estimate_modulus(readings, face_w, face_h, hand=None, contact_law="flat", **kw),
            "hand": estimate_modulus(readings, face_w, face_h, hand=hand, contact_law="flat", **kw),
            "point": estimate_modulus(readings, face_w, face_h, hand=hand, contact_radii_m=contacts["point"] or None,
                                      **kw),
            "new": with_contacts(contacts["surface"]), "perceived": with_contacts(contacts["perceived"]),
            "section": estimate_modulus(readings, face_w, face_h, hand=hand, section=contacts["section"],
                                        contact_law="section" if section_on_flat_pads and contacts["section"]
                                        and not contacts["perceived"].radii_m else "auto",
                                        contact_radii_m=contacts["perceived"].radii_m or None,
                                        contact_line_lengths_m=contacts["perceived"].line_lengths_m or None, **kw)}


def radii_text(pads: PadContacts | None) -> str:
    """Per pad the radius (cm), "/L" and the line length (cm) for a line contact; "flat" without radii."""
    if not pads or not pads.radii_m:
        return "flat"
    lines = pads.line_lengths_m or (0.0,) * len(pads.radii_m)
    return ", ".join(f"{r * 100:.1f}" + (f"/L{length * 100:.1f}" if length > 0 else "")
                     for r, length in zip(pads.radii_m, lines))


def fill_text(contacts: dict) -> str:
    """For flat pads, how much of the flat law's prism the section fills (below squeeze.FLAT_FILL_MIN: the section
    law reads them)."""
    section = contacts.get("section")
    flat = not (contacts.get("perceived") and contacts["perceived"].radii_m)
    return f" (fill {section.flat_fill:.2f})" if flat and section is not None else ""


def factor(estimates, modulus_pa) -> float:
    """Median estimate / truth; inf when every repeat read rigid, nan when every repeat was refused."""
    if not estimates:
        return math.nan
    if all(e.rigid for e in estimates):
        return math.inf
    return statistics.median(e.youngs_modulus_pa for e in estimates) / modulus_pa


def factor_text(value: float, modulus_pa: float) -> str:
    """The factor; for a rigid body (2e9 Pa) read as a number, the number (Pa): its factor is ~0."""
    if math.isnan(value) or math.isinf(value):
        return "refused" if math.isnan(value) else "rigid"
    return f"{value * modulus_pa:.1e}" if modulus_pa >= 1e7 else f"{value:.2f}"


def within(ratios, factor_limit) -> int:
    return sum(1 / factor_limit <= r <= factor_limit for r in ratios)


def summary(rows) -> list:
    """Per variant: soft rows (E < 1e7 Pa) within a factor 2 and 3, rigid rows (2e9 Pa) read rigid."""
    lines = []
    soft = [r for r in rows if r[1] < 1e7]
    stiff = [r for r in rows if r[1] >= 1e7]
    for i, variant in enumerate(VARIANTS):
        ratios = [r[2][i] for r in soft]
        per_modulus = " / ".join(f"{within([r[2][i] for r in soft if r[1] == m], 3)}"
                                 for m in sorted({r[1] for r in soft}))
        lines.append(f"{variant:5s}: soft within x2 {within(ratios, 2)}, x3 {within(ratios, 3)} of {len(ratios)} "
                     f"(x3 per modulus, low to high: {per_modulus}); "
                     f"rigid read rigid {sum(math.isinf(r[2][i]) for r in stiff)} of {len(stiff)}")
    return lines


def settling_lines(readings_path: Path, cell_records: list) -> list:
    """The settling rule's evidence (squeeze.SETTLE_STEP_RATIO): over every stored squeeze, the largest gentle
    interval's ratio (squeeze.gentle_step_ratios), soft (E < 1e7 Pa) and rigid apart; and which squeezes of the
    cell's measured picks (records with "squeeze": forces_n, widths_m) have a step the rule leaves out."""
    rows = [json.loads(line) for line in readings_path.read_text().splitlines() if line.strip()]
    lines = []
    for label, chosen in (("soft", [r for r in rows if r["modulus_pa"] < 1e7]),
                          ("rigid", [r for r in rows if r["modulus_pa"] >= 1e7])):
        ratios = sorted(((max(gentle_step_ratios([SqueezeReading(f, w) for f, w in zip(r["forces_n"], r["widths_m"])],
                                                 WIDTH_RESOLUTION_M), default=0.0), r) for r in chosen),
                        key=lambda item: -item[0])
        lines.append(f"{label}: {len(chosen)} squeezes, the largest gentle-interval ratios: " + ", ".join(
            f"{x:.1f} ({r['object']} {r['modulus_pa']:.2g} yaw {r['yaw_rad']})" for x, r in ratios[:5]))
    for path in cell_records:
        squeezes = [r for r in (json.loads(line) for line in Path(path).read_text().splitlines() if line.strip())
                    if (r.get("squeeze") or {}).get("widths_m")]
        stepped = []
        for r in squeezes:
            readings = [SqueezeReading(f, w) for f, w in zip(r["squeeze"]["forces_n"], r["squeeze"]["widths_m"])]
            _, step_m = without_settling_step(readings, WIDTH_RESOLUTION_M)
            if step_m:
                stepped.append(f"{r['object']} pick {r['pick']}: {step_m * 1e3:.2f} mm")
        lines.append(f"{path}: {len(stepped)} of {len(squeezes)} squeezes with a settling step"
                     + (f" ({'; '.join(stepped)})" if stepped else ""))
    return lines


def what_if_hand(parser, args) -> HandCalibration:
    """--what-if-hand: one compliance for every object (a real hand's; docs/squeeze.md "Limits"), on soft rows."""
    compliance_um, sd_um = args.what_if_hand
    if not (compliance_um > 0 and sd_um >= 0):
        parser.error(f"--what-if-hand needs a compliance > 0 and a noise >= 0 um/N, got {compliance_um} {sd_um}")
    rigid = [m for m in args.moduli if m >= 1e7]
    if rigid or args.calibrate:
        parser.error(f"--what-if-hand reads the FEM bodies' stored squeezes only (soft moduli < 1e7 Pa): the rigid "
                     f"bodies' squeezes ({', '.join(f'{m:g}' for m in rigid) or '--calibrate'}) were made with the "
                     "present pads' contact compliance; drop them")
    return HandCalibration(1e6 / compliance_um, sd_um * 1e-6, f"what-if: {compliance_um:g} +- {sd_um:g} um/N for "
                           "every object (--what-if-hand)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=1,
                        help="squeezes per object and modulus, at yaw 0, 0.3, 0.6 rad ...")
    parser.add_argument("--yaws", type=float, nargs="+", default=None, metavar="RAD",
                        help="squeeze at these yaws instead (e.g. 0.3: where egad_train_08_c5 is perceived flat)")
    parser.add_argument("--moduli", type=float, nargs="+", default=[2e4, 2e5, 2e6, 2e9])
    parser.add_argument("--objects", nargs="+", default=["tuning"])
    parser.add_argument("--readings", type=Path, default=ROOT / "results" / "squeeze" / "readings.jsonl",
                        help="squeeze readings cache (JSON lines, appended; the stored file: every reading "
                             "docs/squeeze.md quotes)")
    parser.add_argument("--meshes", choices=MESH_SOURCES, default="shipped",
                        help="library shapes' bodies: their shipped tet meshes (the same on every machine) or "
                             "fTetWild's mesh of their surface (the rows docs/squeeze.md's tables before "
                             "2026-11-30 read: squeezed on their machine's meshes, which this machine does not have; "
                             "the contacts are perceived on this machine's)")
    parser.add_argument("--hand", choices=HAND_DRIVES, default="pressing",
                        help="the simulated hand's drive for FEM bodies: pressing (the cell's since 2026-11-30: the "
                             "grasp's force on the object) or speed-driven (before: ~2 N at the squeeze's speed "
                             "whatever the force; the stored rows docs/squeeze.md's figures before that read)")
    parser.add_argument("--calibrate", action="store_true", help="print the hand's calibration and stop")
    parser.add_argument("--section-on-flat-pads", action="store_true",
                        help="the section column uses the section law on flat pads too (the executor keeps the flat "
                             "law there; this shows why)")
    parser.add_argument("--what-if-hand", type=float, nargs=2, default=None, metavar=("UM_PER_N", "SD_UM_PER_N"),
                        help="estimate the stored FEM squeezes as if the hand's compliance were this, with this "
                             "noise (um/N), for every object: e.g. 2.3 0.5, the simulated hand with stiff pad "
                             "contacts (bench_pad_contact_stiffness.py; the FEM bodies' readings do not change with "
                             "them). Soft moduli only: the rigid bodies' stored squeezes are the present pads'")
    parser.add_argument("--settling", nargs="*", metavar="CELL_RECORDS", default=None,
                        help="print the settling rule's evidence over the stored squeezes (and the squeezes of the "
                             "given cell records, e.g. results/cell_experiment/records_measured.jsonl) and stop")
    args = parser.parse_args(argv)
    if args.settling is not None:
        print("\n".join(settling_lines(args.readings, args.settling)))
        return 0
    hand = calibration(args.readings)
    if args.what_if_hand is not None:
        hand = what_if_hand(parser, args)
    print(f"hand: {hand.describe()}", flush=True)
    if args.calibrate:
        return 0
    names = [n for o in args.objects for n in {"tuning": TUNING, "held_out": HELD_OUT}.get(o, (o,))]
    yaws = args.yaws if args.yaws is not None else [0.3 * r for r in range(args.repeats)]
    print(f"{'object':16s} {'E true':>8s} " + " ".join(f"{v:>9s}" for v in VARIANTS) +
          "  radii (cm): surface | perceived  spread  perceived estimate")
    rows, in_band, log_errors = [], {v: [] for v in BANDED}, {v: [] for v in BANDED}
    for name in names:
        for modulus in args.moduli:
            by_variant = {v: [] for v in VARIANTS}
            radii = {}
            for yaw in yaws:
                spec = scene_object(name, modulus, yaw, args.meshes)
                radii = contacts_of(spec)
                try:
                    readings = cached_readings(args.readings, name, modulus, yaw, args.meshes, args.hand)
                    estimates = estimates_of(readings, spec, hand, radii, args.section_on_flat_pads)
                    for variant, estimate in estimates.items():
                        by_variant[variant].append(estimate)
                except SqueezeError as error:   # the executor fails such a squeeze: a miss in the counts
                    print(f"{name:16s} {modulus:8.2g} refused: {error}", flush=True)
            for v in BANDED if modulus < 1e7 else ():   # does the estimate's one-sigma band hold the modulus?
                in_band[v] += [e.low_pa <= modulus <= e.high_pa for e in by_variant[v]]
                log_errors[v] += [math.log(e.youngs_modulus_pa / modulus) for e in by_variant[v] if not e.rigid]
            factors = [factor(by_variant[v], modulus) for v in VARIANTS]
            rows.append((name, modulus, factors))
            values = [e.youngs_modulus_pa for e in by_variant["perceived"]]
            spread = max(values) / min(values) if values and all(math.isfinite(v) for v in values) else math.nan
            print(f"{name:16s} {modulus:8.2g} " + " ".join(f"{factor_text(f, modulus):>9s}" for f in factors) +
                  f"  {radii_text(radii.get('surface'))} | {radii_text(radii.get('perceived'))}{fill_text(radii)} "
                  f"{spread:7.2f}  "
                  f"{by_variant['perceived'][0].describe() if by_variant['perceived'] else ''}", flush=True)
    for line in summary(rows):
        print(line)
    if SECTION_MODEL_S:
        print(f"section model: median {statistics.median(SECTION_MODEL_S):.2f} s, max {max(SECTION_MODEL_S):.2f} s "
              f"over {len(SECTION_MODEL_S)} sections (load average {os.getloadavg()[0]:.1f})")
    for v in BANDED:
        print(f"{v}: the one-sigma band holds the true modulus in {sum(in_band[v])} of {len(in_band[v])} soft "
              "squeezes (a band of one sd holds it in ~68 % when the model is right)")
        if log_errors[v]:      # what squeeze.MODEL_FACTOR stands for: the model's own error, one sd in log space
            rms = math.sqrt(sum(x * x for x in log_errors[v]) / len(log_errors[v]))
            print(f"{v}: rms of ln(estimate / true) over the {len(log_errors[v])} soft squeezes read as a number: "
                  f"{rms:.2f} (a factor {math.exp(rms):.2f}; squeeze.MODEL_FACTOR is {MODEL_FACTOR})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The tabletop planner's pad test covers the executor's opening: the hand descends opened to
pre_grasp_opening_m(the grasp's opening) and closes to the grasp, so everything the pads sweep between the two
must be free, not only the pads just outside the planned opening.

Seen in the cell experiment (2026-11-29): every pick of common_ring (75 mm across, a 35 mm hole) failed with
"the fingers did not close ... a finger is on the object": the planner took a radial grasp across the tube
(opening 33 mm, pads checked 17-31 mm from the centre, in the hole), the executor opened to 80 mm and the
inner finger came down on the far side of the tube (pad 15-29 mm beyond the ring's centre; tube 17.5-37.5 mm).
The executor now opens 10 mm wider than the grasp (not fully), so a neighbour beyond that is no obstacle.
"""
import math

import numpy as np
import pytest
import yaml

from defgg_ros.constants import FINGER_PAD_WIDTH_M, PANDA_FINGER_THICKNESS_M
from defgg_ros.control.gripper_rule import pre_grasp_opening_m
from defgg_ros.perception import tabletop as tt
from defgg_ros.perception import tabletop_scenes as ts
from defgg_ros.planning import tabletop_grasps as tg

# The cell experiment's common_ring pick 1 (seed 0): where it lies on the demo cell's table.
RING_XY_M, RING_YAW_RAD = (0.4857, -0.0291), 2.0544
CELL = {"base_T_camera": {"xyz": [0.5, 0.0, 0.40], "quat_xyzw": [1.0, 0.0, 0.0, 0.0]},
        "table": {"size_m": [1.2, 1.2, 0.05], "center_xy_m": [0.45, -0.1]}}


def _grasp_on_the_middle_box(objects):
    """feasible_grasp at the centre cell of the object under (0.5, 0), network angle along x."""
    scene = ts.TabletopScene(tuple(objects), ts.look_at((0.5, 0.0, 0.55), (0.5, 0.0, 0.0)))
    frame = ts.render(scene, seed=0)
    view = tt.perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    rows, cols = np.nonzero(view.grid_labels > 0)
    x, y = view.cell_xy_m(rows, cols)
    nearest = int(np.argmin(np.hypot(x - 0.5, y)))
    label = int(view.grid_labels[rows[nearest], cols[nearest]])
    row, col = (int(round(v)) for v in np.argwhere(view.grid_labels == label).mean(axis=0))
    return tg.feasible_grasp(view, label, row, col, math.pi / 2, 0.03, 0.9, tg.grid_moduli(view), tg.FreeSpace(view))


def _bar_and_neighbour(gap_m: float):
    """A 20 mm wide bar (90 mm long: only closing along x fits the hand) and the grasp on it with a second bar
    whose near face is gap_m from the bar's centre along the closing line (None: no neighbour)."""
    bar = ts.Box((0.5, 0.0), (0.02, 0.09, 0.04))
    if gap_m is None:
        return _grasp_on_the_middle_box([bar])
    return _grasp_on_the_middle_box([bar, ts.Box((0.5 + gap_m + 0.01, 0.0), (0.02, 0.09, 0.04), name="neighbour")])


@pytest.mark.unit
def test_a_neighbour_where_the_opened_finger_comes_down_blocks_the_grasp_and_one_beyond_does_not():
    alone = _bar_and_neighbour(None)
    assert alone is not None and abs(alone.closing_direction_base[0]) == pytest.approx(1.0, abs=1e-3)
    assert alone.width_m < 0.04
    pads_outer_m = alone.width_m / 2 + PANDA_FINGER_THICKNESS_M              # the pads at the planned opening
    opened_outer_m = pre_grasp_opening_m(alone.width_m) / 2 + PANDA_FINGER_THICKNESS_M
    assert opened_outer_m - pads_outer_m == pytest.approx(0.005)
    # Its near face 2.5 mm past the pads at the grasp's opening, under the finger opened 5 mm wider: blocked.
    assert _bar_and_neighbour(pads_outer_m + 0.0025) is None
    # 4 mm past the opened finger: the grasp stands (opened fully to 80 mm, the finger reached 16 mm further).
    beside = _bar_and_neighbour(opened_outer_m + 0.004)
    assert beside is not None and beside.width_m == pytest.approx(alone.width_m, abs=0.002)


def _ring_scene(tmp_path):
    from defgg_ros.sim import objects as sim_objects
    from defgg_ros.sim.meshes import save_tet_mesh_file
    from defgg_ros.sim.scene_spec import load_scene

    tet = sim_objects.get_shape("common_ring").union_tet      # as it is: the same body on every machine
    surface = tet.surface()
    mesh = tmp_path / "common_ring.npz"
    save_tet_mesh_file(mesh, tet.nodes_m, tet.tets)
    ring = {"name": "common_ring", "position_xy_m": list(RING_XY_M), "yaw_rad": RING_YAW_RAD,
            "youngs_modulus_pa": 2e9, "mass_kg": 0.05, "shape": "mesh", "mesh": str(mesh), "size_m": [1.0, 1.0, 1.0]}
    path = tmp_path / "ring.yaml"
    path.write_text(yaml.safe_dump({"name": "ring", **CELL, "objects": [ring]}), encoding="utf-8")
    radii = np.hypot(surface.vertices[:, 0], surface.vertices[:, 1])
    return load_scene(path), (float(radii.min()), float(radii.max()))


def _pad_sweep_xy(grasp, opening_m: float) -> np.ndarray:
    """Points (x, y) of both pads from the grasp's opening out to opening_m (plus the pad's thickness)."""
    p, d = np.asarray(grasp.position_base_m[:2]), np.asarray(grasp.closing_direction_base[:2])
    across = np.array([-d[1], d[0]])
    along = np.linspace(grasp.width_m / 2, opening_m / 2 + PANDA_FINGER_THICKNESS_M, 30)
    sideways = np.linspace(-FINGER_PAD_WIDTH_M / 2, FINGER_PAD_WIDTH_M / 2, 7)
    return np.array([p + side * a * d + s * across for side in (-1, 1) for a in along for s in sideways])


@pytest.mark.sim
def test_the_ring_grasp_leaves_the_opened_fingers_off_the_ring(tmp_path):
    from defgg_ros.model.inference import GraspPredictor
    from defgg_ros.perception.depth_noise import DepthNoiseModel
    from defgg_ros.planning.perceived_frame import moduli_image, perceive_frame, view_from_parts
    from defgg_ros.planning.tabletop_planner import PerceivedObjects, TabletopPlanner
    from defgg_ros.ros.share import share_path
    from defgg_ros.sim.cell.sim_cell import SimCell

    scene, (hole_m, outer_m) = _ring_scene(tmp_path)
    assert hole_m == pytest.approx(0.0175, abs=0.001) and outer_m == pytest.approx(0.0375, abs=0.001)
    cell = SimCell(scene)
    try:
        depth, _, _ = cell.render_depth()
        centre = np.asarray(cell.object_poses()[0][0][:2])
        base_T_camera = np.eye(4)
        base_T_camera[:3, :3] = np.diag([1.0, -1.0, -1.0])      # quat (1, 0, 0, 0): the camera looks down
        base_T_camera[:3, 3] = CELL["base_T_camera"]["xyz"]
        k = cell.camera_k
    finally:
        cell.close()
    # As the nodes plan: the segmentation node perceives, the inference node plans on its parts (top_k 1).
    parts, _, _ = perceive_frame(depth, k, base_T_camera, tt.TabletopConfig(depth_noise=DepthNoiseModel.for_camera(
        "d435")), default_youngs_modulus_pa=2e9)
    view = view_from_parts(parts, depth, k)
    planner = TabletopPlanner(GraspPredictor.from_checkpoint(share_path("models", "defgg_cnn.pt"), num_threads=1))
    prepared = planner.network(PerceivedObjects(view, None, moduli_image(parts, depth.shape), None))
    grasp = planner.search(prepared, 1).grasps[0]
    opening_m = pre_grasp_opening_m(grasp.width_m)
    r = np.hypot(*(_pad_sweep_xy(grasp, opening_m) - centre).T)
    # Off the ring's top-down outline (the fingertips go below the tube's top), 1 mm for the render's pixels.
    on_ring = (r > hole_m - 0.001) & (r < outer_m + 0.001)
    assert not on_ring.any(), (f"a pad opened to {opening_m * 1e3:.0f} mm sweeps the ring: r "
                               f"{r[on_ring].min() * 1e3:.1f}-{r[on_ring].max() * 1e3:.1f} mm from its centre "
                               f"(tube {hole_m * 1e3:.1f}-{outer_m * 1e3:.1f} mm), grasp {grasp}")

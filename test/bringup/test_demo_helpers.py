"""The demo's pure helpers: image geometry against the real cell camera, bin check, table, summary, picture."""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.bringup.demo_geometry import (
    base_T_camera,
    bin_place_xy,
    grasp_is_on_object,
    in_bin,
    label_of_object,
    object_roi,
    project_base_points,
)
from defgg_ros.bringup.demo_report import FramePanels, PickRow, format_table, save_figure, write_summary

SCENES = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes"


@pytest.fixture(scope="module")
def rendered():
    from defgg_ros.sim.cell.sim_cell import SimCell
    from defgg_ros.sim.scene_spec import load_scene

    cell = SimCell(load_scene(SCENES / "demo.yaml"))
    try:
        depth_m, mask, _ = cell.render_depth()
        yield cell.scene.to_json_dict(), [xyz for xyz, _ in cell.object_poses()], cell.camera_k, mask
    finally:
        cell.close()


def test_projection_and_rois_match_the_rendered_objects(rendered):
    scene, positions, k, mask = rendered
    b_t_c = base_T_camera(scene)
    for i, (obj, pos) in enumerate(zip(scene["objects"], positions)):
        u, v = project_base_points([pos], b_t_c, k)[0]
        assert mask[int(round(v)), int(round(u))] == i, obj["name"]
        x, y, w, h = object_roi(obj, pos, b_t_c, k, (640, 480))
        ys, xs = np.nonzero(mask == i)
        assert x <= xs.min() and xs.max() < x + w and y <= ys.min() and ys.max() < y + h, obj["name"]
        labels = (mask == i).astype(np.uint8) * 7
        assert label_of_object(labels, (u, v)) == 7
        # Seen from elsewhere (the object moved away): another object's segment is not it.
        assert label_of_object(labels, (u + 3 * w, v)) == 0


def test_grasp_on_object_and_bin():
    obj = {"shape": "box", "size_m": [0.05, 0.05, 0.05]}
    assert grasp_is_on_object((0.51, 0.0), obj, (0.5, 0.0, 0.025))
    assert not grasp_is_on_object((0.6, 0.0), obj, (0.5, 0.0, 0.025))
    bin_dict = {"center_xy_m": [0.35, -0.45], "inner_size_m": [0.2, 0.2, 0.06]}
    assert in_bin((0.36, -0.44, 0.03), bin_dict)
    assert not in_bin((0.5, 0.0, 0.025), bin_dict)
    assert not in_bin((0.35, -0.45, 0.5), bin_dict)       # held high above the bin
    assert not in_bin((0.35, -0.45, 0.03), None)


def test_table_summary_and_figure(tmp_path):
    rows = [PickRow("sponge", 2e4, "soft", 0.031, 0.8, "done", True, True, True, estimated_mass_kg=0.0631,
                    gripper_force_n=0.678),
            PickRow("can", 2e9, "rigid", failure_reason="PlanGrasp: no object")]
    table = format_table(rows)
    assert "sponge" in table and "31.0" in table and "2e+09" in table and "PlanGrasp: no object" in table
    assert " 63 " in table and "0.68" in table          # estimated mass (g) and the force it closed with (N)
    placed_but_gone = PickRow("block", 2e6, "soft", 0.064, 1.0, "done", True, True, False,
                              final_position_m=(0.734, -0.0816, -12306.607))
    assert "left the table after the pick: ended at (0.73, -0.08, -12306.61) m" in format_table([placed_but_gone])
    placed_beside = PickRow("block", 2e6, "soft", 0.064, 1.0, "done", True, True, False,
                            final_position_m=(0.2, -0.3, 0.02))
    assert "ended outside the bin at (0.20, -0.30, 0.02) m" in format_table([placed_beside])
    summary = write_summary(tmp_path / "summary.json", rows, {"scene": "x"})
    loaded = json.loads((tmp_path / "summary.json").read_text())
    assert loaded == json.loads(json.dumps(summary))
    assert loaded["objects"][1]["grasp_width_m"] is None and loaded["picked_into_bin"] == 1
    depth = np.full((48, 64), 0.4)
    panel = FramePanels("sponge", depth, np.where(depth > 0, 2e4, 0.0), np.zeros((48, 64)), (30.0, 20.0),
                        math.pi / 4, 10.0)
    save_figure(tmp_path / "grasps.png", [panel])
    assert (tmp_path / "grasps.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_multi_material_part_gets_its_own_modulus_in_the_stiffness_image(tmp_path):
    from defgg_interfaces.msg import ObjectStiffness  # noqa: F401  (the demo builds these messages)

    from defgg_ros.bringup.demo_geometry import base_T_camera
    from defgg_ros.demo import _stiffness_msgs
    from defgg_ros.perception.stiffness_assignment import make_entry
    from defgg_ros.perception.tabletop import TabletopConfig
    from defgg_ros.planning.perceived_frame import perceive_frame
    from defgg_ros.sim.cell.sim_cell import SimCell
    from defgg_ros.sim.scene_spec import load_scene

    scene_path = tmp_path / "two_material.yaml"
    scene_path.write_text("""
objects:
  - name: brick_with_foam_end
    shape: box
    size_m: [0.08, 0.04, 0.04]
    position_xy_m: [0.5, 0.0]
    yaw_rad: 0.3
    youngs_modulus_pa: 2.0e9
    part: {youngs_modulus_pa: 2.0e4, x_from_m: 0.0}
""")
    cell = SimCell(load_scene(scene_path))
    try:
        depth_m, mask, _ = cell.render_depth()
        scene = cell.scene.to_json_dict()
        positions = [xyz for xyz, _ in cell.object_poses()]
        k = cell.camera_k
    finally:
        cell.close()
    msgs = _stiffness_msgs(scene, positions, k, (640, 480), {"brick_with_foam_end"})
    assert [m.region_only for m in msgs] == [False, True]
    entries = tuple(make_entry(m.name, m.youngs_modulus_pa, (m.roi.x_offset, m.roi.y_offset, m.roi.width,
                                                             m.roi.height), m.region_only) for m in msgs)
    _, _, image = perceive_frame(depth_m.astype(np.float32), k, base_T_camera(scene), TabletopConfig(), entries)
    on_object = image[mask == 0]
    soft_share = np.mean(on_object == np.float32(2e4))
    assert 0.3 < soft_share < 0.7, f"the foam end should be about half the brick, got {soft_share:.2f}"
    assert np.mean(on_object == np.float32(2e9)) > 0.3


def test_bin_place_points_are_distinct_quadrant_centres_inside_the_bin():
    bin_dict = {"center_xy_m": [0.35, -0.45], "inner_size_m": [0.22, 0.22, 0.06]}
    points = [bin_place_xy(bin_dict, slot) for slot in range(4)]
    assert len(set(points)) == 4
    for x, y in points:
        assert in_bin((x, y, 0.03), bin_dict)
        assert abs(abs(x - 0.35) - 0.055) < 1e-9 and abs(abs(y + 0.45) - 0.055) < 1e-9
    # consecutive objects go to opposite corners, and the fifth reuses the first quadrant
    assert math.dist(points[0], points[1]) == pytest.approx(0.11 * math.sqrt(2))
    assert bin_place_xy(bin_dict, 4) == points[0]
    with pytest.raises(ValueError, match="slot"):
        bin_place_xy(bin_dict, -1)


def test_a_failed_demo_names_the_node_that_died_with_its_last_lines(tmp_path, capsys):
    """A timed-out call is reported with the dead node's own last words (real child processes)."""
    import io
    import time

    from defgg_ros.bringup.node_set import NodeSet
    from defgg_ros.bringup.supervisor import Bringup
    from defgg_ros.demo import _explain_dead_node

    crash = [sys.executable, "-c", "print('loading the model'); print('CUDA? no: out of memory'); raise SystemExit(3)"]
    idle = [sys.executable, "-c", "import time; print('spinning'); time.sleep(30)"]
    empty = NodeSet("none", True, (), tmp_path)
    with Bringup(empty, extra={"idle_node": idle}, out=io.StringIO()) as alive:
        deadline = time.monotonic() + 20
        while not alive.processes["idle_node"].tail and time.monotonic() < deadline:
            time.sleep(0.05)
        _explain_dead_node(alive)
        assert "idle_node is running; its last lines:\n  spinning" in capsys.readouterr().err
    with Bringup(empty, extra={"inference": crash}, out=io.StringIO()) as cell:
        cell.processes["inference"].popen.wait(timeout=20)
        deadline = time.monotonic() + 20      # the log reader thread catches up with the exited process's output
        while len(cell.processes["inference"].tail) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        _explain_dead_node(cell)
    err = capsys.readouterr().err
    assert "node inference died (exit code 3); its last lines:" in err and "out of memory" in err


def test_release_height_keeps_the_drop_short_and_the_palm_over_the_walls():
    from defgg_ros.bringup.demo_geometry import RELEASE_DROP_M, release_tcp_z
    from defgg_ros.constants import PANDA_FINGER_LENGTH_M, PANDA_FINGERTIP_BELOW_TCP_M

    bin_dict = {"center_xy_m": [0.35, -0.45], "inner_size_m": [0.22, 0.22, 0.06]}
    assert release_tcp_z(0.05, bin_dict, 0.12) == pytest.approx(0.05 + RELEASE_DROP_M)   # a 5 cm block
    assert release_tcp_z(0.15, bin_dict, 0.12) == 0.12                                    # capped
    flat = release_tcp_z(0.0, bin_dict, 0.12)                                             # a flat object
    assert flat + PANDA_FINGER_LENGTH_M - PANDA_FINGERTIP_BELOW_TCP_M > 0.06              # palm above the walls
    tall_walls = dict(bin_dict, inner_size_m=[0.22, 0.22, 0.2])
    assert release_tcp_z(0.05, tall_walls, 0.3) > 0.2 - (PANDA_FINGER_LENGTH_M - PANDA_FINGERTIP_BELOW_TCP_M)


@pytest.mark.parametrize("cell_ran,in_bin,strict,expected", [
    (True, [True, True], False, 0), (True, [True, False], False, 0),   # default: the table says what was placed
    (True, [True, True], True, 0), (True, [True, False], True, 3), (True, [], True, 3),
    (False, [True], False, 1), (False, [True, False], True, 1),        # a failed cell is 1 whatever was placed
])
def test_demo_exit_code_says_whether_the_cell_ran_and_with_strict_whether_all_reached_the_bin(
        cell_ran, in_bin, strict, expected):
    from defgg_ros.demo import exit_code

    rows = [PickRow(f"o{i}", 2e4, "soft", in_bin=placed) for i, placed in enumerate(in_bin)]
    assert exit_code(cell_ran, rows, strict) == expected


def test_demo_help_names_the_exit_codes(capsys):
    from defgg_ros.demo import parse_args

    with pytest.raises(SystemExit):
        parse_args(["--help"])
    out = capsys.readouterr().out
    assert "--strict" in out and "exit 3" in out and "Exit codes" in out


def test_a_node_that_dies_during_a_call_ends_the_wait_at_once():
    """The demo checked for dead nodes only between picks: an executor dying mid-pick left it waiting out the
    whole --pick-timeout (900 s) before it said which node had died."""
    import time

    from defgg_ros.bringup.demo_client import DemoClient
    from defgg_ros.bringup.supervisor import BringupError

    def dead():
        raise BringupError("executor_node exited with code -9")

    client = DemoClient(check_alive=dead)
    try:
        started = time.monotonic()
        with pytest.raises(BringupError, match="executor_node exited"):
            client._spin_until(lambda: False, 900.0)
        assert time.monotonic() - started < 5.0
    finally:
        client.close()

"""The demo's place, in one process (no ROS): a block put into the bin's outer quadrant rests flat on the table.

Why: the shipped scenes' bin hung 7 cm over the table's edge (the table is the bin's floor); the rubber block
placed in that quadrant rested with its centre beyond the edge, tipped, and fell off in 1 of 12 demo runs and
2 of 24 in-process placements (bench/bench_release_in_bin.py). On the old table this test fails (the block's
footprint reaches y -0.527 m, beyond the edge at -0.500 m).
"""
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.bringup.demo_in_process import pick_into_bin
from defgg_ros.nodes.executor_node import ExecutorNode
from defgg_ros.ros.parameters import defaults
from defgg_ros.sim.cell.objects import SOFT_COLLISION_MARGIN_M
from defgg_ros.sim.scene_spec import load_scene

DEMO_SCENE = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes" / "demo.yaml"
OUTER_QUADRANT_SLOT = 2            # the third object placed: the quadrant at the bin's far side in y


@pytest.mark.timeout(600)
def test_a_block_placed_in_the_outer_quadrant_rests_flat_on_the_table():
    scene = load_scene(DEMO_SCENE)
    spec = next(o for o in scene.objects if o.name == "rubber_block")
    params = defaults("executor_node")
    placed = pick_into_bin(scene, spec.name, ExecutorNode._sequence_config(params), OUTER_QUADRANT_SLOT,
                           finger_force_n=1.2, release_max_z_m=float(params["place_position_m"][2]), settle_s=2.0)
    assert placed.success, placed.failure_reason
    assert placed.in_bin, f"ended at {placed.final_m}"
    table_lo_y = scene.table_center_xy_m[1] - scene.table_size_m[1] / 2
    half_x, half_y, height = (s / 2 for s in spec.size_m)
    footprint_lo_y = placed.final_m[1] - max(half_x, half_y)
    assert footprint_lo_y > table_lo_y, f"the block's footprint reaches y {footprint_lo_y:.3f} m, beyond the table"
    # Flat: its centroid at half its height above the table, plus the soft contact margin (a tipped block sat
    # 1-10 mm lower).
    assert placed.final_m[2] == pytest.approx(height + SOFT_COLLISION_MARGIN_M, abs=1.5e-3)
    assert np.isfinite(placed.fastest_after_release_mps) and placed.fastest_after_release_mps < 2.0

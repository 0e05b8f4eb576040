"""The pick sequence against the real simulated cell (PyBullet, no ROS): a grasp whose predicted width
is narrower than the object must still pick it.

Why: Def-GG-CNN's width was 14-40 mm under the objects' extent in the demo; opening only
"width + 20 mm" put a finger on top of the object and the pick failed at the close.
"""
from pathlib import Path

import numpy as np
import pytest

from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import (
    ArmState,
    CancelGripper,
    GraspGripper,
    GraspTarget,
    MoveGripper,
    PlaceTarget,
    SendTrajectory,
    SequenceConfig,
)
from defgg_ros.sim.cell import SimCell
from defgg_ros.sim.scene_spec import load_scene

SCENE = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes" / "rigid_box.yaml"
PERIOD_S = 0.01


class CellDriver:
    """Carries the sequence's commands to the cell and its state back, as the two nodes do."""

    def __init__(self, cell: SimCell, sequence: PickPlaceSequence):
        self.cell, self.sequence = cell, sequence
        self.widths_m = []

    def apply(self, commands):
        for command in commands:
            if isinstance(command, SendTrajectory):
                t = command.trajectory
                self.cell.command_trajectory(list(zip(t.times_s, t.q_rad, t.qd_radps, t.qdd_radps2)))
            elif isinstance(command, MoveGripper):
                self.cell.gripper_move(command.width_m, command.speed_mps)
            elif isinstance(command, GraspGripper):
                g = command.command
                self.cell.gripper_grasp(g.width_m, g.epsilon_inner_m, g.epsilon_outer_m, g.speed_mps, g.force_n)
            elif isinstance(command, CancelGripper):
                self.cell.gripper_move(self.cell.gripper_width_m(), 0.1)

    def feed(self, outcomes):
        joints = self.cell.joint_state()
        width = float(joints.positions[7] + joints.positions[8])
        self.sequence.on_joint_state(ArmState(joints.positions[:7], joints.velocities[:7], width), self.cell.time_s)
        self.sequence.on_force(self.cell.external_wrench()[0])
        for _, outcome in outcomes:
            self.sequence.on_gripper_result(outcome.success, outcome.width_m, outcome.error)

    def run(self, max_sim_s: float):
        self.feed([])
        self.apply(self.sequence.start(self.cell.time_s, self.cell.time_s))
        while not self.sequence.finished and self.cell.time_s < max_sim_s:
            outcomes = self.cell.advance(PERIOD_S)
            self.feed(outcomes)
            self.widths_m.append(self.cell.gripper_width_m())
            self.apply(self.sequence.tick(self.cell.time_s, self.cell.time_s))
        return self.sequence.outcome


@pytest.fixture
def cell():
    sim = SimCell(load_scene(SCENE))
    yield sim
    sim.close()


def test_a_grasp_with_an_underestimated_width_still_picks_the_box(cell):
    spec = cell.scene.objects[0]
    position, _ = cell.object_poses()[0]
    box_width_m = spec.size_m[0]
    predicted_width_m = box_width_m - 0.025   # like the demo's predictions: 20+ mm too narrow
    grasp = GraspTarget((position[0], position[1], spec.height_m), spec.yaw_rad, predicted_width_m,
                        spec.youngs_modulus_pa)
    config = SequenceConfig(limits_scale=0.4, transfer_via_position_m=(0.45, -0.2, 0.3))
    sequence = PickPlaceSequence(PandaKinematics(), config, grasp, PlaceTarget((0.35, -0.45, 0.12)))
    outcome = CellDriver(cell, sequence).run(max_sim_s=30.0)
    assert outcome.success, outcome.failure_reason
    # The fingers stopped on the box's sides (contact margin ~3 mm a side), not on its top.
    assert box_width_m < outcome.gripper_width_closed_m < box_width_m + 0.01
    final, _ = cell.object_poses()[0]
    assert np.linalg.norm(final[:2] - [0.35, -0.45]) < 0.1

"""Cancel mid-descend, then pick again: the second pick must take the object, not grasp at the hand.

The whole simulated cell as processes (driver, segmentation, inference with the shipped network,
executor) over real DDS; both goals ask the executor to plan (plan_grasp=true). Issue 27: after a
cancel the arm stayed over the table, in the camera's view, and the next goals planned grasps on
the hand (z ~ 0.245 m, "missed"). Two ways it must not happen, both tested:
- recover_after_failure (the default): the canceled goal brings the arm back to the observation
  pose before its result, and says so (arm_state, recovery);
- recovery off: the arm stays where it stopped, and the next plan_grasp goal moves it to the
  observation pose first ("recover" feedback before pre_grasp) and plans on a frame taken there.
"""

import numpy as np
import pytest
from defgg_interfaces.action import PickAndPlace
from geometry_msgs.msg import PoseArray
from rclpy.node import Node
from sensor_msgs.msg import JointState

from defgg_ros.bringup.node_set import load_node_set
from defgg_ros.bringup.supervisor import Bringup
from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.ros import qos, topics
from defgg_ros.ros.action import ActionClient

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(900)]

SCENES = load_node_set("sim_cell").config_dir.parent / "scenes"
BOX_TOP_M = 0.05                     # rigid_box.yaml: a 5 cm wooden block
BIN_XY_M, BIN_INNER_M = (0.35, -0.45), 0.32   # the scenes' bin (test/control/test_bin_slots.py)
PICK_TIMEOUT_S = 300.0
KIN = PandaKinematics()


@pytest.fixture(params=[True, False], ids=["recovery", "no_recovery"])
def cell(request, tmp_path, executor):
    overrides = {"fake_panda_driver": {"scene_file": str(SCENES / "rigid_box.yaml")},
                 # A slow descent leaves the cancel time to land mid-descent on a busy machine.
                 "executor_node": {"descent_speed_mps": 0.01, "recover_after_failure": request.param}}
    log_path = tmp_path / "cell.log"
    with open(log_path, "w") as log, Bringup(load_node_set("sim_cell"), overrides, out=log) as bringup:
        bringup.wait_ready(180.0)
        probe = Node("recovery_cell_probe", context=executor.context)
        seen = {"joints": [], "poses": []}
        probe.create_subscription(JointState, topics.JOINT_STATES, seen["joints"].append, qos.STATE)
        probe.create_subscription(PoseArray, topics.FAKE_OBJECT_POSES, seen["poses"].append, qos.STATE)
        client = ActionClient(probe, PickAndPlace, topics.PICK_AND_PLACE_ACTION)
        executor.add_node(probe)
        yield request.param, client, seen, log_path, bringup


def _goal(executor, spin, client, feedback):
    spin(executor, client.server_is_ready, 60.0, "the pick-and-place action server")
    handle = spin(executor, client.send_goal_async(PickAndPlace.Goal(plan_grasp=True),
                                                   feedback_callback=lambda f: feedback.append(f.feedback)),
                  30.0, "the goal response")
    assert handle.accepted
    return handle


def _tcp_z(joint_state) -> float:
    return float(KIN.fk(np.array(joint_state.position[:7]))[2, 3])


def test_cancel_mid_descend_then_pick_again_picks_the_object(cell, executor, spin):
    recovery_on, client, seen, log_path, bringup = cell
    feedback = []
    handle = _goal(executor, spin, client, feedback)
    result = handle.get_result_async()
    spin(executor, lambda: result.done() or (feedback and feedback[-1].phase == "descend"
                                             and feedback[-1].phase_progress > 0.3),
         PICK_TIMEOUT_S, "the descent to be under way")
    log = log_path.read_text
    assert not result.done(), ("the first pick ended before its descent", result.result().result.failure_reason,
                               [f.phase for f in feedback][-5:], log()[-3000:])
    spin(executor, handle.cancel_goal_async(), 30.0, "the cancel response")
    canceled = spin(executor, result, PICK_TIMEOUT_S, "the canceled goal's result")
    assert canceled.status == 5, canceled.result.failure_reason  # STATUS_CANCELED
    first = canceled.result
    assert "canceled during descend" in first.failure_reason and first.phase_reached == "descend"
    arm_q = np.array(seen["joints"][-1].position[:7])
    if recovery_on:
        assert first.arm_state == "observation_pose", (first.recovery, log()[-3000:])
        assert "moved to the observation pose" in first.recovery
        assert np.max(np.abs(arm_q - PANDA_READY_Q_RAD)) < 0.05
    else:  # left where it stopped: over the table, in the camera's view
        assert first.arm_state == "at_rest" and first.recovery == ""
        assert _tcp_z(seen["joints"][-1]) < 0.2

    feedback = []   # a new list: the canceled goal's late feedback still lands in the old one
    poses_before_second = len(seen["poses"])
    handle = _goal(executor, spin, client, feedback)
    second = spin(executor, handle.get_result_async(), PICK_TIMEOUT_S, "the second pick's result").result
    poses_at_result = len(seen["poses"])
    phases = list(dict.fromkeys(f.phase for f in feedback))
    # Planned on the object, not on the hand: the grasp is at the block's top, not ~0.245 m up.
    grasp_z = second.grasp_used.pose_base.pose.position.z
    assert abs(grasp_z - BOX_TOP_M) < 0.02, (grasp_z, second.failure_reason, phases)
    assert second.success, (second.failure_reason, phases, log()[-4000:])
    assert second.held_after_transfer and second.arm_state in ("at_rest", "observation_pose")
    if not recovery_on:  # it went to the observation pose before planning
        assert phases[0] == "recover" and phases.index("recover") < phases.index("pre_grasp"), phases
    # A pose published after the result (under load the last one received may be older).
    spin(executor, lambda: len(seen["poses"]) > poses_at_result
         and abs(seen["poses"][-1].poses[0].position.z - BOX_TOP_M / 2) < 0.01, 60.0, "the block to come to rest")
    block = seen["poses"][-1].poses[0].position
    track = [p.poses[0].position for p in seen["poses"][poses_before_second:]]
    grasp = second.grasp_used.pose_base.pose.position
    assert abs(block.x - BIN_XY_M[0]) < BIN_INNER_M / 2 and abs(block.y - BIN_XY_M[1]) < BIN_INNER_M / 2, (
        f"block at ({block.x:.3f}, {block.y:.3f}, {block.z:.3f}); at the second goal ({track[0].x:.3f}, "
        f"{track[0].y:.3f}); highest {max(p.z for p in track):.3f} m; grasp at ({grasp.x:.3f}, {grasp.y:.3f}, "
        f"{grasp.z:.3f}); {second}\n{log()[-3000:]}")
    assert bringup.failed_node() is None

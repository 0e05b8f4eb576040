"""Faults during a pick, over real DDS against the in-test driver of test/support/executor_cell.py.

- the gripper closes on nothing -> the goal is aborted as a missed grasp;
- the object slips out during the transfer -> aborted, "dropped during transfer";
- the driver stays alive but stops publishing joint states -> aborted within
  the watchdog time (plus scheduling margin) with "driver silent";
- every trajectory the executor actually put on the wire (FollowJointTrajectory
  goals, as the driver received them) during a full pick and during a cancel
  is checked independently of the planner's own check: joint position, velocity, acceleration and jerk limits, TCP above
  the table, and the cancel's stop ends at rest.
"""

import numpy as np
import pytest
from defgg_interfaces.action import PickAndPlace
from support.executor_cell import (
    FAST,
    GRASP_XYZ,
    KIN,
    InTestDriver,
    grasp_msg,
    result_of,
    send,
    wait_driver_ready,
)
from trajectory_msgs.msg import JointTrajectory

from defgg_ros.constants import (
    PANDA_Q_MAX_RAD,
    PANDA_Q_MIN_RAD,
    PANDA_QD_MAX_RADPS,
    PANDA_QDD_MAX_RADPS2,
    PANDA_QDDD_MAX_RADPS3,
)

ABORTED, CANCELED = 6, 5  # action_msgs/GoalStatus
REL_TOL = 1e-3  # the wire format rounds times to whole nanoseconds


class SlippingDriver(InTestDriver):
    """Lets the object fall out of the fingers once the TCP has carried it 8 cm sideways."""

    def step(self):
        tcp = KIN.fk(self.q)[:3, 3]
        if self.gripper is None and self.width_m > 0.01 and np.hypot(tcp[0] - GRASP_XYZ[0],
                                                                     tcp[1] - GRASP_XYZ[1]) > 0.08:
            if tcp[2] > GRASP_XYZ[2] + 0.05:  # lifted, i.e. in transfer; not the opening at the place pose
                self.object_width_m = 0.0
                self.width_m = 0.0  # a parallel hand closes fully when the object leaves it
        super().step()


def _check_on_the_wire(msg: JointTrajectory, table_z_m: float, scale: float):
    """Limits from the message alone (not the planner's check_trajectory)."""
    if not msg.points:
        return  # an empty trajectory means "hold"
    t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
    q = np.array([p.positions for p in msg.points])
    qd = np.array([p.velocities for p in msg.points])
    qdd = np.array([p.accelerations for p in msg.points])
    assert np.all(np.diff(t) > 0), "times must increase"
    assert np.all(q >= np.array(PANDA_Q_MIN_RAD) - 1e-9) and np.all(q <= np.array(PANDA_Q_MAX_RAD) + 1e-9)
    assert np.all(np.abs(qd) <= scale * np.array(PANDA_QD_MAX_RADPS) * (1 + REL_TOL))
    assert np.all(np.abs(qdd) <= scale * np.array(PANDA_QDD_MAX_RADPS2) * (1 + REL_TOL))
    if len(t) > 1:
        jerk = np.diff(qdd, axis=0) / np.diff(t)[:, None]
        assert np.all(np.abs(jerk) <= scale * np.array(PANDA_QDDD_MAX_RADPS3) * (1 + REL_TOL))
    assert min(KIN.fk(qk)[2, 3] for qk in q) >= table_z_m


def test_every_trajectory_on_the_wire_is_within_limits_for_a_pick_and_a_cancel(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    driver = start_driver(object_width_m=0.04, contact_height_m=GRASP_XYZ[2] + 0.01)
    seen = driver.trajectory_msgs  # the goals' trajectories as they arrived at the driver
    wait_driver_ready(ex, spin, node)
    response = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg())))
    assert response.result.success, response.result.failure_reason
    spin(ex, lambda: len(seen) >= 6, 5.0, "the pick's trajectories at the recorder")
    picked = len(seen)
    # A second goal, canceled while moving: the stop is one more message and must end at rest.
    handle = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg(xyz=(0.45, -0.05, 0.04), yaw=-0.5)))
    spin(ex, lambda: len(seen) > picked, 10.0, "the second goal's first trajectory")
    spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 10.0, "the arm moving for the second goal")
    spin(ex, handle.cancel_goal_async(), 5.0, "cancel response")
    assert result_of(ex, spin, handle).status == CANCELED
    spin(ex, lambda: len(seen) >= picked + 2, 5.0, "the stop trajectory at the recorder")
    for msg in seen:
        _check_on_the_wire(msg, node._config.table_z_m, FAST["limits_scale"])
    stop = seen[-1]
    assert stop.points and np.allclose(stop.points[-1].velocities, 0.0, atol=1e-9)
    assert np.allclose(stop.points[-1].accelerations, 0.0, atol=1e-9)


def test_gripper_closing_on_nothing_is_a_missed_grasp_not_a_success(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    start_driver(object_width_m=0.0)
    wait_driver_ready(ex, spin, node)
    response = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg())))
    assert response.status == ABORTED
    assert not response.result.success
    assert "missed" in response.result.failure_reason
    assert response.result.phase_reached == "close"
    assert response.result.gripper_width_closed_m < 0.004


def test_object_slipping_out_during_transfer_is_reported(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    driver = SlippingDriver(ex.context, object_width_m=0.04)
    ex.add_node(driver)
    wait_driver_ready(ex, spin, node)
    response = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg())))
    assert response.status == ABORTED
    assert "dropped during transfer" in response.result.failure_reason, response.result.failure_reason
    assert response.result.held_after_lift and not response.result.held_after_transfer
    assert response.result.phase_reached == "transfer"


def test_driver_alive_but_silent_is_aborted_within_the_watchdog_time(executor_cell, spin):
    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    handle = send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg()))
    spin(ex, lambda: np.max(np.abs(driver.qd)) > 0.2, 10.0, "the arm moving")
    for timer in list(driver.timers):  # the node, its actions and its subscription stay up
        timer.cancel()
    # result_of's timeout bounds the wait (a hang fails); the watchdog's own bound is checked on a fake clock
    # (control/test_control_pick_place.py), not timed here
    response = result_of(ex, spin, handle, timeout_s=FAST["watchdog_timeout_s"] + 5.0)
    assert response.status == ABORTED and "driver silent" in response.result.failure_reason
    assert driver.context.ok() and driver.handle is not None


@pytest.mark.parametrize("xyz", [(1.3, 0.0, 0.05), (0.0, 0.0, 0.05), (0.5, 0.0, 1.2)])
def test_unreachable_grasps_are_aborted_before_any_motion(executor_cell, spin, xyz):
    ex, node, client, start_driver = executor_cell
    driver = start_driver()
    wait_driver_ready(ex, spin, node)
    response = result_of(ex, spin, send(ex, client, spin, PickAndPlace.Goal(grasp=grasp_msg(xyz=xyz))),
                         timeout_s=10.0)
    assert response.status == ABORTED and response.result.failure_reason
    assert driver.trajectory_msgs == []

"""The joint_trajectory_controller's tolerances and the ends of a trajectory (sim/cell/tolerances.py, pure numpy).

Facts: ros2_controllers jazzy, joint_trajectory_controller/include/joint_trajectory_controller/tolerances.hpp and
src/joint_trajectory_controller.cpp (`update`); docs/franka_contract.md, "The arm's trajectory controller".
"""
import numpy as np
import pytest

from defgg_ros.sim.cell.tolerances import (
    GOAL_VIOLATED,
    PATH_TEXT,
    PATH_VIOLATED,
    SUCCEEDED,
    SUCCESS_TEXT,
    ToleranceError,
    TrajectoryMonitor,
    default_tolerances,
    goal_tolerances,
    resolve,
)

pytestmark = pytest.mark.unit

JOINTS = tuple(f"fer_joint{i}" for i in range(1, 8))
Z = np.zeros(7)


def test_a_goal_value_replaces_keeps_or_erases_the_default():
    assert resolve(0.01, 0.5) == 0.5
    assert resolve(0.01, 0.0) == 0.01          # 0: unspecified, the controller's value
    assert resolve(0.01, -1.0) == 0.0          # -1: erased, not checked
    with pytest.raises(ToleranceError):
        resolve(0.01, -0.5)


def test_the_controller_defaults_are_franka_s_none_set():
    tol = default_tolerances(7)
    assert np.all(tol.path.position == 0) and np.all(tol.path.velocity == 0) and np.all(tol.goal.position == 0)
    np.testing.assert_array_equal(tol.goal.velocity, 0.01)      # stopped_velocity_tolerance
    assert tol.goal_time_s == 0.0                               # wait for ever


def test_a_goal_overrides_per_joint_and_a_bad_one_falls_back_to_every_default():
    defaults = default_tolerances(7, goal_time_s=0.5)
    tol, why = goal_tolerances(defaults, JOINTS, path_tolerance=[("fer_joint2", 0.05, 0.0, 0.0)],
                               goal_tolerance=[("fer_joint7", 0.001, -1.0, 0.0)], goal_time_tolerance_s=0.2)
    assert why == "" and tol.goal_time_s == 0.2
    assert tol.path.position[1] == 0.05 and tol.path.position[0] == 0.0
    assert tol.goal.position[6] == 0.001 and tol.goal.velocity[6] == 0.0 and tol.goal.velocity[0] == 0.01
    for bad in ({"path_tolerance": [("fr3_joint2", 0.05, 0.0, 0.0)]},     # a joint the controller does not have
                {"goal_tolerance": [("fer_joint1", -0.3, 0.0, 0.0)]},      # negative and not -1
                {"goal_time_tolerance_s": -2.0, "goal_tolerance": [("fer_joint1", 0.1, 0.0, 0.0)]}):
        tol, why = goal_tolerances(defaults, JOINTS, **bad)
        assert tol is defaults and why.endswith("Using default tolerances")
    assert goal_tolerances(defaults, JOINTS, goal_time_tolerance_s=-1.0)[0].goal_time_s == 0.0   # erased: for ever


def test_success_only_after_the_end_and_once_every_joint_is_slower_than_the_stopped_tolerance():
    monitor = TrajectoryMonitor(JOINTS)
    monitor.start(1.0, default_tolerances(7))
    assert monitor.check(0.5, Z, Z, Z, Z) is None                 # before the end: going on, even at rest
    moving = np.array([0, 0, 0, 0, 0, 0, 0.02])
    assert monitor.check(1.0, Z, moving, Z, Z) is None            # at the end, joint 7 still at 0.02 rad/s
    assert monitor.check(30.0, Z, moving, Z, Z) is None           # goal_time 0: it waits for ever
    verdict = monitor.check(30.001, Z, moving / 4, Z, Z)
    assert verdict.outcome == SUCCEEDED and verdict.text == SUCCESS_TEXT


def test_a_goal_tolerance_not_met_within_goal_time_after_the_end_aborts():
    monitor = TrajectoryMonitor(JOINTS)
    tol, _ = goal_tolerances(default_tolerances(7), JOINTS, goal_tolerance=[("fer_joint7", 0.01, 0.0, 0.0)],
                             goal_time_tolerance_s=0.2)
    monitor.start(1.0, tol)
    off = np.array([0, 0, 0, 0, 0, 0, 0.05])
    assert monitor.check(1.2, off, Z, Z, Z) is None               # within goal_time
    verdict = monitor.check(1.201, off, Z, Z, Z)
    assert verdict.outcome == GOAL_VIOLATED
    assert verdict.text.startswith("Aborted due to goal_time_tolerance exceeding by 0.20")
    assert "fer_joint7" in verdict.details


def test_a_path_tolerance_is_checked_while_moving_and_on_the_first_period_only():
    tol, _ = goal_tolerances(default_tolerances(7), JOINTS, path_tolerance=[("fer_joint1", 0.01, 0.5, 0.0)])
    monitor = TrajectoryMonitor(JOINTS)
    monitor.start(1.0, tol)
    assert monitor.check(0.1, Z, Z, Z + 0.005, Z) is None
    verdict = monitor.check(0.2, Z, Z, np.r_[0.02, Z[1:]], Z)
    assert (verdict.outcome, verdict.text) == (PATH_VIOLATED, PATH_TEXT)
    assert "fer_joint1: position error 0.020000 > tolerance 0.010000" in verdict.details
    monitor.start(1.0, tol)                                      # velocity: desired - measured
    assert monitor.check(0.1, Z, np.r_[0.6, Z[1:]], Z, Z).outcome == PATH_VIOLATED
    monitor.start(1.0, tol)                                      # after the end: the goal tolerance only ...
    assert monitor.check(0.1, Z, Z, Z, Z) is None
    assert monitor.check(1.5, Z, Z, np.r_[0.02, Z[1:]], Z).outcome == SUCCEEDED
    monitor.start(0.0, tol)                                      # ... but the first period is always checked
    assert monitor.check(0.0, Z, Z, np.r_[0.02, Z[1:]], Z).outcome == PATH_VIOLATED


def test_a_holding_monitor_checks_nothing():
    monitor = TrajectoryMonitor(JOINTS)
    assert monitor.check(5.0, Z, Z + 1, Z, Z) is None
    monitor.start(1.0, default_tolerances(7))
    monitor.hold()
    assert not monitor.running and monitor.check(5.0, Z, Z + 1, Z, Z) is None

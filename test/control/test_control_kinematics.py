"""Pinocchio kinematics: FK against PyBullet, IK/FK round trips, clear failures."""
import math

import numpy as np
import pybullet as p
import pytest

from defgg_ros.constants import PANDA_TCP_OFFSET_M
from defgg_ros.control.kinematics import (
    IKError,
    KinematicsError,
    PandaKinematics,
    WorkspaceError,
    check_workspace,
    panda_urdf_path,
)
from defgg_ros.control.poses import (
    PoseError,
    matrix_to_quaternion,
    pose_matrix,
    quaternion_to_matrix,
    top_down_pose,
    top_down_yaw,
)

PYBULLET_LINK8 = 7  # link index of panda_link8 in PyBullet's panda.urdf (joints 0..6 are the arm)


@pytest.fixture(scope="module")
def kin():
    return PandaKinematics()


@pytest.fixture(scope="module")
def bullet():
    client = p.connect(p.DIRECT)
    robot = p.loadURDF(str(panda_urdf_path()), useFixedBase=True, physicsClientId=client)
    yield client, robot
    p.disconnect(client)


def random_configurations(kin, n, seed):
    rng = np.random.default_rng(seed)
    # Stay a little inside the limits so the IK's clamping is not what decides.
    margin = 0.1
    return rng.uniform(kin.q_min_rad + margin, kin.q_max_rad - margin, size=(n, 7))


def test_tcp_matches_pybullet_flange_plus_offset(kin, bullet):
    client, robot = bullet
    for q in random_configurations(kin, 10, seed=1):
        for joint, value in enumerate(q):
            p.resetJointState(robot, joint, value, physicsClientId=client)
        state = p.getLinkState(robot, PYBULLET_LINK8, computeForwardKinematics=True, physicsClientId=client)
        flange_R = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        expected_p = np.array(state[4]) + flange_R[:, 2] * PANDA_TCP_OFFSET_M
        tcp = kin.fk(q)
        assert tcp[:3, 3] == pytest.approx(expected_p, abs=1e-5)
        # Same approach axis; hand turned -45 deg about it.
        assert tcp[:3, 2] == pytest.approx(flange_R[:, 2], abs=1e-5)
        assert tcp[:3, 0] @ flange_R[:, 0] == pytest.approx(math.cos(math.pi / 4), abs=1e-5)


def test_ik_fk_round_trip_on_random_reachable_poses(kin):
    for q_true in random_configurations(kin, 25, seed=2):
        target = kin.fk(q_true)
        result = kin.ik(target, kin.q_ready_rad)
        reached = kin.fk(result.q_rad)
        assert reached[:3, 3] == pytest.approx(target[:3, 3], abs=1e-4)
        assert np.abs(reached[:3, :3] - target[:3, :3]).max() < 1e-3
        assert kin.within_limits(result.q_rad)


def test_top_down_ik_picks_the_symmetric_yaw_nearer_the_seed(kin):
    result, yaw = kin.top_down_ik([0.5, 0.0, 0.1], math.pi - 0.1)
    assert yaw in (pytest.approx(math.pi - 0.1), pytest.approx(-0.1))
    tcp = kin.fk(result.q_rad)
    assert tcp[:3, 2] == pytest.approx([0, 0, -1], abs=1e-4)
    # The ready pose has the fingers along base x, so yaw -0.1 is the short turn.
    assert yaw == pytest.approx(-0.1)


def test_unreachable_pose_raises_ik_error_with_residual(kin):
    with pytest.raises(IKError) as info:
        kin.ik(top_down_pose([1.5, 0.0, 0.2], 0.0), restarts=2)
    assert info.value.residual_m > 0.3
    assert "best residual" in str(info.value)


@pytest.mark.parametrize("bad_q", [np.zeros(6), np.full(7, np.nan)])
def test_bad_joint_vectors_are_rejected(kin, bad_q):
    with pytest.raises(KinematicsError):
        kin.fk(bad_q)


@pytest.mark.parametrize("position, message", [
    ([0.5, 0.0, -0.01], "below the table"),
    ([0.9, 0.0, 0.02], "beyond the Panda's reach"),
    ([0.1, 0.0, 0.1], "too close"),
])
def test_workspace_check(position, message):
    with pytest.raises(WorkspaceError, match=message):
        check_workspace(position, table_z_m=0.0)
    check_workspace([0.5, 0.1, 0.05], table_z_m=0.0)


def test_quaternion_rejects_in_the_control_error_type():
    # the conversion itself: test/foundation/test_rotations.py
    q = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    assert matrix_to_quaternion(quaternion_to_matrix(q)) == pytest.approx(q)
    with pytest.raises(PoseError, match="unit norm"):
        quaternion_to_matrix([0, 0, 0, 2.0])
    with pytest.raises(PoseError, match="non-finite"):
        pose_matrix([0, float("inf"), 0], [0, 0, 0, 1])


def test_top_down_yaw_round_trip_and_tilt_rejection():
    assert top_down_yaw(top_down_pose([0.4, 0, 0.1], 0.7)) == pytest.approx(0.7)
    tilted = pose_matrix([0.4, 0, 0.1], [1.0, 0.0, 0.0, 0.0]) @ pose_matrix([0, 0, 0], [0.0, 0.2588, 0.0, 0.9659])
    with pytest.raises(PoseError, match="tilted"):
        top_down_yaw(tilted)


def test_ik_answer_does_not_depend_on_earlier_solves():
    # Poses the ready-pose seed does not reach, so the random restarts decide the solution: a solver that has
    # solved other poses before must give the same joints as a fresh one (an executor's plan for a goal must
    # not depend on the goals before it).
    fresh, used = PandaKinematics(), PandaKinematics()
    targets = [fresh.fk(q) for q in random_configurations(fresh, 40, seed=5)]
    needing_restarts = []
    for target in targets:
        try:
            fresh.ik(target, restarts=0)
        except IKError:
            needing_restarts.append(target)
    assert len(needing_restarts) >= 3
    expected = [PandaKinematics().ik(t).q_rad for t in needing_restarts]
    for _ in range(2):   # history: every pose once more, in reverse order
        for target, q in reversed(list(zip(needing_restarts, expected))):
            assert used.ik(target).q_rad == pytest.approx(q, abs=1e-12)

"""The TCP frame's x axis is the direction the Panda's fingers really close along.

Grasps are "close along x" everywhere (Grasp.pose_base, top_down_pose); the fingers slide along the
hand's y axis in the URDF. Checked on the URDF itself in PyBullet, at IK solutions of top-down poses.
"""
import math

import numpy as np
import pybullet as p
import pytest

from defgg_ros.constants import PANDA_JOINT_NAMES
from defgg_ros.control.kinematics import PandaKinematics, panda_urdf_path
from defgg_ros.control.poses import top_down_pose


@pytest.fixture(scope="module")
def panda():
    client = p.connect(p.DIRECT)
    robot = p.loadURDF(str(panda_urdf_path()), useFixedBase=True, physicsClientId=client)
    joints = {p.getJointInfo(robot, j, physicsClientId=client)[1].decode(): j
              for j in range(p.getNumJoints(robot, physicsClientId=client))}
    links = {p.getJointInfo(robot, j, physicsClientId=client)[12].decode(): j for j in joints.values()}
    yield client, robot, joints, links
    p.disconnect(client)


@pytest.mark.parametrize("yaw_rad", [0.0, 0.5, -1.2, math.pi / 2])
def test_fingers_close_along_the_tcp_x_axis(panda, yaw_rad):
    client, robot, joints, links = panda
    kinematics = PandaKinematics()
    q = kinematics.ik(top_down_pose([0.5, 0.1, 0.1], yaw_rad)).q_rad
    for name, value in zip(PANDA_JOINT_NAMES, q):
        p.resetJointState(robot, joints[name], float(value), physicsClientId=client)
    for name in ("panda_finger_joint1", "panda_finger_joint2"):
        p.resetJointState(robot, joints[name], 0.03, physicsClientId=client)
    left, right = (np.array(p.getLinkState(robot, links[n], physicsClientId=client)[4])
                   for n in ("panda_leftfinger", "panda_rightfinger"))
    between = (left - right) / np.linalg.norm(left - right)
    closing = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    assert abs(float(between @ closing)) == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(kinematics.fk(q)[:3, 0] @ closing, 1.0, atol=1e-6)

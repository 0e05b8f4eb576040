"""A floating Franka Hand built from boxes with the real hand's dimensions.

Hand frame: origin at the TCP (between the finger pads), x along the
closing direction, z up. The palm is a dynamic body held by a fixed
constraint whose target we move (lift, twist); the two fingers are
prismatic links, q = distance of each pad from the TCP (0..0.04 m).
The real hand couples its fingers mechanically; PyBullet ignores URDF
<mimic>, and without coupling fingers and object slid sideways together
(FEM notes), so a JOINT_GEAR constraint keeps q1 = q2.
Fingers are light (5 g) so the shake test's fictitious forces on them
(m * 50 m/s^2 = 0.25 N) barely change the grasp force, as on the real,
non-backdrivable hand.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pybullet as p

from defgg_ros.constants import (
    FINGER_PAD_WIDTH_M,
    GRIPPER_MAX_WIDTH_M,
    PANDA_FINGER_LENGTH_M,
    PANDA_FINGER_THICKNESS_M,
    PANDA_FINGERTIP_BELOW_TCP_M,
    PANDA_HAND_PALM_SIZE_M,
)
from defgg_ros.sim import physics
from defgg_ros.sim.finger_press import PressingClose
from defgg_ros.sim.physics import DEFAULT_FRICTION

PALM_MASS_KG = 0.5
FINGER_MASS_KG = 0.005
FINGER_FRICTION = DEFAULT_FRICTION
HOLD_FORCE_N = 2000.0     # constraint force holding the palm at its target
GEAR_FORCE_N = 500.0
# Finger lock (DefGraspSim's protocol locks both finger joints after pickup). With the gear kept and a
# weak drive the soft squeeze leaked to ~10 % of F/2 in a PyBullet pilot; each finger on its own stiff
# position drive (gear released) kept ~60 %. Measured again by bench/bench_finger_lock.py.
LOCK_FORCE_N = 500.0
LOCK_POSITION_GAIN = 1.0


def speed_drive_ceiling_n(time_step_s: float, close_speed_mps: float) -> float:
    """The most a speed-driven finger (close(press=False)) presses an FEM body with, whatever force it is given: the
    deformable contact takes about its momentum every step (measured 0.88-1.03 N at 0.1 m/s and 0.5 ms steps, ~2 N at
    0.25 ms: bench/bench_fem_grasp_force.py part 2)."""
    return FINGER_MASS_KG * close_speed_mps / time_step_s


def finger_box_centre_z_m() -> float:
    """Height of the finger box centre above the TCP."""
    return -PANDA_FINGERTIP_BELOW_TCP_M + PANDA_FINGER_LENGTH_M / 2


def palm_centre_z_m() -> float:
    return -PANDA_FINGERTIP_BELOW_TCP_M + PANDA_FINGER_LENGTH_M + PANDA_HAND_PALM_SIZE_M[2] / 2


def hand_boxes(opening_m: float) -> list:
    """(centre xyz in the hand frame, half extents) of palm and fingers at an opening width.

    Used both to build the body and by the sampler's collision filter.
    """
    q = opening_m / 2
    t = PANDA_FINGER_THICKNESS_M
    finger_half = [t / 2, FINGER_PAD_WIDTH_M / 2, PANDA_FINGER_LENGTH_M / 2]
    return [
        ([0.0, 0.0, palm_centre_z_m()], [s / 2 for s in PANDA_HAND_PALM_SIZE_M]),
        ([q + t / 2, 0.0, finger_box_centre_z_m()], finger_half),
        ([-q - t / 2, 0.0, finger_box_centre_z_m()], finger_half),
    ]


def world_T_hand(position_m, yaw_rad) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    pose[:3, 3] = position_m
    return pose


@dataclass
class Hand:
    client: int
    body_id: int
    constraint_id: int
    gear_id: int
    # The running pressing close (close(press=True)) until the fingers are locked; None: speed-driven.
    pressing: PressingClose | None = field(default=None, repr=False)
    clock_s: float = 0.0          # sim time the pressing close has been fed (drive())

    FINGER_LINKS = (0, 1)

    def finger_opening_m(self) -> float:
        q = [p.getJointState(self.body_id, j, physicsClientId=self.client)[0] for j in self.FINGER_LINKS]
        return float(sum(q))

    def set_opening(self, opening_m: float) -> None:
        for j in self.FINGER_LINKS:
            p.resetJointState(self.body_id, j, opening_m / 2, 0.0, physicsClientId=self.client)

    def close(self, force_n: float, speed_mps: float, press: bool = False) -> None:
        """Each finger closes towards the TCP at `speed_mps` with at most `force_n`. press=False: a speed drive
        (the labels of fem_v1-v5; on an FEM body it pushes with only ~m v / dt, speed_drive_ceiling_n). press=True: the
        cell's rule (sim.finger_press): once on the object each finger pushes with `force_n`; drive() before
        every physics step applies it."""
        self._force_n, self._speed_mps = force_n, speed_mps
        self.pressing = PressingClose(speed_mps, speed_mps) if press else None
        self.clock_s, self._pushing = 0.0, [False] * len(self.FINGER_LINKS)
        for j in self.FINGER_LINKS:
            self._speed_drive(j)

    def _speed_drive(self, joint: int) -> None:
        p.setJointMotorControl2(self.body_id, joint, p.VELOCITY_CONTROL, targetVelocity=-self._speed_mps,
                                force=self._force_n, physicsClientId=self.client)

    def drive(self, step_s: float) -> None:
        """A pressing close's drive for the next step (nothing for a speed drive or locked fingers)."""
        if self.pressing is None:
            return
        q = [p.getJointState(self.body_id, j, physicsClientId=self.client)[0] for j in self.FINGER_LINKS]
        self._pushing = self.pressing.update(self.clock_s, q, step_s)
        for j, push in zip(self.FINGER_LINKS, self._pushing):
            if push:
                p.setJointMotorControl2(self.body_id, j, p.VELOCITY_CONTROL, force=0.0, physicsClientId=self.client)
                p.setJointMotorControl2(self.body_id, j, p.TORQUE_CONTROL, force=-self._force_n,
                                        physicsClientId=self.client)
            else:
                self._speed_drive(j)
        self.clock_s += step_s

    def finger_forces_n(self) -> list:
        """Force each finger's motor applies now (N, positive = closing); a pushing finger's is the force it was
        given (PyBullet reports no torque-controlled motor's force)."""
        pushing = self._pushing if self.pressing is not None else [False] * len(self.FINGER_LINKS)
        return [self._force_n if push else -p.getJointState(self.body_id, j, physicsClientId=self.client)[3]
                for j, push in zip(self.FINGER_LINKS, pushing)]

    def lock_fingers(self) -> None:
        """Lock both fingers where they are: gear released, each on a stiff position drive."""
        self.pressing = None
        if self.gear_id is not None:
            p.removeConstraint(self.gear_id, physicsClientId=self.client)
            self.gear_id = None
        for j in self.FINGER_LINKS:
            q = p.getJointState(self.body_id, j, physicsClientId=self.client)[0]
            p.setJointMotorControl2(self.body_id, j, p.POSITION_CONTROL, targetPosition=q, targetVelocity=0.0,
                                    positionGain=LOCK_POSITION_GAIN, velocityGain=1.0, force=LOCK_FORCE_N,
                                    physicsClientId=self.client)

    def move_to(self, pose: np.ndarray) -> None:
        """Move the palm's target pose (the constraint pulls the palm there)."""
        yaw = math.atan2(pose[1, 0], pose[0, 0])
        quat = p.getQuaternionFromEuler([0, 0, yaw]) if np.allclose(pose[2, :3], [0, 0, 1]) else _quat(pose)
        p.changeConstraint(self.constraint_id, pose[:3, 3].tolist(), quat, maxForce=HOLD_FORCE_N,
                           physicsClientId=self.client)

    def reset_pose(self, pose: np.ndarray) -> None:
        p.resetBasePositionAndOrientation(self.body_id, pose[:3, 3].tolist(), _quat(pose),
                                          physicsClientId=self.client)
        p.resetBaseVelocity(self.body_id, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        self.move_to(pose)

    def pose(self) -> np.ndarray:
        pos, orn = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self.client)
        out = np.eye(4)
        out[:3, :3] = np.reshape(p.getMatrixFromQuaternion(orn), (3, 3))
        out[:3, 3] = pos
        return out

    def finger_contacts(self, body_id: int) -> list:
        """Number of contact points of each finger with `body_id`."""
        return [len(p.getContactPoints(body_id, self.body_id, -1, link, physicsClientId=self.client))
                for link in self.FINGER_LINKS]

    def save_state(self) -> dict:
        q = [p.getJointState(self.body_id, j, physicsClientId=self.client)[0] for j in self.FINGER_LINKS]
        return {"pose": self.pose(), "q": q}

    def restore_state(self, state: dict) -> None:
        self.reset_pose(state["pose"])
        if self.pressing is not None:
            self.pressing.restart_window()
        for j, q in zip(self.FINGER_LINKS, state["q"]):
            p.resetJointState(self.body_id, j, q, 0.0, physicsClientId=self.client)


def _quat(pose):
    # rotation matrix -> quaternion (x, y, z, w), robust branch on the trace. Not defgg_ros.rotations on
    # purpose: that one normalises and turns w >= 0, and the trials' numbers depend on these last bits
    # (4 fem_v5 trials re-run with it: 3 of 64 shake directions moved by 0.5 m/s²).
    m = pose[:3, :3]
    tr = np.trace(m)
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    i = int(np.argmax(np.diag(m)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k]) * 2
    q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    return q


def create_hand(client: int, world_T_tcp: np.ndarray, opening_m: float = GRIPPER_MAX_WIDTH_M,
                friction: float = FINGER_FRICTION) -> Hand:
    """Create the floating hand with its TCP at `world_T_tcp`, fingers open to `opening_m`; `friction` is
    the pads' own coefficient (Bullet multiplies it by the object's)."""
    if not 0.0 <= opening_m <= GRIPPER_MAX_WIDTH_M + 1e-9:
        raise ValueError(f"opening {opening_m} m outside [0, {GRIPPER_MAX_WIDTH_M}]")
    (palm_c, palm_h), (f1_c, f_h), _ = hand_boxes(0.0)
    t = PANDA_FINGER_THICKNESS_M

    def cid(half, offset=(0, 0, 0)):
        return p.createCollisionShape(p.GEOM_BOX, halfExtents=half, collisionFramePosition=offset,
                                      physicsClientId=client)

    def vid(half, offset=(0, 0, 0)):
        return p.createVisualShape(p.GEOM_BOX, halfExtents=half, visualFramePosition=offset,
                                   rgbaColor=[0.9, 0.9, 0.9, 1], physicsClientId=client)

    # Each finger's box sits half a thickness outwards of its joint position (the pad face).
    offsets = ([t / 2, 0, f1_c[2]], [-t / 2, 0, f1_c[2]])
    body = p.createMultiBody(
        baseMass=PALM_MASS_KG, baseCollisionShapeIndex=cid(palm_h, palm_c),
        baseVisualShapeIndex=vid(palm_h, palm_c),
        basePosition=world_T_tcp[:3, 3].tolist(), baseOrientation=_quat(world_T_tcp),
        baseInertialFramePosition=[0, 0, 0],
        linkMasses=[FINGER_MASS_KG] * 2, linkCollisionShapeIndices=[cid(f_h, o) for o in offsets],
        linkVisualShapeIndices=[vid(f_h, o) for o in offsets], linkPositions=[[0, 0, 0]] * 2,
        linkOrientations=[[0, 0, 0, 1]] * 2,
        linkInertialFramePositions=list(offsets),
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * 2, linkParentIndices=[0, 0],
        linkJointTypes=[p.JOINT_PRISMATIC] * 2, linkJointAxis=[[1, 0, 0], [-1, 0, 0]],
        physicsClientId=client)
    for link in (-1, 0, 1):
        p.changeDynamics(body, link, lateralFriction=friction, jointLowerLimit=0.0,
                         jointUpperLimit=GRIPPER_MAX_WIDTH_M / 2, physicsClientId=client)
    hold = p.createConstraint(body, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0], [0, 0, 0],
                              world_T_tcp[:3, 3].tolist(), childFrameOrientation=_quat(world_T_tcp),
                              physicsClientId=client)
    gear = physics.couple_fingers(client, body, 0, 1, GEAR_FORCE_N, erp=0.2)
    hand = Hand(client, body, hold, gear)
    hand.move_to(world_T_tcp)
    hand.set_opening(opening_m)
    for j in Hand.FINGER_LINKS:  # hold the opening until close() is called
        p.setJointMotorControl2(body, j, p.POSITION_CONTROL, targetPosition=opening_m / 2, force=50.0,
                                physicsClientId=client)
    return hand


"""The simulated Panda cell: arm, hand, table, bin, objects and depth camera in PyBullet.

This is the pure core of the fake driver (no rclpy): the node only moves
commands in and states out. The world is a deformable one when the scene has
soft objects (FEM settings from the FEM notes / `defgg_ros.sim`), otherwise a
plain rigid world with a larger step. Sim time advances only in `advance()`.

Frames: the world origin is `panda_link0`; the table top is z = 0.
"""
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pybullet as p
import pybullet_data

from defgg_ros.constants import (
    FRANKA_JTC_GAINS_PD,
    GRIPPER_MAX_WIDTH_M,
    OFF_TABLE_DEPTH_M,
    PANDA_FINGER_JOINT_NAMES,
    PANDA_JOINT_NAMES,
    PANDA_READY_Q_RAD,
    PANDA_TCP_OFFSET_M,
)
from defgg_ros.sim import physics
from defgg_ros.sim.cell import objects as cell_objects
from defgg_ros.sim.cell import soft as cell_soft
from defgg_ros.sim.cell.camera import DepthCamera, DepthNoise, camera_matrix
from defgg_ros.sim.cell.gripper import GRIPPER_MAX_SPEED_MPS, GripperController, GripperOutcome
from defgg_ros.sim.cell.trajectory import TrajectoryTracker, make_waypoints
from defgg_ros.sim.finger_press import FingerSpeeds, finger_pushes
from defgg_ros.sim.scene_spec import SceneSpec

# Rigid-only scenes: 1 ms keeps 70 N finger contacts calm and runs faster than real time.
RIGID_TIME_STEP_S = 1e-3
# Joint torque limits of the Panda (Franka datasheet), N*m; fingers: N.
ARM_MAX_TORQUE_NM = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
# How the arm follows its trajectory (CellSettings.arm_drive; docs/franka_contract.md, "How the arm follows it"):
# "position_motor", the cell's: PyBullet's position motor, gains tuned so the arm tracks a Ruckig trajectory within
# ~1 mrad at 1 ms steps; it holds the hand 10-30x stiffer than a real arm's controller (bench_hand_stiffness.py).
# "franka_jtc": as franka_bringup's <robot_type>_arm_controller drives a real arm, joint torques of its PID
# (FRANKA_JTC_GAINS_PD) plus the robot's gravity compensation, capped at the datasheet's torques; it lags and rings
# as the real one would, and the executor's stop tests do not pass on it yet (2026-12-03).
ARM_DRIVES = ("position_motor", "franka_jtc")
ARM_POSITION_GAIN = 0.3
ARM_VELOCITY_GAIN = 1.0
ARM_KP_NM_PER_RAD = tuple(p_gain for p_gain, _ in FRANKA_JTC_GAINS_PD)
ARM_KD_NMS_PER_RAD = tuple(d_gain for _, d_gain in FRANKA_JTC_GAINS_PD)
FINGER_POSITION_GAIN = 0.2
# A pressing finger that closed faster than the hand can (franka_gripper's top speed, per finger) over the last
# finger_press.PRESS_SPEED_WINDOW_S has lost the object: speed-limited again (finger_press.finger_pushes). From
# positions over a window: the deformable contact leaves a pressed finger's joint velocity meaningless and its
# position jitters.
PRESS_SPEED_LIMIT_MPS = GRIPPER_MAX_SPEED_MPS / 2
# Viscous damping of each finger joint (N s/m), as a force-controlled hand's drive has. Without it a pressed finger
# rang on the 2e5 Pa FEM ball: grasps took up to 3.58 s to stop and 2 of 6 at 1.5-2 N timed out (5 s); with it they
# stopped in 0.19-0.22 s, steps 0.58-0.64 mm (bench/bench_fem_grasp_force.py --forces 1 --no-trials --ringing).
# 30 is near critical for a finger (0.1 kg) on such a contact (~2 kN/m).
FINGER_JOINT_DAMPING_NSPM = 30.0
# Links whose contacts make up the external wrench: hand and both fingers.
HAND_LINK_NAMES = ("panda_hand", "panda_leftfinger", "panda_rightfinger")
TCP_LINK_NAME = "panda_grasptarget"   # pybullet_data's panda.urdf: 0.105 m along panda_hand's z
# franka_description's <robot_type>_hand_tcp (franka_hand.xacro: tcp_xyz 0 0 0.1034 from the hand, the hand at
# -45 deg about link8's z): libfranka's EE with the Franka Hand, current_pose and the wrench's reference point K.
HAND_LINK_NAME = "panda_hand"
# Objects settle this long on the table before the cell starts.
SETTLE_TIME_S = 0.3
# How often (sim time) soft objects are woken up / put to sleep.
SOFT_ACTIVITY_PERIOD_S = 0.05


@dataclass
class CellSettings:
    time_step_s: float | None = None     # None: chosen from the scene (softest object)
    depth_noise: DepthNoise = field(default_factory=DepthNoise)
    seed: int = 0
    gui: bool = False
    initial_q_rad: tuple = PANDA_READY_Q_RAD
    # False: soft objects sleep as static meshes until the hand comes near
    # (see cell_soft); True: always FEM (for benchmarks and render checks).
    soft_always_active: bool = False
    arm_drive: str = "position_motor"    # one of ARM_DRIVES


@dataclass(frozen=True)
class JointState:
    names: tuple
    positions: np.ndarray
    velocities: np.ndarray
    efforts: np.ndarray


class SimCell:
    """A Panda cell in its own PyBullet client."""

    def __init__(self, scene: SceneSpec, settings: CellSettings | None = None):
        self.scene = scene
        self.settings = settings or CellSettings()
        if self.settings.arm_drive not in ARM_DRIVES:
            raise ValueError(f"arm_drive must be one of {', '.join(ARM_DRIVES)}, got {self.settings.arm_drive!r}")
        self._torque_driven = self.settings.arm_drive == "franka_jtc"
        self.time_s = 0.0
        self._steps = 0                     # physics steps taken: what the joint state memo is keyed by
        self._joint_state_memo = (None, None)
        self._wall_per_sim = []
        self._gripper_token = 0
        self._pending_token = None
        self._outcomes = []
        self._next_activity_check_s = 0.0
        self._scratch = Path(tempfile.mkdtemp(prefix="defgg_cell_"))
        self.client = p.connect(p.GUI if self.settings.gui else p.DIRECT)
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    # ---- construction -------------------------------------------------
    def _build(self):
        c = self.client
        self.time_step_s = self._time_step_s()
        cell_objects.reset_world(c, deformable=self.scene.has_soft_objects, time_step_s=self.time_step_s)
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=c)
        self.robot = p.loadURDF("franka_panda/panda.urdf", [0, 0, 0], useFixedBase=True,
                                flags=p.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT, physicsClientId=c)
        self._index_joints()
        self.table_id = cell_objects.add_table(c, self.scene)
        self.bin_ids = cell_objects.add_bin(c, self.scene.bin) if self.scene.bin else []
        self._rigid = {i: cell_objects.add_rigid_object(c, spec)
                       for i, spec in enumerate(self.scene.objects) if not spec.is_soft}
        self._soft = {i: cell_soft.spawn_dormant(c, spec, self._scratch)
                      for i, spec in enumerate(self.scene.objects) if spec.is_soft}
        if self.settings.soft_always_active:
            for obj in self._soft.values():
                cell_soft.activate(c, obj)
            self._set_time_step()
        self._set_initial_state()
        self.camera = DepthCamera(c, self.scene.base_xyz_camera_m, self.scene.base_quat_camera_xyzw,
                                  self.settings.depth_noise, self.settings.seed)
        self.camera_k = camera_matrix()
        # Let objects come to rest on the table under the arm's hold.
        self.advance(SETTLE_TIME_S)
        self.time_s = 0.0

    def _index_joints(self):
        by_name, link_by_name = {}, {}
        for j in range(p.getNumJoints(self.robot, physicsClientId=self.client)):
            info = p.getJointInfo(self.robot, j, physicsClientId=self.client)
            by_name[info[1].decode()] = j
            link_by_name[info[12].decode()] = j
        self.arm_joints = [by_name[n] for n in PANDA_JOINT_NAMES]
        self.finger_joints = [by_name[n] for n in PANDA_FINGER_JOINT_NAMES]
        self._movable_joints = self.arm_joints + self.finger_joints   # calculateInverseDynamics wants every DoF
        self._zero_dof = [0.0] * len(self._movable_joints)
        self.hand_links = [link_by_name[n] for n in HAND_LINK_NAMES]
        self.tcp_link = link_by_name[TCP_LINK_NAME]
        self.hand_link = link_by_name[HAND_LINK_NAME]

    def _set_initial_state(self):
        c = self.client
        q0 = np.asarray(self.settings.initial_q_rad, dtype=float)
        for j, q in zip(self.arm_joints, q0):
            p.resetJointState(self.robot, j, q, 0.0, physicsClientId=c)
        if self._torque_driven:   # _drive_arm: PyBullet's default velocity motor on each joint would brake it
            p.setJointMotorControlArray(self.robot, self.arm_joints, p.VELOCITY_CONTROL, forces=[0.0] * 7,
                                        physicsClientId=c)
        for j in self.finger_joints:
            p.resetJointState(self.robot, j, GRIPPER_MAX_WIDTH_M / 2, 0.0, physicsClientId=c)
        self._joint_state_memo = (None, None)
        physics.couple_fingers(c, self.robot, self.finger_joints[0], self.finger_joints[1], max_force_n=200,
                               erp=0.1)
        physics.set_friction(c, self.robot, self.finger_joints, cell_objects.MATERIAL.finger_friction)
        for j in self.finger_joints:
            p.changeDynamics(self.robot, j, jointDamping=FINGER_JOINT_DAMPING_NSPM, physicsClientId=c)
        self.tracker = TrajectoryTracker(q0)
        self.gripper = GripperController(GRIPPER_MAX_WIDTH_M)
        self._finger_speeds = FingerSpeeds()

    def close(self):
        if self.client is not None and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = None
        shutil.rmtree(self._scratch, ignore_errors=True)

    # ---- objects ----------------------------------------------------------
    @property
    def object_ids(self) -> list:
        """Current PyBullet body id of every scene object, in scene order."""
        return [self._rigid[i] if i in self._rigid else self._soft[i].body for i in range(len(self.scene.objects))]

    def active_soft_objects(self) -> list:
        """Names of the soft objects simulated as FEM bodies right now."""
        return [o.spec.name for o in self._soft.values() if o.active]

    def _time_step_s(self) -> float:
        if self.settings.time_step_s:
            return self.settings.time_step_s
        active = [o.spec.youngs_modulus_pa for o in getattr(self, "_soft", {}).values() if o.active]
        return min((cell_objects.soft_time_step_s(e) for e in active), default=RIGID_TIME_STEP_S)

    def _set_time_step(self):
        self.time_step_s = self._time_step_s()
        p.setTimeStep(self.time_step_s, physicsClientId=self.client)

    def _update_soft_activity(self):
        if self.settings.soft_always_active or not self._soft or self.time_s < self._next_activity_check_s:
            return
        self._next_activity_check_s = self.time_s + SOFT_ACTIVITY_PERIOD_S
        tcp, _ = self.tcp_pose()
        if cell_soft.update_activity(self.client, list(self._soft.values()), self.robot, tcp, self._scratch):
            self._set_time_step()

    # ---- commands -------------------------------------------------------
    def command_trajectory(self, points, start_time_s: float | None = None) -> None:
        """Replace the active trajectory; points: (t_s, q, qd|None, qdd|None), panda_joint1..7 order.

        Times count from start_time_s (sim time; default now). Raises
        TrajectoryError on malformed points (the current motion goes on). A trajectory whose first point is still
        ahead blends into it from the measured position and velocity now, as the joint_trajectory_controller does.
        """
        waypoints = make_waypoints(points, len(self.arm_joints))
        start_s = self.time_s if start_time_s is None else float(start_time_s)
        states = p.getJointStates(self.robot, self.arm_joints, physicsClientId=self.client)
        self.tracker.replace(waypoints, start_s, np.array([s[0] for s in states]), np.array([s[1] for s in states]),
                             now_s=self.time_s)

    def gripper_move(self, width_m: float, speed_mps: float) -> int:
        """Start a move; returns a token whose outcome `advance` reports later."""
        return self._start_gripper(lambda: self.gripper.start_move(width_m, speed_mps, self.time_s))

    def gripper_stop(self) -> None:
        """Cancel the running gripper command as franka_gripper does: stopped, no force held. The command it stops
        ends failed ("stopped"), whichever goal started it (a stop also ends a goal that preempted the canceled one,
        as on the real hand)."""
        if self.gripper.busy and self._pending_token is not None:
            self._end_gripper_command(self._pending_token, "stopped")
            self._pending_token = None
        self.gripper.stop()

    def gripper_grasp(self, width_m, eps_inner_m, eps_outer_m, speed_mps, force_n) -> int:
        return self._start_gripper(lambda: self.gripper.start_grasp(
            width_m, eps_inner_m, eps_outer_m, speed_mps, force_n, self.time_s))

    def _start_gripper(self, start) -> int:
        previous = self._pending_token if self.gripper.busy else None
        start()  # raises GripperCommandError before anything changes
        if previous is not None:   # a new command replaces the running one, as on the real hand
            self._end_gripper_command(previous, "preempted by a newer gripper command")
        self._gripper_token += 1
        self._pending_token = self._gripper_token
        return self._gripper_token

    def _end_gripper_command(self, token: int, why: str) -> None:
        """The command of `token` ends failed, reported by the next advance()."""
        self._outcomes.append((token, GripperOutcome(False, self.gripper_width_m(), why)))

    # ---- simulation -------------------------------------------------------
    def advance(self, duration_s: float) -> list:
        """Step for duration_s of sim time; returns finished gripper commands [(token, GripperOutcome)]."""
        wall0, sim0 = time.perf_counter(), self.time_s
        end_s = self.time_s + duration_s - 0.5 * self.time_step_s
        while self.time_s < end_s:
            self._update_soft_activity()
            self._step()
        self._wall_per_sim.append((time.perf_counter() - wall0, self.time_s - sim0))
        self._wall_per_sim = self._wall_per_sim[-200:]
        done, self._outcomes = self._outcomes, []
        return done

    def _step(self):
        c = self.client
        q_des, qd_des = self.tracker.sample(self.time_s)
        if self._torque_driven:
            self._drive_arm(q_des, qd_des)
        else:
            p.setJointMotorControlArray(self.robot, self.arm_joints, p.POSITION_CONTROL, targetPositions=q_des,
                                        targetVelocities=qd_des, forces=ARM_MAX_TORQUE_NM,
                                        positionGains=[ARM_POSITION_GAIN] * 7, velocityGains=[ARM_VELOCITY_GAIN] * 7,
                                        physicsClientId=c)
        self._drive_fingers(self.gripper.motor)
        p.stepSimulation(physicsClientId=c)
        self.time_s += self.time_step_s
        self._steps += 1
        outcome = self.gripper.update(self.time_s, self.gripper_width_m())
        if outcome is not None and self._pending_token is not None:
            self._outcomes.append((self._pending_token, outcome))
            self._pending_token = None

    def _drive_arm(self, q_des, qd_des) -> None:
        """arm_drive "franka_jtc", this step's torques: p * (q_des - q) + d * (qd_des - qd) per joint (ros2_controllers'
        JTC on the effort interface, no feed-forward) plus gravity at q (the robot's own compensation; a Franka does not
        compensate Coriolis either), capped at ARM_MAX_TORQUE_NM. Plain floats: this runs every physics step."""
        c = self.client
        states = p.getJointStates(self.robot, self._movable_joints, physicsClientId=c)
        q = [s[0] for s in states]
        gravity = p.calculateInverseDynamics(self.robot, q, self._zero_dof, self._zero_dof, physicsClientId=c)
        torques = []
        for i in range(7):
            tau = (ARM_KP_NM_PER_RAD[i] * (float(q_des[i]) - q[i])
                   + ARM_KD_NMS_PER_RAD[i] * (float(qd_des[i]) - states[i][1]) + gravity[i])
            limit = ARM_MAX_TORQUE_NM[i]
            torques.append(-limit if tau < -limit else limit if tau > limit else tau)
        p.setJointMotorControlArray(self.robot, self.arm_joints, p.TORQUE_CONTROL, forces=torques, physicsClientId=c)

    def _drive_fingers(self, motor) -> None:
        """Speed-limited position drive; on the object (motor.press) a force of finger_force_n per finger while
        the finger closes no faster than the hand can (PRESS_SPEED_LIMIT_MPS). The deformable contact takes a
        speed-driven finger's momentum each step, so such a drive pressed an FEM body with ~2 N at 0.02 m/s whatever
        force was asked (measured: docs/real_cell.md, "Grasp force on FEM objects"); a rigid body got the force
        either way."""
        c = self.client
        q = [p.getJointState(self.robot, j, physicsClientId=c)[0] for j in self.finger_joints]
        closing_mps = self._finger_speeds.update(self.time_s, q, self.time_step_s)
        for j, speed_mps in zip(self.finger_joints, closing_mps):
            if finger_pushes(motor.press, speed_mps, PRESS_SPEED_LIMIT_MPS):
                p.setJointMotorControl2(self.robot, j, p.VELOCITY_CONTROL, force=0.0, physicsClientId=c)
                p.setJointMotorControl2(self.robot, j, p.TORQUE_CONTROL, force=-motor.finger_force_n,
                                        physicsClientId=c)
            else:
                p.setJointMotorControl2(self.robot, j, p.POSITION_CONTROL, targetPosition=motor.finger_target_m,
                                        force=motor.finger_force_n, maxVelocity=motor.finger_speed_mps,
                                        positionGain=FINGER_POSITION_GAIN, physicsClientId=c)

    def moving(self, time_s: float | None = None) -> bool:
        """Is a trajectory or a gripper command running?"""
        return self.tracker.is_active(self.time_s if time_s is None else time_s) or self.gripper.busy

    def real_time_factor(self) -> float:
        """Sim seconds per wall second over the recent advance() calls."""
        wall = sum(w for w, _ in self._wall_per_sim)
        sim = sum(s for _, s in self._wall_per_sim)
        return sim / wall if wall > 0 else float("inf")

    # ---- state ------------------------------------------------------------
    def arm_positions(self) -> np.ndarray:
        states = p.getJointStates(self.robot, self.arm_joints, physicsClientId=self.client)
        return np.array([s[0] for s in states])

    def gripper_width_m(self) -> float:
        states = p.getJointStates(self.robot, self.finger_joints, physicsClientId=self.client)
        return float(states[0][0] + states[1][0])

    def joint_state(self) -> JointState:
        """The arm's and fingers' measured state (read-only arrays, one reading per physics step: the driver's
        publication and the controller's check of a period share it)."""
        steps, memo = self._joint_state_memo
        if steps != self._steps:
            memo = self._read_joint_state()
            self._joint_state_memo = (self._steps, memo)
        return memo

    def _read_joint_state(self) -> JointState:
        joints = self.arm_joints + self.finger_joints
        states = p.getJointStates(self.robot, joints, physicsClientId=self.client)
        arrays = [np.array([s[i] for s in states]) for i in (0, 1, 3)]
        for array in arrays:
            array.flags.writeable = False   # shared by every reader of this step
        return JointState(PANDA_JOINT_NAMES + PANDA_FINGER_JOINT_NAMES, *arrays)

    def tcp_pose(self):
        """(position xyz, quaternion xyzw) of the TCP link in the base frame."""
        state = p.getLinkState(self.robot, self.tcp_link, computeForwardKinematics=True,
                               physicsClientId=self.client)
        return np.array(state[4]), np.array(state[5])

    def hand_tcp_pose(self):
        """(position xyz, quaternion xyzw) of franka_description's hand TCP in the base frame: PANDA_TCP_OFFSET_M
        (0.1034 m) along the hand's z, the hand's orientation (franka_robot_state_broadcaster's current_pose)."""
        state = p.getLinkState(self.robot, self.hand_link, computeForwardKinematics=True,
                               physicsClientId=self.client)
        rotation = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return np.array(state[4]) + rotation[:, 2] * PANDA_TCP_OFFSET_M, np.array(state[5])

    def external_wrench(self):
        """(force N, torque N*m about the hand TCP), both in the base frame: contacts acting on hand + fingers
        (libfranka's O_F_ext_hat_K: K, the stiffness frame, is the EE frame, the hand TCP, unless set otherwise)."""
        active = [o.body for o in self._soft.values() if o.active]
        contacts = cell_objects.hand_contact_forces(self.client, self.robot, self.hand_links, active)
        if not contacts:
            return np.zeros(3), np.zeros(3)
        cx, cy, cz = (float(v) for v in self.hand_tcp_pose()[0])
        fx = fy = fz = tx = ty = tz = 0.0
        # Plain floats, once per 1 ms control period: np.cross on each contact cost ~60 us (an FEM grasp has dozens).
        for (px, py, pz), (gx, gy, gz) in contacts:
            rx, ry, rz = px - cx, py - cy, pz - cz
            fx, fy, fz = fx + gx, fy + gy, fz + gz
            tx, ty, tz = tx + ry * gz - rz * gy, ty + rz * gx - rx * gz, tz + rx * gy - ry * gx
        return np.array([fx, fy, fz]), np.array([tx, ty, tz])

    def object_poses(self) -> list:
        """[(xyz, quat_xyzw)] per scene object, in scene order (soft: node centroid, identity rotation)."""
        poses = []
        for i in range(len(self.scene.objects)):
            if i in self._rigid:
                pos, quat = p.getBasePositionAndOrientation(self._rigid[i], physicsClientId=self.client)
                poses.append((np.array(pos), np.array(quat)))
            else:
                obj = self._soft[i]
                nodes = cell_objects.soft_nodes_m(self.client, obj.body) if obj.active else obj.nodes_m
                poses.append((nodes.mean(axis=0), np.array([0.0, 0.0, 0.0, 1.0])))
        return poses

    def objects_off_the_table(self, poses: list, below_m: float = OFF_TABLE_DEPTH_M) -> list:
        """[(name, xyz)] of the objects (poses: object_poses()) more than below_m under the table top
        (z = 0): fallen off an edge, or through the top when an FEM body's simulation failed. Nothing in
        the cell brings them back."""
        return [(spec.name, xyz) for spec, (xyz, _) in zip(self.scene.objects, poses) if xyz[2] < -below_m]

    def render_depth(self, with_color: bool = False):
        """(depth_m HxW float32 NaN = invalid, object index mask int32 (-1 none), rgb or None).

        The mask holds the scene-object index (not the body id), so callers can
        match pixels to the scene's objects.
        """
        depth_m, body_mask, rgb = self.camera.render(with_color)
        object_mask = np.full(body_mask.shape, -1, dtype=np.int32)
        for i, body in enumerate(self.object_ids):
            object_mask[body_mask == body] = i
        return depth_m, object_mask, rgb

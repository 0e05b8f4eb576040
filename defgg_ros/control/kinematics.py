"""Panda arm kinematics with Pinocchio: TCP forward kinematics, IK, workspace.

The model is PyBullet's own `franka_panda/panda.urdf` (shipped with
pybullet_data, so nothing is downloaded and the fake driver simulates the
same geometry). The two finger joints are locked: only the 7 arm joints move.
A `panda_tcp` frame is added at the fingertip centre (franka_ros default TCP), with its x
axis along the fingers' closing direction (the hand's y axis; see PANDA_TCP_YAW_RAD).
Joint ranges are Franka's datasheet values from `defgg_ros.constants`, which
are tighter than the URDF's: the Panda's, or the FR3's (`arm="fr3"`: the same
kinematic structure, other joint ranges, cut for goals where its velocity bound is 0).
"""
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet_data

from defgg_ros.constants import (
    ARM_GOAL_RANGES,
    ARM_JOINT_LIMITS,
    ARM_MODELS,
    PANDA_FINGERTIP_BELOW_TCP_M,
    PANDA_JOINT_NAMES,
    PANDA_MAX_REACH_M,
    PANDA_READY_Q_RAD,
    PANDA_SHOULDER_HEIGHT_M,
    PANDA_TCP_OFFSET_M,
    PANDA_TCP_YAW_RAD,
    TABLE_CLEARANCE_M,
)
from defgg_ros.control.poses import PoseError, top_down_pose, wrap_angle

TCP_FRAME = "panda_tcp"
FLANGE_FRAME = "panda_link8"
# Converged when the TCP is this close to the target (position, orientation).
IK_POSITION_ATOL_M = 1e-5
IK_ROTATION_ATOL_RAD = 1e-4
IK_MAX_ITERATIONS = 150
# Levenberg-Marquardt damping: a floor (keeps the step bounded near
# singularities) plus a term growing with the squared error (Sugihara 2011).
IK_DAMPING_FLOOR = 1e-6
IK_DAMPING_ERROR_GAIN = 1e-2
IK_RESTARTS = 8
# A grasp closer to the base axis than this makes the wrist fold onto the base.
WORKSPACE_MIN_RADIUS_M = 0.20
# Keep the reach check a little inside the datasheet sphere: the IK needs
# some slack to satisfy the orientation at full stretch.
WORKSPACE_REACH_MARGIN_M = 0.02
# The TCP may not go lower than this above the table: the fingertips end PANDA_FINGERTIP_BELOW_TCP_M below it
# and keep TABLE_CLEARANCE_M (the floor of grasping.geometry.tcp_height_m). Until 2026-11-28 it was 3 mm, which
# let the fingertips 4 mm into the table.
MIN_TCP_HEIGHT_ABOVE_TABLE_M = PANDA_FINGERTIP_BELOW_TCP_M + TABLE_CLEARANCE_M
# Every other link's frame origin keeps this much above the table.
MIN_LINK_HEIGHT_ABOVE_TABLE_M = 0.003


class KinematicsError(ValueError):
    """Base class of the motion code's 'this cannot be done' errors."""


class IKError(KinematicsError):
    """No joint configuration reaches the target; carries the best residual."""

    def __init__(self, message: str, residual_m: float, residual_rad: float):
        super().__init__(f"{message} (best residual {residual_m * 1000:.2f} mm, {math.degrees(residual_rad):.2f} deg)")
        self.residual_m = residual_m
        self.residual_rad = residual_rad


class WorkspaceError(KinematicsError):
    """The target lies outside the arm's workspace (reach, base, table)."""


@dataclass(frozen=True)
class IKResult:
    q_rad: np.ndarray
    residual_m: float
    residual_rad: float
    iterations: int


def panda_urdf_path() -> Path:
    return Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"


def _arm_model(urdf_path: Path) -> pin.Model:
    full = pin.buildModelFromUrdf(str(urdf_path))
    arm = set(PANDA_JOINT_NAMES)
    locked = [full.getJointId(name) for name in full.names[1:] if name not in arm]
    model = pin.buildReducedModel(full, locked, pin.neutral(full))
    if tuple(model.names[1:]) != PANDA_JOINT_NAMES:
        raise KinematicsError(f"unexpected joints in {urdf_path}: {list(model.names[1:])}")
    flange = model.getFrameId(FLANGE_FRAME)
    flange_M_tcp = pin.SE3(pin.utils.rotate("z", PANDA_TCP_YAW_RAD), np.array([0.0, 0.0, PANDA_TCP_OFFSET_M]))
    parent = model.frames[flange]
    model.addFrame(pin.Frame(TCP_FRAME, parent.parentJoint, flange, parent.placement * flange_M_tcp,
                             pin.FrameType.OP_FRAME))
    return model


class PandaKinematics:
    """Forward and inverse kinematics of the Panda's TCP (7 arm joints), within the joint limits of the arm
    model `arm` (panda or fr3)."""

    def __init__(self, urdf_path: Path | None = None, seed: int = 0, arm: str = "panda"):
        if arm not in ARM_JOINT_LIMITS:
            raise KinematicsError(f"unknown arm model {arm!r}; known: {', '.join(ARM_MODELS)}")
        self.arm = arm
        self.model = _arm_model(Path(urdf_path) if urdf_path else panda_urdf_path())
        self.data = self.model.createData()
        self.tcp_id = self.model.getFrameId(TCP_FRAME)
        # The IK chooses goals in this range (the FR3's is cut where its controller's velocity bound is 0
        # towards a range end: constants.ARM_GOAL_RANGES); trajectories are checked against ARM_JOINT_LIMITS.
        self.q_min_rad = np.array(ARM_GOAL_RANGES[arm][0])
        self.q_max_rad = np.array(ARM_GOAL_RANGES[arm][1])
        self.q_ready_rad = np.array(PANDA_READY_Q_RAD)
        self.restart_seed = seed
        self._link_ids: dict = {}

    # --- forward kinematics -------------------------------------------------
    def _check_q(self, q_rad) -> np.ndarray:
        q = np.asarray(q_rad, dtype=float)
        if q.shape != (7,):
            raise KinematicsError(f"expected 7 arm joint positions, got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            raise KinematicsError(f"joint positions are not finite: {q.tolist()}")
        return q

    def fk(self, q_rad) -> np.ndarray:
        """base_M_tcp (4x4) at joint positions q."""
        q = self._check_q(q_rad)
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.tcp_id].homogeneous.copy()

    def lowest_heights_m(self, q_rad, exempt_frames=frozenset()) -> tuple[float, float]:
        """(TCP z, lowest z of the other link frames not in exempt_frames) at q, in the base frame."""
        q = self._check_q(q_rad)
        key = frozenset(exempt_frames)
        ids = self._link_ids.get(key)
        if ids is None:  # cached per exemption set: this runs for every trajectory sample
            ids = [i for i, f in enumerate(self.model.frames)
                   if f.type == pin.FrameType.BODY and f.name not in key and f.name != TCP_FRAME]
            self._link_ids[key] = ids
        pin.framesForwardKinematics(self.model, self.data, q)
        frames = self.data.oMf
        return float(frames[self.tcp_id].translation[2]), min(float(frames[i].translation[2]) for i in ids)

    def within_limits(self, q_rad, atol_rad: float = 1e-9) -> bool:
        q = self._check_q(q_rad)
        return bool(np.all(q >= self.q_min_rad - atol_rad) and np.all(q <= self.q_max_rad + atol_rad))

    # --- inverse kinematics -------------------------------------------------
    def _solve_from(self, oMdes: pin.SE3, q0: np.ndarray, pos_atol: float, rot_atol: float) -> IKResult:
        q = np.clip(q0, self.q_min_rad, self.q_max_rad)
        err = np.full(6, np.inf)
        for iteration in range(1, IK_MAX_ITERATIONS + 1):
            pin.framesForwardKinematics(self.model, self.data, q)
            tcpMdes = self.data.oMf[self.tcp_id].actInv(oMdes)
            err = pin.log6(tcpMdes).vector
            if np.linalg.norm(err[:3]) < pos_atol and np.linalg.norm(err[3:]) < rot_atol:
                return IKResult(q, float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:])), iteration)
            jac = pin.computeFrameJacobian(self.model, self.data, q, self.tcp_id, pin.LOCAL)
            jac = -pin.Jlog6(tcpMdes.inverse()) @ jac
            damping = IK_DAMPING_FLOOR + IK_DAMPING_ERROR_GAIN * float(err @ err)
            dq = -jac.T @ np.linalg.solve(jac @ jac.T + damping * np.eye(6), err)
            # Clamping at the limits is what keeps every solution executable.
            q = np.clip(pin.integrate(self.model, q, dq), self.q_min_rad, self.q_max_rad)
        return IKResult(q, float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:])), IK_MAX_ITERATIONS)

    def ik(self, base_M_tcp, q_seed_rad=None, restarts: int = IK_RESTARTS,
           pos_atol_m: float = IK_POSITION_ATOL_M, rot_atol_rad: float = IK_ROTATION_ATOL_RAD) -> IKResult:
        """Joint positions within the limits that put the TCP at base_M_tcp.

        Tries the seed first (solutions near it keep motions short), then
        `restarts` random seeds. Raises IKError with the best residual.
        The random seeds come from a generator started afresh on every call, so
        the answer depends only on the arguments and `restart_seed`, never on
        what was solved before (an executor's plan for a goal does not depend
        on the goals before it).
        """
        target = np.asarray(base_M_tcp, dtype=float)
        if target.shape != (4, 4) or not np.all(np.isfinite(target)):
            raise KinematicsError("IK target must be a finite 4x4 transform")
        oMdes = pin.SE3(target[:3, :3], target[:3, 3])
        seed = self.q_ready_rad if q_seed_rad is None else self._check_q(q_seed_rad)
        best, rng = None, np.random.default_rng(self.restart_seed)
        for attempt in range(restarts + 1):
            q0 = seed if attempt == 0 else rng.uniform(self.q_min_rad, self.q_max_rad)
            result = self._solve_from(oMdes, q0, pos_atol_m, rot_atol_rad)
            if result.residual_m < pos_atol_m and result.residual_rad < rot_atol_rad:
                return result
            if best is None or result.residual_m + result.residual_rad < best.residual_m + best.residual_rad:
                best = result
        p = target[:3, 3]
        raise IKError(f"no joint configuration within the limits reaches the TCP pose at "
                      f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m", best.residual_m, best.residual_rad)

    def top_down_ik(self, position_m, yaw_rad: float, q_seed_rad=None) -> tuple[IKResult, float]:
        """IK of a top-down grasp; returns (solution, yaw used).

        A parallel-jaw grasp is symmetric: yaw and yaw + pi are the same grasp,
        so both are tried and the one nearer the seed (shorter wrist turn, away
        from joint 7's limits) wins.
        """
        seed = self.q_ready_rad if q_seed_rad is None else self._check_q(q_seed_rad)
        candidates, errors = [], []
        # Random restarts are expensive: only when neither yaw converges from the seed.
        for restarts in (0, IK_RESTARTS):
            for yaw in (wrap_angle(yaw_rad), wrap_angle(yaw_rad + math.pi)):
                try:
                    result = self.ik(top_down_pose(position_m, yaw), seed, restarts=restarts)
                except IKError as error:
                    errors.append(error)
                    continue
                candidates.append((float(np.linalg.norm(result.q_rad - seed)), result, yaw))
            if candidates:
                break
        if not candidates:
            raise min(errors, key=lambda e: e.residual_m + e.residual_rad)
        _, result, yaw = min(candidates, key=lambda c: c[0])
        return result, yaw


def check_workspace(position_m, table_z_m: float, min_height_m: float = MIN_TCP_HEIGHT_ABOVE_TABLE_M) -> None:
    """WorkspaceError when a top-down TCP position is out of reach or below the table."""
    p = np.asarray(position_m, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise PoseError(f"TCP position must be 3 finite values, got {p.tolist()}")
    if p[2] < table_z_m + min_height_m:
        raise WorkspaceError(f"TCP height {p[2]:.3f} m is below the table surface at {table_z_m:.3f} m "
                             f"+ {min_height_m * 1000:.0f} mm clearance")
    radius = math.hypot(p[0], p[1])
    if radius < WORKSPACE_MIN_RADIUS_M:
        raise WorkspaceError(f"TCP at {radius:.3f} m from the base axis is too close to the robot "
                             f"(at least {WORKSPACE_MIN_RADIUS_M:.2f} m)")
    # For a top-down pose the flange sits PANDA_TCP_OFFSET_M straight above the TCP.
    flange = p + np.array([0.0, 0.0, PANDA_TCP_OFFSET_M])
    reach = float(np.linalg.norm(flange - np.array([0.0, 0.0, PANDA_SHOULDER_HEIGHT_M])))
    limit = PANDA_MAX_REACH_M - WORKSPACE_REACH_MARGIN_M
    if reach > limit:
        raise WorkspaceError(f"flange would be {reach:.3f} m from the shoulder, beyond the Panda's reach "
                             f"({limit:.3f} m)")

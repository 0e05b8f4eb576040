"""When a joint_trajectory_controller ends a trajectory: its path and goal tolerances, checked once per control period.

The facts (ros2_controllers, branch jazzy; docs/franka_contract.md, "The arm's trajectory controller"):
- Defaults come from the controller's `constraints` parameters: per joint `trajectory` (path) and `goal` position
  tolerances (0 = not checked), `stopped_velocity_tolerance` (0.01 rad/s: the goal velocity tolerance of every
  joint) and `goal_time` (0 = wait for the goal tolerance for ever) (`joint_trajectory_controller_parameters.yaml`,
  `tolerances.hpp` `get_segment_tolerances`).
- A FollowJointTrajectory goal overrides them per joint and per field: > 0 replaces the default, 0 keeps it, -1
  erases it (not checked); any other negative value, or a joint the controller does not have, makes the controller
  log an error and use its defaults for everything (`tolerances.hpp` `resolve_tolerance_source`).
- Every control period the error is desired - measured (position, and velocity with a velocity state and an effort
  or velocity command interface, as franka's arm controllers have). Before the last point's time (and on the first
  period of a trajectory) a joint outside its path tolerance aborts the goal: PATH_TOLERANCE_VIOLATED. From the last
  point's time on, the goal succeeds in the first period every joint is inside its goal tolerance; if that has not
  happened more than goal_time after that time (goal_time != 0), GOAL_TOLERANCE_VIOLATED. After any of these the
  controller holds and checks nothing more (`joint_trajectory_controller.cpp` `update`).
Accelerations are not checked: without an acceleration state interface (franka's arms have none) their error is 0.
Pure numpy; no rclpy, no PyBullet.
"""
from dataclasses import dataclass, replace

import numpy as np

ERASE = -1.0                  # JointTolerance's "no limit" (control_msgs/msg/JointTolerance.msg)
FLOAT32_EPSILON = 1.1920929e-07
SUCCEEDED, PATH_VIOLATED, GOAL_VIOLATED = "succeeded", "path_tolerance_violated", "goal_tolerance_violated"
# The controller's result texts (joint_trajectory_controller.cpp); which joint and by how much goes to the log.
SUCCESS_TEXT = "Goal successfully reached!"
PATH_TEXT = "Aborted due to path tolerance violation"


class ToleranceError(ValueError):
    """A goal's tolerance the controller refuses (it then uses its defaults)."""


@dataclass(frozen=True)
class StateTolerances:
    """Per joint; 0 = not checked."""
    position: np.ndarray
    velocity: np.ndarray


@dataclass(frozen=True)
class SegmentTolerances:
    path: StateTolerances
    goal: StateTolerances
    goal_time_s: float = 0.0   # 0 = no limit on the time after the end to reach the goal tolerances


def default_tolerances(n_joints: int, trajectory_rad=None, goal_rad=None, stopped_velocity_radps: float = 0.01,
                       goal_time_s: float = 0.0) -> SegmentTolerances:
    """The controller's own tolerances from its `constraints` parameters (per-joint lists or None = all 0)."""
    def per_joint(values):
        arr = np.zeros(n_joints) if values is None or len(values) == 0 else np.asarray(values, dtype=float)
        if arr.shape != (n_joints,):
            raise ValueError(f"expected {n_joints} per-joint tolerances, got {len(arr)}")
        return arr

    zeros = np.zeros(n_joints)
    return SegmentTolerances(StateTolerances(per_joint(trajectory_rad), zeros.copy()),
                             StateTolerances(per_joint(goal_rad), np.full(n_joints, float(stopped_velocity_radps))),
                             float(goal_time_s))


def resolve(default: float, requested: float) -> float:
    """A goal's tolerance value over the controller's: > 0 wins, 0 keeps the default, -1 erases (0)."""
    if requested > 0.0:
        return float(requested)
    if abs(requested - ERASE) < FLOAT32_EPSILON:
        return 0.0
    if requested < 0.0:
        raise ToleranceError(f"illegal tolerance value {requested}")
    return float(default)


def _override(state: StateTolerances, joint_tolerances, joint_names, what: str) -> StateTolerances:
    position, velocity = state.position.copy(), state.velocity.copy()
    for name, pos, vel, acc in joint_tolerances:
        if name not in joint_names:
            raise ToleranceError(f"joint '{name}' specified in goal.{what} does not exist")
        i = list(joint_names).index(name)
        try:
            position[i], velocity[i] = resolve(position[i], pos), resolve(velocity[i], vel)
            resolve(0.0, acc)   # checked like the others; never violated without an acceleration state
        except ToleranceError as error:
            raise ToleranceError(f"joint '{name}' specified in goal.{what} has an {error}") from None
    return StateTolerances(position, velocity)


def goal_tolerances(defaults: SegmentTolerances, joint_names, path_tolerance=(), goal_tolerance=(),
                    goal_time_tolerance_s: float = 0.0) -> tuple:
    """(tolerances, '') for a goal's fields, each tolerance (name, position, velocity, acceleration); (defaults, why)
    when the controller would refuse one of them (it logs why and uses its defaults for everything)."""
    try:
        goal_time_s = resolve(defaults.goal_time_s, goal_time_tolerance_s)
    except ToleranceError:
        return defaults, f"Specified illegal goal_time_tolerance: {goal_time_tolerance_s}. Using default tolerances"
    try:
        path = _override(defaults.path, path_tolerance, joint_names, "path_tolerance")
        goal = _override(defaults.goal, goal_tolerance, joint_names, "goal_tolerance")
    except ToleranceError as error:
        return defaults, f"{error}. Using default tolerances"
    return replace(defaults, path=path, goal=goal, goal_time_s=goal_time_s), ""


def violations(state: StateTolerances, error_q, error_qd, joint_names) -> list:
    """'joint: position error e > tolerance t' for every joint outside its tolerance (0 = unchecked)."""
    out = []
    for what, error, tolerance in (("position", error_q, state.position), ("velocity", error_qd, state.velocity)):
        for name, e, tol in zip(joint_names, error, tolerance):
            if tol > 0.0 and abs(e) > tol:
                out.append(f"{name}: {what} error {e:.6f} > tolerance {tol:.6f}")
    return out


@dataclass(frozen=True)
class Verdict:
    outcome: str          # SUCCEEDED, PATH_VIOLATED or GOAL_VIOLATED
    text: str             # the controller's result text
    details: str = ""     # which joints, by how much (for the log)


class TrajectoryMonitor:
    """The checks of the running trajectory, one call per control period, until a verdict; then it holds (checks
    nothing) until the next trajectory starts."""

    def __init__(self, joint_names):
        self.joint_names = tuple(joint_names)
        self._end_s = None    # None: holding
        self._first = False
        self._tolerances = None

    @property
    def running(self) -> bool:
        return self._end_s is not None

    def start(self, end_time_s: float, tolerances: SegmentTolerances) -> None:
        self._end_s, self._first, self._tolerances = float(end_time_s), True, tolerances

    def hold(self) -> None:
        self._end_s = None

    def check(self, now_s: float, q, qd, q_desired, qd_desired) -> Verdict | None:
        """This period's verdict on measured (q, qd) against the desired state at now_s, or None (going on)."""
        if self._end_s is None:
            return None
        first, self._first = self._first, False
        error_q = np.asarray(q_desired, dtype=float) - np.asarray(q, dtype=float)
        error_qd = np.asarray(qd_desired, dtype=float) - np.asarray(qd, dtype=float)
        before_end = now_s < self._end_s
        tol = self._tolerances
        if before_end or first:
            path = violations(tol.path, error_q, error_qd, self.joint_names)
            if path:
                return Verdict(PATH_VIOLATED, PATH_TEXT, "; ".join(path))
        if before_end:
            return None
        goal = violations(tol.goal, error_q, error_qd, self.joint_names)
        if not goal:
            return Verdict(SUCCEEDED, SUCCESS_TEXT)
        late_s = now_s - self._end_s
        if tol.goal_time_s != 0.0 and late_s > tol.goal_time_s:
            return Verdict(GOAL_VIOLATED, f"Aborted due to goal_time_tolerance exceeding by {late_s:.6f} seconds",
                           "; ".join(goal))
        return None

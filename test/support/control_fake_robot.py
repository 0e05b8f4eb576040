"""A fake-clock robot for driving PickPlaceSequence in tests.

It plays the driver's part in the simplest physical way: the arm follows the
commanded samples exactly, the fingers move at the commanded speed and stop
on an object of a given width, the external force rises when the TCP goes
below a contact height. Faults (silence, a slipping object) are switches.
"""
from dataclasses import dataclass

import numpy as np

from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control import sequence_types
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import ArmState, CancelGripper, GraspGripper, MoveGripper, SendTrajectory

TICK_S = 0.01
CONTACT_STIFFNESS_N_PER_M = 5000.0
# A rigid 5 cm block's grasp, the bin's place pose, and a config that recovers to the ready pose (shared by tests).
GRASP = sequence_types.GraspTarget(position_m=(0.5, 0.05, 0.05), yaw_rad=0.4, width_m=0.05, youngs_modulus_pa=2e9)
PLACE = sequence_types.PlaceTarget(position_m=(0.35, -0.45, 0.12))
RECOVERING_CONFIG = sequence_types.SequenceConfig(watchdog_timeout_s=0.5, observation_q_rad=tuple(PANDA_READY_Q_RAD))


@dataclass
class World:
    object_width_m: float | None = 0.05     # None: nothing between the fingers
    contact_height_m: float = -1.0           # TCP z below which the hand touches something
    silent: bool = False                     # driver stops publishing joint states
    wrench_silent: bool = False              # the external wrench stops (joint states go on)
    slip_at_phase: str | None = None         # object falls out when this phase starts
    slip_closing_mps: float = 0.0            # after the slip the fingers close at this rate (0: at once, to 0)
    gripper_report_delay_s: float = 0.0      # fingers report this long after they stopped (a slow squeeze)
    slip_below_tcp_z_m: float | None = None  # with slip_at_phase: the slip waits until the TCP is below this
    object_compliance_m_per_n: float = 0.0   # a grasp at force F stops at object_width_m - F * this (a squeeze)
    open_blocked_below_tcp_z_m: float | None = None  # an opening move stops where it is while the TCP is below this
    opening_rejected: bool = False           # the gripper's server rejects every opening move (no width: nan)


class FakeRobot:
    def __init__(self, kin, world: World, q0=PANDA_READY_Q_RAD, width_m: float = 0.0):
        self.kin, self.world = kin, world
        self.q = np.array(q0, dtype=float)
        self.qd = np.zeros(7)
        self.width_m = width_m
        self.sim_s = 0.0
        self.wall_ahead_s = 0.0   # wall clock - sim time (a pause of the whole cell moves the wall clock only)
        self.trajectory, self.trajectory_start_s = None, 0.0
        self.gripper = None   # (kind, target_width, speed)
        self.gripper_stopped_s = None
        self.sent = []        # every command, in order

    def apply(self, commands, sequence: PickPlaceSequence):
        for command in commands:
            self.sent.append(command)
            if isinstance(command, SendTrajectory):
                self.trajectory, self.trajectory_start_s = command.trajectory, self.sim_s
            elif isinstance(command, MoveGripper):
                self.gripper = ("move", command.width_m, command.speed_mps)
            elif isinstance(command, GraspGripper):
                target = self.world.object_width_m or 0.0
                if target:
                    target -= command.command.force_n * self.world.object_compliance_m_per_n
                self.gripper = ("grasp", target, command.command.speed_mps)
            elif isinstance(command, CancelGripper):
                self.gripper = None
            if isinstance(command, (MoveGripper, GraspGripper, CancelGripper)):
                self.gripper_stopped_s = None

    def _step_gripper(self, sequence: PickPlaceSequence):
        if self.gripper is None:
            return
        kind, target, speed = self.gripper
        blocked_below = self.world.open_blocked_below_tcp_z_m
        if kind == "move" and target > self.width_m and self.world.opening_rejected:
            self.gripper = None
            sequence.on_gripper_result(False, float("nan"), "gripper goal rejected")
            return
        if kind == "move" and target > self.width_m and blocked_below is not None \
                and self.kin.fk(self.q)[2, 3] < blocked_below:
            self.gripper = None   # the finger tips pressed on the floor: friction holds them (franka_gripper's error)
            sequence.on_gripper_result(False, self.width_m, f"fingers blocked at {self.width_m * 1000:.1f} mm")
            return
        step = speed * TICK_S
        remaining = target - self.width_m
        self.width_m = target if abs(remaining) <= step else self.width_m + np.sign(remaining) * step
        if self.width_m != target:
            return
        if self.gripper_stopped_s is None:
            self.gripper_stopped_s = self.sim_s
        if self.sim_s - self.gripper_stopped_s >= self.world.gripper_report_delay_s - 1e-9:
            self.gripper, self.gripper_stopped_s = None, None
            sequence.on_gripper_result(True, self.width_m, "")

    def step(self, sequence: PickPlaceSequence):
        self.sim_s += TICK_S
        if self.trajectory is not None:
            q, qd, _ = self.trajectory.state_at(self.sim_s - self.trajectory_start_s)
            self.q, self.qd = q, qd
        self._step_gripper(sequence)
        low_enough = self.world.slip_below_tcp_z_m is None or self.kin.fk(self.q)[2, 3] < self.world.slip_below_tcp_z_m
        if self.world.slip_at_phase == sequence.phase and self.gripper is None and low_enough:
            self.world.slip_at_phase = "slipped"    # from here on the fingers close on nothing
        if self.world.slip_at_phase == "slipped" and self.gripper is None:
            # Force-controlled fingers close at their grasp speed once nothing is between them.
            rate = self.world.slip_closing_mps
            self.width_m = 0.0 if rate <= 0 else max(0.0, self.width_m - rate * TICK_S)
        tcp_z = self.kin.fk(self.q)[2, 3]
        depth = max(0.0, self.world.contact_height_m - tcp_z)
        if not self.world.wrench_silent:
            sequence.on_force([0.0, 0.0, CONTACT_STIFFNESS_N_PER_M * depth], self.wall_s)
        if not self.world.silent:
            sequence.on_joint_state(ArmState(self.q.copy(), self.qd.copy(), self.width_m), self.wall_s)
        self.apply(sequence.tick(self.sim_s, self.wall_s), sequence)

    @property
    def wall_s(self) -> float:
        return self.sim_s + self.wall_ahead_s


def run(sequence: PickPlaceSequence, robot: FakeRobot, max_s: float = 60.0, until=None):
    """Start the sequence and step until it finishes (or `until(robot, sequence)` is true)."""
    sequence.on_joint_state(ArmState(robot.q.copy(), robot.qd.copy(), robot.width_m), robot.sim_s)
    if not robot.world.wrench_silent:   # the executor starts a goal only with a wrench in (and tells its age)
        sequence.on_force([0.0, 0.0, 0.0], robot.wall_s)
    robot.apply(sequence.start(robot.sim_s, robot.sim_s), sequence)
    while not sequence.finished and robot.sim_s < max_s:
        if until is not None and until(robot, sequence):
            return
        robot.step(sequence)
    assert sequence.finished, f"sequence still in {sequence.phase} after {max_s} s"

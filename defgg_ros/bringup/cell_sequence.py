"""Run a pick-and-place sequence against the simulated cell in one process, without ROS.

The executor node and the fake driver node do the same over DDS: the sequence's commands go to the
cell, the cell's joint state, wrench and gripper outcomes come back every period. In-process runs are
deterministic (no DDS timing), so a test or a bench can repeat a pick exactly.
"""
import numpy as np

from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import ArmState, CancelGripper, GraspGripper, MoveGripper, SendTrajectory
from defgg_ros.sim.cell.sim_cell import SimCell

PERIOD_S = 0.01   # the executor's control period (its 100 Hz loop)


class CellSequenceDriver:
    """Carries a PickPlaceSequence's commands to a SimCell and the cell's state back.

    state_lag_periods > 0 hands the sequence the joint state of that many periods ago, as a busy ROS cell
    does (states arrived 10-30 ms late at a real-time factor of 3, 2026-11-28); start_jumps_rad records, for
    each trajectory sent, how far its first point is from where the arm is then (rad, largest joint).
    """

    def __init__(self, cell: SimCell, sequence: PickPlaceSequence, period_s: float = PERIOD_S,
                 state_lag_periods: int = 0):
        if state_lag_periods < 0:
            raise ValueError(f"state_lag_periods must be >= 0, got {state_lag_periods}")
        self.cell, self.sequence, self.period_s = cell, sequence, period_s
        self.state_lag_periods, self._states = state_lag_periods, []
        self.start_jumps_rad = []

    def apply(self, commands) -> None:
        for command in commands:
            if isinstance(command, SendTrajectory):
                t = command.trajectory
                self.start_jumps_rad.append(float(np.max(np.abs(t.q_rad[0] - self.cell.arm_positions()))))
                self.cell.command_trajectory(list(zip(t.times_s, t.q_rad, t.qd_radps, t.qdd_radps2)))
            elif isinstance(command, MoveGripper):
                self.cell.gripper_move(command.width_m, command.speed_mps)
            elif isinstance(command, GraspGripper):
                g = command.command
                self.cell.gripper_grasp(g.width_m, g.epsilon_inner_m, g.epsilon_outer_m, g.speed_mps, g.force_n)
            elif isinstance(command, CancelGripper):
                self.cell.gripper_stop()   # franka_gripper's cancel: stopped, no force held

    def feed(self, outcomes) -> None:
        joints = self.cell.joint_state()
        width = float(joints.positions[7] + joints.positions[8])
        now = ArmState(joints.positions[:7].copy(), joints.velocities[:7].copy(), width)
        self._states = (self._states + [now])[-(self.state_lag_periods + 1):]
        self.sequence.on_joint_state(self._states[0], self.cell.time_s)
        self.sequence.on_force(self.cell.external_wrench()[0])
        for _, outcome in outcomes:
            self.sequence.on_gripper_result(outcome.success, outcome.width_m, outcome.error)

    def run(self, max_sim_s: float, on_period=None):
        """Step until the sequence finishes or the cell's clock reaches max_sim_s; returns its Outcome.

        on_period(cell) is called after every period (a bench records the objects there)."""
        self.feed([])
        self.apply(self.sequence.start(self.cell.time_s, self.cell.time_s))
        while not self.sequence.finished and self.cell.time_s < max_sim_s:
            outcomes = self.cell.advance(self.period_s)
            self.feed(outcomes)
            if on_period is not None:
                on_period(self.cell)
            self.apply(self.sequence.tick(self.cell.time_s, self.cell.time_s))
        return self.sequence.outcome

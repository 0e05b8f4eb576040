"""The squeeze phase of a pick (issue 49 item 4): the object's stiffness measured by the hand itself.

After the descent the hand closes at squeeze.GENTLE_FORCES_N, then at squeeze.FIRM_FORCES_N while the
compression is not resolved (squeeze.needs_firmer); the opening is read SqueezeRequest.settle_s after each
grasp answered. squeeze.estimate_modulus turns the readings into a modulus (docs/squeeze.md). Then either the
pick goes on (the close uses the measured modulus's force unless the grasp carries its own), or, measure only,
the hand opens, the TCP rises back to the pre-grasp height and the arm returns to the observation pose.

A mixin of PickPlaceSequence (it shares the sequence's state: the plan, the gripper's pending result, the
recovery runner that carries out the way back); no ROS, no clock of its own.
"""
import dataclasses
import math
import threading

import numpy as np

from defgg_ros import section_model
from defgg_ros.constants import TRAINING_YOUNGS_MODULI_PA
from defgg_ros.control.gripper_rule import MISSED_WIDTH_M, GraspCommand, grasp_command
from defgg_ros.control.sequence_types import GraspGripper, SequenceFailure
from defgg_ros.squeeze import (
    FIRM_FORCES_N,
    GENTLE_FORCES_N,
    ModulusEstimate,
    SqueezeError,
    SqueezeReading,
    estimate_modulus,
    needs_firmer,
    section_may_apply,
)

# A rigid verdict is planned with the paper's rigid class (the network knows 2e4, 2e5, 2e6 and 2e9 Pa).
RIGID_PLANNING_MODULUS_PA = TRAINING_YOUNGS_MODULI_PA[-1]
# The object's height is at least this for the loaded area (a grasp point on the table would give 0).
MIN_FACE_HEIGHT_M = 0.005
# The section law's model (section_model.py; 0.01-0.03 s on a quiet machine, bench_squeeze_stiffness.py prints it)
# runs from the goal's start, beside the motions, so a loaded machine never stalls the control loop; the estimate
# waits for it at most this long (robot time) after the last reading, then goes without it (the contact laws).
SECTION_WAIT_S = 5.0
# The opening read after a squeeze settled may creep below what the gripper reported (a soft body relaxing), but
# not below this fraction of it: less is the object sliding out of the hand (it read 1.4e4 Pa for a rigid block).
SETTLED_WIDTH_FRACTION = 0.75


class SectionJob:
    """The grasp's section curve computed on a thread of its own (numpy's solver releases the GIL), so the
    control loop never stalls on it; `curve` is None until done, and stays None when the section is refused."""

    def __init__(self, cell_m: float, heights_m: tuple, model=section_model.section_curve):
        self.curve: section_model.SectionCurve | None = None
        self.error = ""
        self._done = threading.Event()
        self._model = model
        threading.Thread(target=self._run, args=(cell_m, np.asarray(heights_m, float)), daemon=True).start()

    def _run(self, cell_m: float, heights: np.ndarray) -> None:
        try:
            self.curve = self._model(heights > 0.0, heights, cell_m)
        except section_model.SectionError as error:
            self.error = str(error)
        finally:
            self._done.set()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def wait(self, timeout_s: float) -> bool:
        return self._done.wait(timeout_s)


def planning_modulus_pa(estimate: ModulusEstimate) -> float:
    """The modulus to plan and grasp with: the estimate (a lower bound as it is), RIGID_PLANNING_MODULUS_PA when
    rigid."""
    return RIGID_PLANNING_MODULUS_PA if estimate.rigid else float(estimate.youngs_modulus_pa)


class SqueezePhase:
    """The "squeeze" phase and the measure-only way back (mixed into PickPlaceSequence)."""

    def _init_squeeze(self, squeeze) -> None:
        if squeeze is not None:
            squeeze.validate()
        self._squeeze = squeeze
        self.squeeze_readings: list = []
        self.squeeze_estimate: ModulusEstimate | None = None
        self._squeeze_force_n = math.nan
        self._squeeze_read_at_s: float | None = None   # robot time the running squeeze's opening is read at
        self._squeeze_reported_m = math.nan             # the opening the gripper reported for it
        self._returning = False    # measure only: on the way back (a failure there is the goal's failure)
        self._section_job: SectionJob | None = None
        self._section_wait_from_s: float | None = None   # robot time the estimate began to wait for the section

    @property
    def squeeze_request(self):
        return self._squeeze

    @property
    def squeeze_requested(self) -> bool:
        return self._squeeze is not None

    def _start_section_job(self) -> None:
        """With the goal: the section law's model runs while the arm goes down; only where the estimate may read it
        (a pad along a line, flat pads: squeeze.section_may_apply; two point contacts keep the point law)."""
        grasp = self._grasp
        if (self._squeeze is not None and grasp is not None and grasp.section_heights_m
                and section_may_apply(grasp.contact_radii_m, grasp.contact_line_lengths_m)):
            self._section_job = SectionJob(grasp.section_cell_m, grasp.section_heights_m)

    @property
    def section_job(self) -> SectionJob | None:
        return self._section_job

    @property
    def section_note(self) -> str:
        """Why a grasp's section did not give the estimate ("" when it did or there was none)."""
        job = self._section_job
        if job is None or job.curve is not None:
            return ""
        reason = job.error or f"its model was still running {SECTION_WAIT_S:g} s after the last reading"
        return f"the section law not used: {reason}"

    def _begin_squeeze(self, sim_s: float) -> list:
        self._phase = "squeeze"
        return self._next_squeeze(sim_s)

    def _section_pending(self, sim_s: float) -> bool:
        """Whether the estimate still waits for the section's curve (at most SECTION_WAIT_S)."""
        job = self._section_job
        if job is None or job.done:
            return False
        if self._section_wait_from_s is None:
            self._section_wait_from_s = sim_s
        return sim_s - self._section_wait_from_s < SECTION_WAIT_S

    def _next_force_n(self) -> float | None:
        done = len(self.squeeze_readings)
        if done < len(GENTLE_FORCES_N):
            return GENTLE_FORCES_N[done]
        firm_done = done - len(GENTLE_FORCES_N)
        if firm_done < len(FIRM_FORCES_N) and needs_firmer(self.squeeze_readings, self._squeeze.width_resolution_m):
            return FIRM_FORCES_N[firm_done]
        return None

    def _next_squeeze(self, sim_s: float) -> list:
        force_n = self._next_force_n()
        if force_n is not None:
            self._squeeze_force_n = force_n
            opened = self._plan.gripper.pre_open_width_m
            # width 0 with epsilons over the whole opening: the goal succeeds wherever the fingers stop
            command = GraspCommand(opened, 0.0, 0.0, opened, self._squeeze.speed_mps, force_n)
            return self._send_gripper(GraspGripper(command), sim_s)
        if self._section_pending(sim_s):
            return []      # _tick_squeeze comes back here once the curve is in
        self.squeeze_estimate = self._estimate()
        if self._squeeze.only:
            return self._begin_way_back(sim_s)
        grasp = self._grasp
        gripper = grasp_command(planning_modulus_pa(self.squeeze_estimate), grasp.width_m, grasp.finger_force_n)
        self._plan = dataclasses.replace(self._plan, gripper=gripper)
        self._phase = "close"
        return self._send_gripper(GraspGripper(gripper), sim_s)

    def _estimate(self) -> ModulusEstimate:
        # The face's height: from the grasp's surface point down to the table; its extent across the closing axis
        # is not known here (inf: the pads' spread alone is loaded, docs/squeeze.md). The grasp's contact radii
        # (perceived, planning/contact_radii.py): Hertz where the surface is curved (the line-contact law where a
        # pad touches along a line); none: the flat law.
        face_height_m = max(float(self._grasp.position_m[2]) - self._cfg.table_z_m, MIN_FACE_HEIGHT_M)
        # The grasp's section (the section law) when its curve is in.
        section = self._section_job.curve if self._section_job is not None else None
        try:
            return estimate_modulus(self.squeeze_readings, math.inf, face_height_m, hand=self._squeeze.hand,
                                    width_resolution_m=self._squeeze.width_resolution_m,
                                    contact_radii_m=tuple(self._grasp.contact_radii_m) or None,
                                    contact_line_lengths_m=tuple(self._grasp.contact_line_lengths_m) or None,
                                    section=section)
        except SqueezeError as error:
            raise SequenceFailure(f"squeeze: {error}") from error

    def _tick_squeeze(self, sim_s: float) -> list:
        if self._section_wait_from_s is not None:
            return self._next_squeeze(sim_s)      # every reading is in: waiting for the section's curve
        if self._squeeze_read_at_s is None:
            result = self._gripper_result(sim_s, f"the squeeze at {self._squeeze_force_n:g} N")
            if result is None:
                return []
            success, width_m, error = result
            if width_m < MISSED_WIDTH_M:
                raise SequenceFailure(f"missed: the fingers closed to {width_m * 1000:.1f} mm with nothing "
                                      "between them (squeeze)")
            if not success:
                raise SequenceFailure(f"squeeze at {self._squeeze_force_n:g} N failed: {error or 'no reason given'}")
            self._check_closed(width_m, " (squeeze)")   # else read as a rigid object, sent as 2e9 Pa
            self._squeeze_reported_m = width_m
            self._squeeze_read_at_s = sim_s + self._squeeze.settle_s
            return []
        if sim_s < self._squeeze_read_at_s:
            return []
        self._squeeze_read_at_s = None
        reading_m = self._obs.state.gripper_width_m
        if reading_m < max(MISSED_WIDTH_M, SETTLED_WIDTH_FRACTION * self._squeeze_reported_m):
            raise SequenceFailure(f"the object moved in the squeeze at {self._squeeze_force_n:g} N: the opening went "
                                  f"from {self._squeeze_reported_m * 1000:.1f} to {reading_m * 1000:.1f} mm while it "
                                  "settled; squeeze again")
        self.squeeze_readings.append(SqueezeReading(self._squeeze_force_n, reading_m))
        return self._next_squeeze(sim_s)

    # --- measure only: back up ---------------------------------------------------------------------------
    def _begin_way_back(self, sim_s: float) -> list:
        """Open, rise to the pre-grasp height, then the observation pose: run by the recovery's step runner."""
        self._returning, self._recovering, self._phase = True, True, "retreat"
        self._recovery_steps = [self._step_open, self._step_back_up]
        if self._cfg.observation_q_rad is not None:
            self._recovery_steps.append(self._step_observe)
        return self._next_recovery_step(sim_s)

    def _step_back_up(self, sim_s: float) -> list:
        up_m = self._pregrasp_z_m() - self._tcp_z_m()
        if up_m < 0.005:
            return []
        return self._recovery_motion(f"lifted the hand {up_m * 100:.0f} cm", self._line_up(up_m, sim_s))

    def _pregrasp_z_m(self) -> float:
        return float(self._kin.fk(self._plan.pregrasp_q)[2, 3])

    def _end_way_back_on_failure(self) -> None:
        """A failure or cancel on the way back: from here on the goal's own failure (its recovery may follow)."""
        self._returning = self._recovering = False
        self._recovery_steps = []

    def _squeeze_outcome(self) -> None:
        """At the end of a measure-only run: it succeeded if the way back was completed."""
        if self._returning and not self.outcome.canceled and not self.outcome.failure_reason:
            self.outcome.success = True
            self._phase, self._recovery_log = "done", []

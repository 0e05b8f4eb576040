"""The squeeze phase of the sequence (issue 49 item 4), on a fake clock: measure only, measure then pick, a
stiffness the squeeze cannot resolve, a cancel while squeezing.

The fake robot's object yields linearly (World.object_compliance_m_per_n): a grasp at F stops at width - F c, so
the expected modulus is squeeze.estimate_modulus's model with k = 1 / c.
"""
import dataclasses
import math
import threading

import numpy as np
import pytest
from defgg_interfaces.action import PickAndPlace
from support.control_fake_robot import GRASP, PLACE, RECOVERING_CONFIG, FakeRobot, World, run

from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control.gripper_rule import grasp_command
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.observation import ObservationWatch
from defgg_ros.control.pick_place import PickPlaceSequence
from defgg_ros.control.sequence_types import GraspGripper, SendTrajectory, SqueezeRequest
from defgg_ros.control.squeeze_phase import SectionJob
from defgg_ros.nodes.executor_messages import copy_squeeze
from defgg_ros.section_model import section_curve
from defgg_ros.squeeze import FIRM_FORCES_N, GENTLE_FORCES_N, estimate_modulus, loaded_area_m2

pytestmark = pytest.mark.unit

CONFIG = RECOVERING_CONFIG
COMPLIANCE_M_PER_N = 1.3e-4   # ~2e5 Pa for a 5 cm block under the hand's pads
SQUEEZE = SqueezeRequest(width_resolution_m=1e-5)


@pytest.fixture(scope="module")
def kin():
    return PandaKinematics()


def expected_modulus_pa(width_m=0.05, compliance=COMPLIANCE_M_PER_N, face_height_m=0.05):
    first_width = width_m - GENTLE_FORCES_N[0] * compliance
    return first_width / (loaded_area_m2(first_width, math.inf, face_height_m) * compliance)


def grasps_sent(robot):
    return [c.command for c in robot.sent if isinstance(c, GraspGripper)]


def test_measure_only_squeezes_opens_and_returns_without_a_pick(kin):
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
    robot = FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N))
    run(sequence, robot, max_s=120.0)
    out, estimate = sequence.outcome, sequence.squeeze_estimate
    assert out.success, out.failure_reason
    assert out.phase_reached == "done" and out.arm_state == "observation_pose" and out.recovery == ""
    assert [r.force_n for r in sequence.squeeze_readings] == list(GENTLE_FORCES_N)   # resolved: no firm squeeze
    assert [g.force_n for g in grasps_sent(robot)] == list(GENTLE_FORCES_N)
    assert estimate.youngs_modulus_pa == pytest.approx(expected_modulus_pa(), rel=0.02)
    assert estimate.low_pa < estimate.youngs_modulus_pa < estimate.high_pa and not estimate.rigid
    assert robot.width_m == pytest.approx(grasp_command(2e9, GRASP.width_m).pre_open_width_m)   # the hand let go
    tcp_lowest = min(kin.fk(t.trajectory.final_q_rad)[2, 3] for t in robot.sent if isinstance(t, SendTrajectory))
    assert tcp_lowest > 0.0 and not sequence.released_at_place   # never went to the place


def test_measure_then_pick_closes_with_the_measured_modulus_force(kin):
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE, SQUEEZE)
    robot = FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N))
    run(sequence, robot, max_s=120.0)
    assert sequence.outcome.success, sequence.outcome.failure_reason
    close = grasps_sent(robot)[len(GENTLE_FORCES_N)]
    measured = sequence.squeeze_estimate.youngs_modulus_pa
    assert close.force_n == pytest.approx(grasp_command(measured, GRASP.width_m).force_n)
    assert close.force_n != pytest.approx(grasp_command(GRASP.youngs_modulus_pa, GRASP.width_m).force_n)


def test_the_grasps_contact_radii_reach_the_estimate_hertz_where_curved(kin):
    """A grasp carrying the perceived contact radii (Grasp.contact_radii_m) is read with Hertz's law on them; the
    same squeeze without radii with the flat law."""
    radii = (0.02, 0.03)
    estimates = {}
    for name, grasp in (("curved", dataclasses.replace(GRASP, contact_radii_m=radii)), ("flat", GRASP)):
        sequence = PickPlaceSequence(kin, CONFIG, grasp, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
        run(sequence, FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N)), max_s=120.0)
        assert sequence.outcome.success, sequence.outcome.failure_reason
        estimates[name] = (sequence.squeeze_estimate, sequence.squeeze_readings)
    curved, readings = estimates["curved"]
    face_height_m = GRASP.position_m[2] - CONFIG.table_z_m
    expected = estimate_modulus(readings, math.inf, face_height_m, width_resolution_m=1e-5, contact_radii_m=radii)
    assert curved.contact_law == "hertz" and expected.contact_law == "hertz"
    assert curved.youngs_modulus_pa == pytest.approx(expected.youngs_modulus_pa, rel=1e-9)
    assert estimates["flat"][0].contact_law == "flat"
    assert estimates["flat"][0].youngs_modulus_pa == pytest.approx(expected_modulus_pa(), rel=0.02)


def test_the_grasps_contact_line_lengths_reach_the_estimate_the_line_law_where_straight(kin):
    """A grasp whose pads touch along lines (Grasp.contact_line_lengths_m, e.g. a standing cylinder's side) is read
    with the line-contact law on its radii and lengths, not Hertz's point contact on the same radii."""
    radii, lengths = (0.02, 0.02), (0.018, 0.018)
    grasp = dataclasses.replace(GRASP, contact_radii_m=radii, contact_line_lengths_m=lengths)
    sequence = PickPlaceSequence(kin, CONFIG, grasp, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
    run(sequence, FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N)), max_s=120.0)
    assert sequence.outcome.success, sequence.outcome.failure_reason
    face_height_m = GRASP.position_m[2] - CONFIG.table_z_m
    readings = sequence.squeeze_readings
    line = estimate_modulus(readings, math.inf, face_height_m, width_resolution_m=1e-5, contact_radii_m=radii,
                            contact_line_lengths_m=lengths)
    point = estimate_modulus(readings, math.inf, face_height_m, width_resolution_m=1e-5, contact_radii_m=radii)
    assert line.contact_law == sequence.squeeze_estimate.contact_law == "hertz-line" != point.contact_law
    assert sequence.squeeze_estimate.youngs_modulus_pa == pytest.approx(line.youngs_modulus_pa, rel=1e-9)
    assert line.youngs_modulus_pa != pytest.approx(point.youngs_modulus_pa, rel=0.05)


def diamond_section(rows: int = 13, cols: int = 19, cell_m: float = 0.003, height_m: float = 0.03) -> tuple:
    """A rhombus section (pointed at both pads, a star prism's arms end to end) as Grasp.section_heights_m rows."""
    r = (np.arange(rows) + 0.5 - rows / 2) / (rows / 2)
    c = (np.arange(cols) + 0.5 - cols / 2) / (cols / 2)
    inside = np.abs(c)[None, :] + np.abs(r)[:, None] <= 1.0
    return tuple(tuple(row) for row in np.where(inside, height_m, 0.0))


def test_a_grasp_with_a_section_is_read_with_the_section_law_at_lines_and_on_faces_of_no_box(kin):
    """The grasp's section (Grasp.section_*) is modelled beside the squeeze (section_model.py, on a thread) and the
    estimate fits it where a pad touches along a line, and with flat pads (no contact radii) where the section does
    not fill the flat law's prism (a rhombus; a block keeps the flat law); with two point contacts the point law
    stays and no model runs (docs/squeeze.md "The section law")."""
    heights = diamond_section()
    curved = dataclasses.replace(GRASP, contact_radii_m=(0.004, 0.004), contact_line_lengths_m=(0.018, 0.018),
                                 section_cell_m=0.003, section_heights_m=heights)
    flat = dataclasses.replace(curved, contact_radii_m=(), contact_line_lengths_m=())
    block = dataclasses.replace(flat, section_heights_m=tuple((0.03,) * len(row) for row in heights))
    off_pads = tuple(row if i < 3 else (0.0,) * len(row) for i, row in enumerate(heights))   # nothing under the pads
    refused = dataclasses.replace(curved, section_heights_m=off_pads)
    points = dataclasses.replace(curved, contact_line_lengths_m=(0.0, 0.0))    # two point contacts: Hertz, no model
    laws, notes = {}, {}
    for name, grasp in (("refused", refused), ("flat", flat), ("block", block), ("points", points),
                        ("curved", curved)):
        sequence = PickPlaceSequence(kin, CONFIG, grasp, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
        assert (sequence.section_job is None) == (name == "points"), name
        if sequence.section_job is not None:    # the fake clock outruns the model's thread; a cell's descent does not
            assert sequence.section_job.wait(30.0)
        run(sequence, FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N)), max_s=120.0)
        assert sequence.outcome.success, sequence.outcome.failure_reason
        laws[name], notes[name] = sequence.squeeze_estimate, sequence.section_note
        result = PickAndPlace.Result()       # the action's result says which law the estimate used
        copy_squeeze(result, sequence)
        assert result.measured_contact_law == laws[name].contact_law, name
    face_height_m = GRASP.position_m[2] - CONFIG.table_z_m
    heights_m = np.asarray(heights)
    expected = estimate_modulus(sequence.squeeze_readings, math.inf, face_height_m, width_resolution_m=1e-5,
                                contact_radii_m=curved.contact_radii_m,
                                contact_line_lengths_m=curved.contact_line_lengths_m,
                                section=section_curve(heights_m > 0, heights_m, 0.003))
    assert laws["curved"].contact_law == "section" and notes["curved"] == ""
    assert laws["curved"].youngs_modulus_pa == pytest.approx(expected.youngs_modulus_pa, rel=1e-6)
    assert laws["flat"].contact_law == "section" and notes["flat"] == ""
    assert laws["flat"].youngs_modulus_pa == pytest.approx(expected.youngs_modulus_pa, rel=1e-6)
    assert laws["block"].contact_law == "flat" and notes["block"] == ""
    assert laws["points"].contact_law == "hertz" and notes["points"] == ""
    assert laws["refused"].contact_law == "hertz-line"
    assert notes["refused"] == "the section law not used: no section under the pads (the middle rows are empty)"


def test_a_section_model_still_running_is_waited_for_a_while_then_the_contact_laws_read(kin):
    """The estimate never waits on the section's thread longer than SECTION_WAIT_S of robot time: with the model
    held until the squeeze is over, the squeeze ends with the contact law and says why."""
    heights = diamond_section()
    grasp = dataclasses.replace(GRASP, contact_radii_m=(0.004, 0.004), contact_line_lengths_m=(0.018, 0.018),
                                section_cell_m=0.003, section_heights_m=heights)
    sequence = PickPlaceSequence(kin, CONFIG, grasp, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
    released = threading.Event()

    def held_model(mask, heights_m, cell_m):     # the real model, started only once the test lets it
        released.wait(60.0)
        return section_curve(mask, heights_m, cell_m)
    sequence._section_job = SectionJob(0.003, heights, model=held_model)
    try:
        run(sequence, FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N)), max_s=120.0)
    finally:
        released.set()
    assert sequence.outcome.success, sequence.outcome.failure_reason
    assert sequence.squeeze_estimate.contact_law == "hertz-line"
    assert sequence.section_note == "the section law not used: its model was still running 5 s after the last reading"


def test_an_unresolved_compression_squeezes_firmer_and_reads_rigid(kin):
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
    robot = FakeRobot(kin, World(object_compliance_m_per_n=0.0))
    run(sequence, robot, max_s=120.0)
    assert sequence.outcome.success, sequence.outcome.failure_reason
    assert [r.force_n for r in sequence.squeeze_readings] == list(GENTLE_FORCES_N + FIRM_FORCES_N)
    assert sequence.squeeze_estimate.rigid and sequence.squeeze_estimate.lower_bound


def test_cancel_while_squeezing_recovers_to_the_observation_pose(kin):
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
    robot = FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N))
    run(sequence, robot, until=lambda r, s: len(s.squeeze_readings) == 2)
    robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
    run_on = 0
    while not sequence.finished and run_on < 12000:
        robot.step(sequence)
        run_on += 1
    out = sequence.outcome
    assert out.canceled and not out.success and out.phase_reached == "squeeze"
    assert out.arm_state == "observation_pose" and "opened the hand" in out.recovery
    assert np.max(np.abs(robot.q - np.array(PANDA_READY_Q_RAD))) < CONFIG.arrival_joint_atol_rad


def test_frames_perceived_before_a_measurement_reached_perception_do_not_count():
    watch = ObservationWatch(PANDA_READY_Q_RAD, 0.05)
    watch.update(PANDA_READY_Q_RAD, 10.0)
    assert watch.frame_is_clear(10.5)
    watch.frames_from(11.0)          # the squeeze's modulus was sent at 11 s
    assert not watch.frame_is_clear(10.5) and watch.frame_is_clear(11.2)
    watch.frames_from(5.0)           # never back
    assert not watch.frame_is_clear(10.5)


def test_a_finger_resting_on_the_object_is_no_measurement_and_neither_is_an_object_that_slid_out(kin):
    """Fingers that stayed at their opening (a finger on top of the object) read as a rigid object and 2e9 Pa
    went to perception; an object sliding out while a squeeze settled read 1.4e4 Pa for a rigid block. Both fail
    the measurement ("squeeze again"), nothing is estimated."""
    opened = grasp_command(2e9, GRASP.width_m).pre_open_width_m
    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
    robot = FakeRobot(kin, World(object_width_m=opened))          # the fingers stop where they opened to
    run(sequence, robot, max_s=120.0)
    assert "the fingers did not close (squeeze)" in sequence.outcome.failure_reason
    assert sequence.squeeze_estimate is None and not sequence.outcome.success

    sequence = PickPlaceSequence(kin, CONFIG, GRASP, PLACE, SqueezeRequest(only=True, width_resolution_m=1e-5))
    robot = FakeRobot(kin, World(object_compliance_m_per_n=COMPLIANCE_M_PER_N))
    run(sequence, robot, max_s=120.0, until=lambda r, s: s._squeeze_read_at_s is not None)
    robot.width_m = 0.018                                        # slid out while the squeeze settles
    while not sequence.finished and robot.sim_s < 120.0:
        robot.step(sequence)
    assert "the object moved in the squeeze" in sequence.outcome.failure_reason
    assert sequence.squeeze_estimate is None

"""Property: whole pick-and-place runs, not single motions, stay safe.

For random reachable grasps, object widths, place poses, contact heights and
cancel moments, every trajectory PickPlaceSequence sends (approach, guarded
descent, lift, transfer, place, retreat, and the stop after a cancel) is
checked from its samples alone: joint position, velocity, acceleration and
jerk limits at the configured scale, and fingertips above the table. A descent with
something in the way stops there (force threshold), and a canceled run ends
with the arm at rest. Runs on the fake-clock robot of test/control (real
Pinocchio kinematics and Ruckig trajectories).
"""

import dataclasses

import numpy as np
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from support.control_fake_robot import CONTACT_STIFFNESS_N_PER_M, FakeRobot, World, run

from defgg_ros.constants import PANDA_FINGERTIP_BELOW_TCP_M
from defgg_ros.control.kinematics import PandaKinematics
from defgg_ros.control.pick_place import GRASP_MIN_HEIGHT_ABOVE_TABLE_M, PickPlaceSequence
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget, SendTrajectory, SequenceConfig
from defgg_ros.control.trajectories import panda_limits
from defgg_ros.grasping.geometry import tcp_height_m

KIN = PandaKinematics()
CONFIG = SequenceConfig(watchdog_timeout_s=0.5)
assert CONFIG.grasp_height_rule == "half_height"
LIMITS = panda_limits(CONFIG.limits_scale)
REL_TOL = 1e-6
CANCEL_PHASES = ("pre_grasp", "descend", "lift", "transfer", "place")


def check_samples(trajectory):
    q, qd, qdd, t = trajectory.q_rad, trajectory.qd_radps, trajectory.qdd_radps2, trajectory.times_s
    assert np.all(q >= LIMITS.q_min_rad - 1e-9) and np.all(q <= LIMITS.q_max_rad + 1e-9)
    assert np.all(np.abs(qd) <= LIMITS.qd_max_radps * (1 + REL_TOL))
    assert np.all(np.abs(qdd) <= LIMITS.qdd_max_radps2 * (1 + REL_TOL))
    if len(t) > 1:
        assert np.all(np.diff(t) > 0)
        jerk = np.diff(qdd, axis=0) / np.diff(t)[:, None]
        assert np.all(np.abs(jerk) <= LIMITS.qddd_max_radps3 * (1 + REL_TOL))
    # the fingertips (7 mm below the TCP) never reach the table, stops after a contact included
    assert min(KIN.fk(qk)[2, 3] for qk in q) >= CONFIG.table_z_m + PANDA_FINGERTIP_BELOW_TCP_M


scenarios = st.fixed_dictionaries({
    "grasp": st.tuples(st.floats(0.35, 0.62), st.floats(-0.25, 0.25), st.floats(0.015, 0.12), st.floats(-3.1, 3.1)),
    "width_m": st.floats(0.01, 0.07),
    "place": st.tuples(st.floats(0.3, 0.5), st.floats(-0.5, -0.3), st.floats(0.08, 0.2)),
    # Above the descent's end by more than the threshold's spring travel (10 N / 5 kN/m = 2 mm).
    "contact_above_grasp_m": st.one_of(st.none(), st.floats(0.005, 0.012), st.floats(0.012, 0.02)),
    "cancel": st.one_of(st.none(), st.tuples(st.sampled_from(CANCEL_PHASES), st.floats(0.1, 0.9))),
    # after a cancel the arm recovers to the observation pose (the node's default): those motions too
    "recover": st.booleans(),
    "via": st.one_of(st.none(), st.tuples(st.floats(0.3, 0.5), st.floats(-0.3, 0.0), st.floats(0.2, 0.35))),
})


def run_scenario(s) -> dict:
    x, y, z, yaw = s["grasp"]
    grasp = GraspTarget((x, y, z), yaw, 0.08, 2e6)
    # The default grasp_height_rule, half_height: half the height seen at the grasp point.
    tcp_grasp_z = max(tcp_height_m(z, CONFIG.table_z_m), CONFIG.table_z_m + GRASP_MIN_HEIGHT_ABOVE_TABLE_M)
    contact_z = None if s["contact_above_grasp_m"] is None else tcp_grasp_z + s["contact_above_grasp_m"]
    world = World(object_width_m=s["width_m"], contact_height_m=-1.0 if contact_z is None else contact_z)
    config = dataclasses.replace(CONFIG, transfer_via_position_m=s["via"],
                                 observation_q_rad=tuple(KIN.q_ready_rad) if s["recover"] else None)
    sequence = PickPlaceSequence(KIN, config, grasp, PlaceTarget(s["place"]))
    robot = FakeRobot(KIN, world)
    lowest_descent_z = [np.inf]

    def watch(r, seq):
        if seq.phase in ("descend", "close"):
            lowest_descent_z[0] = min(lowest_descent_z[0], KIN.fk(r.q)[2, 3])
        if s["cancel"] is None:
            return False
        phase, fraction = s["cancel"]
        return seq.phase == phase and seq.feedback(r.sim_s).phase_progress >= fraction

    run(sequence, robot, until=watch)
    canceled_at = None
    if not sequence.finished:  # `watch` stopped the run here: cancel, then let it finish
        canceled_at = sequence.phase
        robot.apply(sequence.cancel(robot.sim_s, robot.sim_s), sequence)
        end_s = robot.sim_s + 60.0
        while not sequence.finished and robot.sim_s < end_s:
            robot.step(sequence)
    out = sequence.outcome
    assert sequence.finished
    trajectories = [c.trajectory for c in robot.sent if isinstance(c, SendTrajectory)]
    assert trajectories, out.failure_reason
    for trajectory in trajectories:
        check_samples(trajectory)
    if canceled_at is not None:
        assert out.canceled and f"canceled during {canceled_at}" in out.failure_reason
        assert np.max(np.abs(robot.qd)) < 1e-6, "a canceled run must leave the arm at rest"
    else:
        assert out.success, out.failure_reason
    descended = out.phase_reached not in ("pre_grasp", "descend")
    if contact_z is not None and descended:
        assert out.contact_detected
        # Stopped within the force threshold's spring travel plus a couple of ticks at descent speed.
        travel_m = CONFIG.contact_force_threshold_n / CONTACT_STIFFNESS_N_PER_M
        assert lowest_descent_z[0] >= contact_z - travel_m - 2 * CONFIG.descent_speed_mps * 0.01 - 1e-3
    if canceled_at is not None and s["recover"]:
        assert out.arm_state == "observation_pose", out.recovery
    return {"canceled": canceled_at is not None, "contact": contact_z is not None and descended,
            "trajectories": len(trajectories), "recovered": canceled_at is not None and s["recover"],
            "via": s["via"] is not None}


def test_random_pick_and_place_runs_stay_within_limits_and_above_the_table():
    seen = []

    @settings(max_examples=24, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck), phases=(Phase.explicit, Phase.generate))  # no slow shrink
    @given(scenarios)
    def check(s):
        seen.append(run_scenario(s))

    check()
    # The random runs must cover the interesting cases, not only the happy path.
    assert sum(r["canceled"] for r in seen) >= 2 and sum(r["contact"] for r in seen) >= 2
    assert sum(r["recovered"] for r in seen) >= 2 and sum(r["via"] for r in seen) >= 2
    assert sum(r["trajectories"] for r in seen) >= 40

"""The simulated arm keeps wall-clock pace like a real one: after a stall (a busy machine) the simulation goes on
at most at max_real_time_factor instead of racing to make the lost time up (fake_panda_driver_node.SimPacer)."""
import pytest

from defgg_ros.nodes.fake_panda_driver_node import SimPacer

pytestmark = pytest.mark.unit

STEP_S = 1e-3   # one control period of sim time
STEP_CPU_S = 2e-4   # what a step costs in wall time: the simulation's capacity is 5x real time


def _run(pacer, wall_s, sim_s, sim_until_s):
    """Step the simulation as the sim thread does (step, then sleep what the pacer says); (wall, sim) at the end."""
    while sim_s < sim_until_s - 1e-9:
        sim_s += STEP_S
        wall_s += STEP_CPU_S
        wall_s += max(pacer.ahead_s(wall_s, sim_s), 0.0)
    return wall_s, sim_s


def test_after_a_stall_sim_time_never_runs_faster_than_wall_time():
    pacer = SimPacer(1.0, 0.0, 0.0)
    wall_s, sim_s = _run(pacer, 0.0, 0.0, 1.0)
    assert wall_s == pytest.approx(1.0, abs=2e-3)
    wall_s += 2.0   # the sim thread got no CPU for 2 s
    stall_end_wall_s = wall_s
    wall_s, sim_s = _run(pacer, wall_s, sim_s, sim_s + 0.5)
    # a cumulative pace made the 2 s up at capacity: 0.5 s of sim time in 0.1 s of wall time
    assert wall_s - stall_end_wall_s >= 0.5 - 0.02   # at most MAX_LAG_S (20 ms) made up


def test_the_pace_follows_the_real_time_factor_and_zero_is_unthrottled():
    wall_s, _ = _run(SimPacer(2.0, 0.0, 0.0), 0.0, 0.0, 1.0)
    assert wall_s == pytest.approx(0.5, abs=2e-3)
    wall_s, _ = _run(SimPacer(0.0, 0.0, 0.0), 0.0, 0.0, 1.0)
    assert wall_s == pytest.approx(1000 * STEP_CPU_S)

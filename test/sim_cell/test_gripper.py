"""The gripper state machine (pure): move/grasp outcomes from measured openings."""
import pytest

from defgg_ros.sim.cell.gripper import STALL_TIME_S, GripperCommandError, GripperController


def _feed(ctrl, widths, t0=0.0, dt=0.01):
    t = t0
    for w in widths:
        t += dt
        out = ctrl.update(t, w)
        if out is not None:
            return out
    return None


def test_move_arrives():
    ctrl = GripperController(0.08)
    ctrl.start_move(0.04, 0.05, 0.0)
    assert ctrl.motor.finger_target_m == pytest.approx(0.02)
    out = _feed(ctrl, [0.08 - 0.0005 * i for i in range(100)])
    assert out.success and out.width_m == pytest.approx(0.04, abs=0.002)
    assert not ctrl.busy


def test_move_blocked_fails_with_the_width():
    ctrl = GripperController(0.08)
    ctrl.start_move(0.0, 0.05, 0.0)
    out = _feed(ctrl, [0.08 - 0.001 * i for i in range(30)] + [0.05] * 100)
    assert not out.success and "blocked at 50.0 mm" in out.error


def test_grasp_succeeds_inside_the_band_and_fails_outside():
    n_stall = int(STALL_TIME_S / 0.01) + 5
    ctrl = GripperController(0.08)
    ctrl.start_grasp(0.05, 0.005, 0.005, 0.05, 20.0, 0.0)
    assert ctrl.motor.finger_target_m == 0.0 and ctrl.motor.finger_force_n == 20.0
    out = _feed(ctrl, [0.08 - 0.001 * i for i in range(28)] + [0.052] * n_stall)
    assert out.success and out.width_m == pytest.approx(0.052)
    ctrl.start_grasp(0.05, 0.005, 0.005, 0.05, 20.0, 10.0)
    out = _feed(ctrl, [0.052 - 0.001 * i for i in range(52)] + [0.0] * n_stall, t0=10.0)
    assert not out.success and "outside" in out.error


@pytest.mark.parametrize("args", [(0.09, 0.05), (-0.01, 0.05), (0.04, 0.0), (0.04, 0.5)])
def test_bad_move_goals_raise(args):
    with pytest.raises(GripperCommandError):
        GripperController(0.08).start_move(*args, 0.0)


def test_bad_grasp_force_raises():
    with pytest.raises(GripperCommandError, match="force"):
        GripperController(0.08).start_grasp(0.04, 0.005, 0.005, 0.05, 500.0, 0.0)


def test_a_grasp_held_still_with_contact_jitter_ends():
    """A soft object's FEM contact makes the opening jitter by microns at a 0.5 ms step: that
    is 2+ mm/s as a per-step speed, yet the fingers are not moving (the 2026-11-25 demo's
    sponge grasp timed out this way)."""
    ctrl = GripperController(0.08)
    ctrl.start_grasp(0.045, 0.01, 0.01, 0.05, 20.0, 0.0)
    closing = [0.08 - 0.00005 * i for i in range(640)]            # 0.1 m/s opening rate
    jitter = [0.0488 + (0.000002 if i % 2 else -0.000002) for i in range(2000)]
    out = _feed(ctrl, closing + jitter, dt=0.0005)
    assert out is not None and out.success, out
    assert out.width_m == pytest.approx(0.0488, abs=1e-5)


def test_slow_squeezing_is_not_a_stop():
    ctrl = GripperController(0.08)
    ctrl.start_grasp(0.03, 0.005, 0.005, 0.05, 20.0, 0.0)
    squeeze = [0.05 - 0.004 * 0.0005 * i for i in range(1000)]    # 4 mm/s for 0.5 s
    assert _feed(ctrl, squeeze, dt=0.0005) is None


def test_a_grasp_presses_once_its_fingers_slow_on_the_object_and_a_move_never_does():
    """Force control begins where the opening closes slower than half the grasp's speed over a window (the fingers
    met the object), and lasts until the next command; a move is a speed-driven position move throughout."""
    ctrl = GripperController(0.08)
    ctrl.start_grasp(0.0, 0.08, 0.08, 0.02, 10.0, 0.0)
    closing = [0.08 - 0.02 * 0.001 * i for i in range(1, 200)]          # 0.2 s at the commanded speed
    assert _feed(ctrl, closing, dt=0.001) is None and not ctrl.motor.press
    _feed(ctrl, [closing[-1] - 1e-6 * i for i in range(1, 60)], t0=0.2, dt=0.001)    # on the object: ~1 mm/s
    assert ctrl.motor.press and ctrl.motor.finger_force_n == 10.0
    ctrl.start_move(0.08, 0.05, 1.0)
    _feed(ctrl, [closing[-1]] * 100, t0=1.0, dt=0.001)                  # blocked, but a move does not press
    assert not ctrl.motor.press


def test_a_stop_ends_the_command_and_lets_go_of_the_force():
    """franka_gripper's cancel calls Gripper::stop: the grasp ends and no force is held (the simulated hand held
    the width with the move's 70 N, so a canceled grasp kept its object in simulation and not on a real hand)."""
    ctrl = GripperController(0.08)
    ctrl.start_grasp(0.0, 0.08, 0.08, 0.02, 10.0, 0.0)
    _feed(ctrl, [0.05] * 60, dt=0.001)                                   # blocked on the object: pressing
    assert ctrl.motor.press and ctrl.busy
    ctrl.stop()
    assert not ctrl.busy and not ctrl.motor.press and ctrl.motor.finger_force_n == 0.0
    assert ctrl.motor.finger_target_m == pytest.approx(0.025)            # where the fingers are
    assert _feed(ctrl, [0.05] * 30, t0=1.0) is None                      # nothing to report any more

"""The pressing grasp's rule (sim/finger_press.py), shared by the cell's hand and the trial hand: speed-limited
until the fingers are on the object, then each pushes with the force while it closes no faster than the limit."""
import pytest

from defgg_ros.sim.finger_press import (
    CONTACT_WINDOW_S,
    ContactWindow,
    FingerSpeeds,
    PressingClose,
    finger_pushes,
    on_object,
)

pytestmark = pytest.mark.unit

STEP_S = 0.001


def test_on_object_means_closing_slower_than_half_the_commanded_speed():
    # Both fingers at 0.05 m/s close the opening 2 mm in 20 ms; on the object below half of that.
    assert not on_object(0.0015, 0.05, CONTACT_WINDOW_S)
    assert on_object(0.0009, 0.05, CONTACT_WINDOW_S)


def test_a_finger_pushes_only_when_pressing_and_not_faster_than_the_limit():
    assert finger_pushes(True, 0.01, 0.05)
    assert not finger_pushes(True, 0.06, 0.05)       # the object is gone: speed drive again
    assert not finger_pushes(False, 0.0, 0.05)


def test_finger_speeds_are_measured_over_the_window_and_forget_a_reset():
    speeds = FingerSpeeds(window_s=0.01)
    for k in range(20):
        found = speeds.update(k * STEP_S, [0.04 - 0.001 * k, 0.04], STEP_S)
    assert found[0] == pytest.approx(1.0) and found[1] == 0.0
    speeds.clear()
    assert speeds.update(1.0, [0.0, 0.04], STEP_S) == [0.0, 0.0]   # a jump after a reset is no speed


def closing_then_blocked(close: PressingClose, steps_closing: int, steps_blocked: int) -> list:
    q, out = 0.04, []
    for k in range(steps_closing + steps_blocked):
        if k < steps_closing:
            q -= close.finger_speed_mps * STEP_S
        out.append(close.update(k * STEP_S, [q, q], STEP_S))
    return out


def test_a_pressing_close_is_speed_limited_until_blocked_then_pushes():
    close = PressingClose(finger_speed_mps=0.05, speed_limit_mps=0.05)
    modes = closing_then_blocked(close, 100, 100)
    assert not any(any(m) for m in modes[:100])          # closing freely: the speed drive
    assert all(all(m) for m in modes[-50:]) and close.pressing
    close.restart_window()
    assert close.pressing                                # a restored state keeps the press


def blocked_window_latches_at(window: ContactWindow, step_s: float, steps: int) -> int | None:
    """The step (1-based) at which a grasp blocked from the start is found on the object, the clock summed."""
    clock_s = 0.0
    window.start(clock_s, 0.05)
    for k in range(1, steps + 1):
        clock_s += step_s
        if window.update(clock_s, 0.05):
            return k
    return None


def test_one_contact_window_for_both_hands_and_what_its_tolerance_is_for():
    # 200 steps of 0.1 ms summed land a hair short of 20 ms: the clock's tolerance counts that as the window.
    assert blocked_window_latches_at(ContactWindow(0.01), 1e-4, 400) == 200
    window = ContactWindow(0.01)
    window.start(0.0, 0.05)
    assert not window.update(CONTACT_WINDOW_S, 0.05 - 0.0005)   # closed at the commanded speed: not on it yet
    assert window.update(2 * CONTACT_WINDOW_S, 0.05 - 0.0005)   # then stopped for a window: on it, and it stays
    assert window.update(3 * CONTACT_WINDOW_S, 0.0)


@pytest.mark.parametrize("step_s", [1e-3, 5e-4, 2.5e-4])
def test_the_cells_hand_uses_the_same_contact_window(step_s):
    """The cell's clock is summed step by step too (SimCell._step): a grasp blocked from its start presses after
    one window's steps wherever on that clock it starts (without the tolerance about half the starts took one
    step more)."""
    from defgg_ros.sim.cell.gripper import GripperController
    window_steps = round(CONTACT_WINDOW_S / step_s)
    clock_s, latched_after = 0.0, set()
    for _ in range(60):                       # grasps starting at 60 successive steps of one clock
        clock_s += step_s
        gripper = GripperController(0.08)
        gripper.start_grasp(0.05, 0.005, 0.005, 0.02, 5.0, now_s=clock_s)
        assert isinstance(gripper._contact, ContactWindow) and gripper._contact.finger_speed_mps == 0.01
        now_s = clock_s
        for k in range(1, 2 * window_steps):
            now_s += step_s
            gripper.update(now_s, 0.08)
            if gripper.motor.press:
                latched_after.add(k)
                break
    assert latched_after == {window_steps}

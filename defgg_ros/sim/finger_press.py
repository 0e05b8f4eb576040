"""The pressing grasp, one rule for the cell's hand (sim/cell) and the trial hand (sim/hand.py). No PyBullet.

franka_gripper's grasp closes at its speed and then holds its force on the object (docs/franka_contract.md). A
speed-driven PyBullet finger does not: the deformable contact takes its momentum every step, so it pressed an FEM
body with about that momentum per step whatever force it was given (docs/real_cell.md, "Grasp force on FEM
objects"). So a grasp is speed-limited until it is on the object, then each finger pushes with the force (torque
control), and goes back to the speed drive while it closes faster than the hand can (the object is gone).
"""
from __future__ import annotations

import collections

# On the object: the opening closed by less than CONTACT_SPEED_FRACTION of the commanded closing over a window of
# CONTACT_WINDOW_S (sim time).
CONTACT_WINDOW_S = 0.02
CONTACT_SPEED_FRACTION = 0.5
# Both hands' clocks are sums of their time steps, which land a hair short of a whole window (200 steps of 0.1 ms:
# 19.999999999999 ms): this much short still counts as one.
CLOCK_TOLERANCE_S = 1e-9
# A pressing finger's closing speed is measured over this window of positions: the deformable contact jitters a
# single step's speed.
PRESS_SPEED_WINDOW_S = 0.01


def on_object(closed_m: float, finger_speed_mps: float, elapsed_s: float) -> bool:
    """Is a grasp whose opening closed by `closed_m` in `elapsed_s` (>= CONTACT_WINDOW_S), both fingers driven at
    `finger_speed_mps`, on the object?"""
    return closed_m < CONTACT_SPEED_FRACTION * 2 * finger_speed_mps * elapsed_s


def finger_pushes(pressing: bool, closing_mps: float, speed_limit_mps: float) -> bool:
    """Does a finger push with the force (else: the speed drive)?"""
    return pressing and closing_mps <= speed_limit_mps


class FingerSpeeds:
    """Each finger's closing speed (m/s, positive = closing) over the last PRESS_SPEED_WINDOW_S of positions."""

    def __init__(self, window_s: float = PRESS_SPEED_WINDOW_S):
        self.window_s = window_s
        self._history = collections.deque()      # (sim s, finger positions)

    def clear(self) -> None:
        """Forget the history (the fingers were reset: a jump is no speed)."""
        self._history.clear()

    def update(self, now_s: float, positions_m, step_s: float) -> list:
        self._history.append((now_s, list(positions_m)))
        while now_s - self._history[0][0] > self.window_s:
            self._history.popleft()
        then_s, before = self._history[0]
        elapsed_s = max(now_s - then_s, step_s)
        return [(b - q) / elapsed_s for b, q in zip(before, positions_m)]


class ContactWindow:
    """Is a closing grasp on the object (on_object)? Checked at the end of each window of CONTACT_WINDOW_S of sim
    time (CLOCK_TOLERANCE_S short still counts); once on, it stays on."""

    def __init__(self, finger_speed_mps: float):
        self.finger_speed_mps = finger_speed_mps
        self.on = False
        self._start = None                        # (sim s, opening) the running window began at

    def start(self, now_s: float, opening_m: float) -> None:
        self._start = (now_s, opening_m)

    def restart(self) -> None:
        """The next update begins a new window (the fingers were reset); on stays on."""
        self._start = None

    def update(self, now_s: float, opening_m: float) -> bool:
        if self.on:
            return True
        if self._start is None:
            self.start(now_s, opening_m)
        start_s, start_m = self._start
        if now_s - start_s >= CONTACT_WINDOW_S - CLOCK_TOLERANCE_S:
            self.on = on_object(start_m - opening_m, self.finger_speed_mps, now_s - start_s)
            self._start = (now_s, opening_m)
        return self.on


class PressingClose:
    """One grasp's pressing close, fed each step: which fingers push with the force."""

    def __init__(self, finger_speed_mps: float, speed_limit_mps: float):
        self.speed_limit_mps = speed_limit_mps
        self.contact = ContactWindow(finger_speed_mps)
        self.speeds = FingerSpeeds()

    @property
    def finger_speed_mps(self) -> float:
        return self.contact.finger_speed_mps

    @property
    def pressing(self) -> bool:
        return self.contact.on

    def update(self, now_s: float, finger_positions_m, step_s: float) -> list:
        """Finger positions (m, each from the TCP) after the last step -> per finger: push with the force?"""
        pressing = self.contact.update(now_s, sum(finger_positions_m))
        speeds = self.speeds.update(now_s, finger_positions_m, step_s)
        return [finger_pushes(pressing, v, self.speed_limit_mps) for v in speeds]

    def restart_window(self) -> None:
        """The fingers were reset (a saved state restored): speeds start again; a press stays a press."""
        self.speeds.clear()
        self.contact.restart()

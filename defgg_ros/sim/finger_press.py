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


class PressingClose:
    """One grasp's pressing close, fed each step: which fingers push with the force."""

    def __init__(self, finger_speed_mps: float, speed_limit_mps: float):
        self.finger_speed_mps, self.speed_limit_mps = finger_speed_mps, speed_limit_mps
        self.pressing = False
        self.speeds = FingerSpeeds()
        self._window = None                       # (sim s, opening) the running contact window began at

    def update(self, now_s: float, finger_positions_m, step_s: float) -> list:
        """Finger positions (m, each from the TCP) after the last step -> per finger: push with the force?"""
        opening_m = sum(finger_positions_m)
        if self._window is None:
            self._window = (now_s, opening_m)
        start_s, start_m = self._window
        if not self.pressing and now_s - start_s >= CONTACT_WINDOW_S - 1e-9:
            self.pressing = on_object(start_m - opening_m, self.finger_speed_mps, now_s - start_s)
            self._window = (now_s, opening_m)
        speeds = self.speeds.update(now_s, finger_positions_m, step_s)
        return [finger_pushes(self.pressing, v, self.speed_limit_mps) for v in speeds]

    def restart_window(self) -> None:
        """The fingers were reset (a saved state restored): speeds start again; a press stays a press."""
        self.speeds.clear()
        self._window = None

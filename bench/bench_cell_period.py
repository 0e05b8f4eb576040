"""What one 1 kHz control period of the simulated driver costs, call by call, alone and beside a busy thread.

    .venv/bin/python bench/bench_cell_period.py [--periods 500]

The driver's sim thread calls, every period: SimCell.advance(1 ms), joint_state(), external_wrench(), the trajectory
tracker's sample() and (with a reader) hand_tcp_pose(). Two cases: `rigid` (rigid_box.yaml, the arm swaying) and
`fem-press` (soft_box.yaml, the FEM box active, the closed hand pressed into it: contacts on the hand). Each runs
alone and beside a second Python thread that only counts (as the driver's ROS threads and the executor's share its
process's GIL in the tests). Then numpy calls on 3-vectors, per second alone and beside the busy thread: a call that
gives the GIL up (np.dot, and np.linalg.norm through it) must wait for it behind that thread each time.
Nothing is asserted; the machine is shared, so compare rows of one run.
"""
import argparse
import collections
import math
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.sim.cell.sim_cell import CellSettings, SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

SCENES = ROOT / "sim_bringup" / "scenes"
PERIOD_S = 0.001


class BusyThread:
    """A second Python thread that only counts, while the block runs."""

    def __init__(self, on: bool):
        self.on, self._stop = on, threading.Event()
        self._thread = threading.Thread(target=self._count, daemon=True)

    def _count(self):
        n = 0
        while not self._stop.is_set():
            for i in range(1000):
                n += i

    def __enter__(self):
        if self.on:
            self._thread.start()
        return self

    def __exit__(self, *_):
        self._stop.set()
        if self.on:
            self._thread.join()


def sway(cell):
    q = cell.joint_state().positions[:7].copy()
    cell.command_trajectory([(5.0, q + 0.1, None, None), (10.0, q, None, None)])


def press(cell):
    """The closed hand 3 cm into the FEM box, held there (contacts on the fingers)."""
    q0 = cell.joint_state().positions[:7].copy()
    xyz, _ = cell.object_poses()[0]
    solution, _ = PandaKinematics().top_down_ik([xyz[0] + 0.01, xyz[1], 0.03], 0.3, q0)
    cell.gripper_move(0.0, 0.05)
    cell.command_trajectory([(2.0, solution.q_rad, None, None)])
    cell.advance(2.5)


def period_costs(cell, periods: int) -> dict:
    calls = (("advance", lambda: cell.advance(PERIOD_S)), ("joint_state", cell.joint_state),
             ("external_wrench", cell.external_wrench), ("tracker.sample", lambda: cell.tracker.sample(cell.time_s)),
             ("hand_tcp_pose", cell.hand_tcp_pose))
    costs = collections.Counter()
    for _ in range(periods):
        for name, call in calls:
            started = time.perf_counter()
            call()
            costs[name] += time.perf_counter() - started
    return {name: total / periods * 1e6 for name, total in costs.items()}


def numpy_rates(seconds: float = 0.5) -> list:
    v, w = np.array([0.1, 0.2, 0.3]), np.array([0.3, 0.1, 0.2])
    calls = {"np.dot(v, w)": lambda: np.dot(v, w), "v @ w": lambda: v @ w,
             "np.linalg.norm(v)": lambda: np.linalg.norm(v), "np.cross(v, w)": lambda: np.cross(v, w),
             "v + w": lambda: v + w, "math.hypot(*v)": lambda: math.hypot(*(float(x) for x in v))}
    rows = []
    for name, call in calls.items():
        rates = []
        for busy in (False, True):
            with BusyThread(busy):
                n, stop = 0, time.monotonic() + seconds
                while time.monotonic() < stop:
                    for _ in range(100):
                        call()
                    n += 100
            rates.append(n / seconds)
        rows.append((name, *rates))
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--periods", type=int, default=500, help="control periods measured per case")
    args = parser.parse_args()
    print(f"# bench_cell_period: {args.periods} periods of {PERIOD_S * 1e3:g} ms per case; us per call")
    for case, scene, active, prepare in (("rigid", "rigid_box.yaml", False, sway),
                                         ("fem-press", "soft_box.yaml", True, press)):
        cell = SimCell(load_scene(SCENES / scene), CellSettings(soft_always_active=active))
        try:
            prepare(cell)
            for busy in (False, True):
                with BusyThread(busy):
                    costs = period_costs(cell, args.periods)
                label = "beside a busy thread" if busy else "alone"
                print(f"{case:<10} {label:<21} " + "  ".join(f"{k} {v:.0f}" for k, v in costs.items()))
        finally:
            cell.close()
    print("# numpy on 3-vectors, calls per second: alone / beside a busy thread")
    for name, alone, busy in numpy_rates():
        print(f"{name:<18} {alone / 1e3:8.0f}k / {busy / 1e3:8.1f}k")


if __name__ == "__main__":
    main()

"""Does each motion start where the arm is, and does the held block stay put? In one process and in the ROS cell.

In one process (PyBullet, no ROS): rigid_box.yaml's block picked with the demo's grasp and the sim cell's
executor parameters, the sequence fed joint states --lags periods late (a busy ROS cell delivered them 10-30 ms
late, 2026-11-28). Prints per lag: success, the pick's sim duration, the largest jump between a trajectory's
first point and the arm (largest joint), and how far the block moved in the hand while held.

With --ros-runs N: N `defgg-demo` runs on rigid_box.yaml (real nodes, real DDS), the fake driver's cell
instrumented from outside (bench/hooks/sitecustomize.py); prints per run the largest start jump of any
trajectory (from the driver's side), the block's largest move in the hand while held, and the TCP's peak
acceleration while held (second differences of 5 ms samples logged to 10 nm: rounding adds < 0.01 m/s^2).
--repo measures another checkout (e.g. a `git worktree` of an older commit) the same way, to compare before and
after a change: its demo for the ROS runs, its code for the in-process picks (older code: lag 0 only, and no
start jumps when its CellSequenceDriver did not record them).

    .venv/bin/python bench/bench_motion_start.py [--lags 0 3 6] [--ros-runs 6] [--repo /tmp/old]
"""
import argparse
import glob
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SCENE = ROOT / "sim_bringup" / "scenes" / "rigid_box.yaml"
# The demo's grasp on that block (defgg-demo's log, 2026-11-28): centre, yaw, width, E, force a finger.
GRASP = ((0.50396, 0.04357, 0.05), 0.30092, 0.0639, 2e9, 1.709)
PLACE_XYZ_M = (0.35, -0.45, 0.12)


def release_sent(sequence) -> bool:
    # Checkouts older than the public property (--repo) only have the private flag.
    return sequence.release_sent if hasattr(sequence, "release_sent") else sequence._placed_open_sent


def in_process(lag_periods: int) -> str:
    import pybullet as p

    from defgg_ros.bringup.cell_sequence import CellSequenceDriver
    from defgg_ros.bringup.node_set import load_node_set
    from defgg_ros.control.kinematics import PandaKinematics
    from defgg_ros.control.pick_place import PickPlaceSequence
    from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget
    from defgg_ros.demo import executor_params
    from defgg_ros.nodes.executor_node import ExecutorNode
    from defgg_ros.sim.cell.sim_cell import SimCell
    from defgg_ros.sim.scene_spec import load_scene

    config = ExecutorNode._sequence_config(executor_params(load_node_set("sim_cell")))
    cell = SimCell(load_scene(str(SCENE)))
    try:
        sequence = PickPlaceSequence(PandaKinematics(), config, GraspTarget(*GRASP), PlaceTarget(PLACE_XYZ_M))
        lagged = {"state_lag_periods": lag_periods} if lag_periods else {}   # older drivers had no lag
        driver, in_hand = CellSequenceDriver(cell, sequence, **lagged), []

        def record(c):
            if sequence.phase in ("lift", "transfer", "place") and not release_sent(sequence):
                tcp = c.tcp_pose()
                inv = p.invertTransform(tcp[0], tcp[1])
                in_hand.append(p.multiplyTransforms(inv[0], inv[1], c.object_poses()[0][0], [0, 0, 0, 1])[0])

        outcome = driver.run(60.0, record)
        jumps = getattr(driver, "start_jumps_rad", None)
        jump_mrad = f"{max(jumps) * 1000:.1f}" if jumps else "(not recorded)"
        moved = np.linalg.norm(np.array(in_hand) - in_hand[0], axis=1).max() * 1000 if in_hand else float("nan")
        return (f"lag {lag_periods} periods ({lag_periods * 10} ms): success {outcome.success}, "
                f"{outcome.duration_s:.2f} s sim, largest start jump {jump_mrad} mrad, "
                f"block moved in the hand {moved:.1f} mm while held")
    finally:
        cell.close()


def read_log(path: str):
    lines = {"S": [], "T": [], "G": [], "M": []}
    for line in open(path):
        kind, *values = line.split()
        lines[kind].append([float(v) for v in values])
    return {kind: np.array(rows) for kind, rows in lines.items()}


def held_figures(log: dict):
    """(largest start jump mrad of any trajectory; block moved in the hand mm and peak TCP acceleration m/s^2
    while the block was held: from the lift's start (the first trajectory after the grasp command, sent once
    the fingers have stopped on the block) until the next gripper move); None without a grasp or lift."""
    steps, starts = log["S"], log["T"]
    t, tcp, rel = steps[:, 0], steps[:, 1:4], steps[:, 4:7]
    if not len(log["G"]) or not len(starts):
        return None
    grasp_s = log["G"][0, 0]
    lift_s = min([row[0] for row in starts if row[0] > grasp_s], default=None)
    if lift_s is None:
        return None
    release_s = min([m for (m,) in log["M"] if m > lift_s], default=t[-1])
    k0, k1 = np.searchsorted(t, lift_s), np.searchsorted(t, release_s)
    if k1 - k0 < 3:
        return None
    moved = np.linalg.norm(rel[k0:k1] - rel[k0], axis=1).max() * 1000
    dt = np.diff(t[k0:k1])
    v = np.diff(tcp[k0:k1], axis=0) / dt[:, None]
    accel = np.linalg.norm(np.diff(v, axis=0) / dt[1:, None], axis=1).max()
    jumps = np.abs(starts[:, 1:8] - starts[:, 8:15]).max(axis=1) * 1000
    return jumps.max(), moved, accel


def ros_run(index: int, repo: Path, folder: Path) -> str:
    log = folder / f"cell{index}"
    env = dict(os.environ, DEFGG_BENCH_CELL_LOG=str(log),
               PYTHONPATH=os.pathsep.join([str(ROOT / "bench" / "hooks"), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "defgg_ros.demo", "--scene", str(SCENE),
                           "--out", str(folder / f"demo{index}")], cwd=repo, env=env, capture_output=True,
                          text=True, timeout=600)
    row = [line for line in proc.stdout.splitlines() if line.startswith("wooden_block")]
    verdict = " ".join(row[0].split()[7:10]) if row else f"no result (exit {proc.returncode})"
    logs = [f for f in glob.glob(f"{log}.*") if os.path.getsize(f) > 0]   # only the driver's cell writes
    figures = held_figures(read_log(logs[0])) if logs else None
    if figures is None:
        return f"run {index}: {verdict}; the hand never held the block"
    jump, moved, accel = figures
    return (f"run {index}: phase/held/in bin {verdict}; largest start jump {jump:.1f} mrad, block moved in the "
            f"hand {moved:.1f} mm while held, peak TCP acceleration {accel:.1f} m/s^2")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lags", type=int, nargs="*", default=[0, 3, 6],
                        help="joint-state delays to try in one process, in 10 ms control periods")
    parser.add_argument("--ros-runs", type=int, default=0, help="defgg-demo runs in the ROS cell (~25 s each)")
    parser.add_argument("--repo", type=Path, default=ROOT, help="checkout to measure (default: this one)")
    args = parser.parse_args(argv)
    if args.repo.resolve() != ROOT:
        sys.path.insert(0, str(args.repo.resolve()))   # its defgg_ros for the in-process picks
    for lag in args.lags:
        print(in_process(lag), flush=True)
    with tempfile.TemporaryDirectory(prefix="bench_motion_start_") as tmp:
        for i in range(args.ros_runs):
            print(ros_run(i, args.repo.resolve(), Path(tmp)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

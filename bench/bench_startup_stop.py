"""Does a node stop when the launcher's SIGINT lands while it is still starting?

Starts one node process at a time (the fake driver on the rigid scene, or the segmentation node) in a
private localhost-only ROS domain, sends SIGINT to it DELAY seconds after the start, and prints for each
delay how it ended: its exit code (0: a clean stop; -2: interrupted while Python imported modules, before
the node existed; 1: a traceback), or "ran on" if it was still running STOP_WAIT_S later (the signal was
lost; the bringup's stop then waits 10 s and sends SIGTERM). The window that matters is the node's import
(trimesh's optional imports catch BaseException) and its constructor (rclpy shuts the context down under it).

  .venv/bin/python bench/bench_startup_stop.py --node fake_panda_driver --delays 0.4 0.45 0.5 0.55 0.6
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODULES = {"fake_panda_driver": "defgg_ros.nodes.fake_panda_driver_node",
           "segmentation_node": "defgg_ros.nodes.segmentation_node"}
STOP_WAIT_S = 8.0


def _argv(node: str) -> list:
    argv = [sys.executable, "-m", MODULES[node], "--ros-args",
            "--params-file", str(ROOT / "sim_bringup" / "config" / f"{node}.yaml")]
    if node == "fake_panda_driver":
        argv += ["-p", f"scene_file:={ROOT / 'sim_bringup' / 'scenes' / 'rigid_box.yaml'}"]
    return argv


def stop_after(node: str, delay_s: float, domain: int) -> tuple[str, str]:
    """How the node ended when SIGINTed delay_s after its start, and its last output line."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.Popen(_argv(node), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                            cwd=ROOT, start_new_session=True)
    time.sleep(delay_s)
    os.killpg(proc.pid, signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=STOP_WAIT_S)
        ended = f"exit {proc.returncode}"
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        ended = "ran on"
    lines = [line for line in out.splitlines() if line.strip() and not line.startswith("pybullet build")]
    return ended, (lines[-1][:120] if lines else "")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--node", choices=sorted(MODULES), default="fake_panda_driver")
    parser.add_argument("--delays", type=float, nargs="+", default=[0.4, 0.45, 0.5, 0.55, 0.6, 0.8, 1.0, 2.0],
                        help="seconds from the start to the SIGINT, one run each")
    parser.add_argument("--domain", type=int, default=77, help="ROS domain id of the runs (localhost only)")
    args = parser.parse_args(argv)
    counts = {}
    for delay in args.delays:
        ended, last = stop_after(args.node, delay, args.domain)
        counts[ended] = counts.get(ended, 0) + 1
        print(f"{args.node}: SIGINT at {delay:.2f} s -> {ended}" + (f"   ({last})" if ended != "exit 0" else ""),
              flush=True)
    print(f"{args.node}: {len(args.delays)} runs: " + ", ".join(f"{k} x{v}" for k, v in sorted(counts.items())))
    return 1 if "ran on" in counts or "exit 1" in counts else 0


if __name__ == "__main__":
    sys.exit(main())

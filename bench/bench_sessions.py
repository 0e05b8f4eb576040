"""Recorded sessions: camera-sized messages between processes, and replay wall time per session.

1. transport: a segmentation_node process gets N 640x480 depth frames (0.6 MB, best effort) from this
   process and answers each with a 1.2 MB stiffness image; counts the answers with Fast DDS's default
   transports and with defgg_ros/ros/fastdds_profile.xml (each variant in a fresh child process,
   because the profile is read when the DDS participant starts).
2. replay: `defgg-replay` over each committed session (sim_bringup/sessions), wall time per session.

    .venv/bin/python bench/bench_sessions.py [--frames 27] [--skip-replay]
"""
import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from defgg_ros.ros.domain import pick_private_domain

REPO = Path(__file__).resolve().parents[1]


def transport_child(n_frames: int) -> None:
    """Runs in a child process: publish frames, count stiffness images back, print the count."""
    import rclpy
    from sensor_msgs.msg import Image

    from defgg_ros.ros import qos
    from defgg_ros.ros.cell_client import CellClient
    from defgg_ros.ros.executor import ThreadedExecutor
    from defgg_ros.sessions.player import SessionPlayer
    from defgg_ros.sessions.replay_nodes import NodeGraph, NodeSpec
    from defgg_ros.sessions.session import load_session

    frames = load_session(REPO / "sim_bringup" / "sessions" / "soft_objects").frames
    received = []
    with NodeGraph(tempfile.mkdtemp(prefix="bench_sessions_")) as graph:
        graph.start(NodeSpec("segmentation_node", "defgg_ros.nodes.segmentation_node"))
        rclpy.init()
        player = SessionPlayer()
        player.create_subscription(Image, "/defgg/stiffness/youngs_modulus_pa", received.append, qos.SENSOR_DATA)
        executor = ThreadedExecutor()
        executor.add_node(player)
        threading.Thread(target=executor.spin, daemon=True).start()
        CellClient(player).stiffness_client.wait_for_service(timeout_sec=60.0)
        for i in range(n_frames):
            player._send(frames[i % len(frames)])
            time.sleep(0.3)  # a 3 Hz camera
        time.sleep(2.0)      # late answers
        executor.shutdown()
        rclpy.try_shutdown()
    print(len(received))


def transport(n_frames: int) -> None:
    for name, profile in (("default transports", None),
                          ("fastdds_profile.xml", str(REPO / "defgg_ros" / "ros" / "fastdds_profile.xml"))):
        env = {k: v for k, v in os.environ.items() if k != "FASTRTPS_DEFAULT_PROFILES_FILE"}
        env.update(ROS_DOMAIN_ID=str(pick_private_domain()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
        if profile:
            env["FASTRTPS_DEFAULT_PROFILES_FILE"] = profile
        out = subprocess.run([sys.executable, __file__, "--child", str(n_frames)], env=env, capture_output=True,
                             text=True, timeout=600, check=True).stdout.split()
        print(f"transport, {name}: {out[-1]} of {n_frames} stiffness images came back")


def replay() -> None:
    sessions = sorted(p for p in (REPO / "sim_bringup" / "sessions").iterdir() if (p / "metadata.yaml").is_file())
    for session in sessions:
        size_kb = sum(f.stat().st_size for f in session.iterdir()) / 1024
        start = time.monotonic()
        code = subprocess.run([sys.executable, "-m", "defgg_ros.sessions.replay", str(session)],
                              capture_output=True, timeout=900).returncode
        print(f"replay {session.name}: {time.monotonic() - start:.1f} s wall, exit {code}, bag {size_kb:.0f} kB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=27, help="depth frames sent per transport variant")
    parser.add_argument("--skip-replay", action="store_true", help="only the transport measurement")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        transport_child(args.child)
        return
    print(f"load average at start: {os.getloadavg()[0]:.1f} (2 cores)")
    transport(args.frames)
    if not args.skip_replay:
        replay()


if __name__ == "__main__":
    main()

"""How hard the transfer accelerates the held object, with and without transfer_max_tcp_accel_mps2.

The 2026-11-28 recovery-cell grasp (rigid_box.yaml's 126 g block, grasp at (0.504, 0.044), 1.44 N a finger:
the labels' rule at 2e6 Pa) picked in the simulated cell (PyBullet, in one process, no ROS) with the executor's
sequence; prints, per cap, the transfer's duration and its peak TCP acceleration (second differences of the
FK positions of the points sent), and where the block ended.

    .venv/bin/python bench/bench_transfer_accel.py
"""
import argparse
import dataclasses
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.bringup.cell_sequence import CellSequenceDriver  # noqa: E402
from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.control.pick_place import PickPlaceSequence  # noqa: E402
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget, SendTrajectory, SequenceConfig  # noqa: E402
from defgg_ros.control.trajectories import tcp_peak_acceleration_mps2  # noqa: E402
from defgg_ros.sim.cell.sim_cell import SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

GRASP = GraspTarget((0.50396, 0.04357, 0.05), 0.30092, 0.0634, 2e6, 1.4426)
PLACE = PlaceTarget((0.35, -0.45, 0.12), None)


def pick(cap_mps2):
    kin, cell = PandaKinematics(), SimCell(load_scene(str(ROOT / "sim_bringup/scenes/rigid_box.yaml")))
    try:
        config = dataclasses.replace(SequenceConfig(descent_speed_mps=0.01), transfer_max_tcp_accel_mps2=cap_mps2)
        sequence = PickPlaceSequence(kin, config, GRASP, PLACE)
        driver, sent = CellSequenceDriver(cell, sequence), []
        apply = driver.apply
        driver.apply = lambda commands: (sent.extend(commands), apply(commands))
        outcome = driver.run(60.0)
        transfer = [c.trajectory for c in sent if isinstance(c, SendTrajectory)][3]   # pre-grasp, descent, lift
        return outcome, transfer.duration_s, tcp_peak_acceleration_mps2(kin, transfer), cell.object_poses()[0][0]
    finally:
        cell.close()


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    for cap in (None, 3.0):
        outcome, duration_s, peak, block = pick(cap)
        print(f"cap {cap}: transfer {duration_s:.2f} s, peak TCP acceleration {peak:.2f} m/s^2; "
              f"success {outcome.success}; block at ({block[0]:.3f}, {block[1]:.3f}, {block[2]:.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

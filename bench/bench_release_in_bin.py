"""Where the demo's rubber block ends after its place, over many in-process picks.

Why: one `make demo` run in 12 (bench/README.md, 2026-11-28) placed the rubber block (2e6 Pa FEM, 27 nodes)
"done, held after transfer" and then found it 12 km under the table: it left the table top right after the
release. Over DDS a run is not repeatable; here the same pick runs in one process (no ROS,
defgg_ros.bringup.demo_in_process), so a run that loses the block can be replayed and looked at.

Each trial: a fresh demo cell (sim_bringup/scenes/demo.yaml), the executor's parameters (schema defaults plus
the sim cell's overrides), a grasp at the block's top centre moved by up to --offset-mm and turned by up to
--yaw-deg, closed with --force-n a finger (the fem_v5 pair's rule gave 1.2 N in the demo), placed as the demo
places it (its quadrant of the bin, released at demo_geometry.release_tcp_z, the grasp's yaw), then the cell
runs --settle-s more. Prints per trial the outcome, where the block ended, its lowest centroid height and its
fastest centroid speed after the release, and a summary: in the bin, on the table elsewhere, under the table.

    .venv/bin/python bench/bench_release_in_bin.py [--trials 20] [--seed 1] [--slot 2]
"""
import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.bringup.demo_in_process import pick_into_bin  # noqa: E402
from defgg_ros.bringup.node_set import load_node_set  # noqa: E402
from defgg_ros.constants import OFF_TABLE_DEPTH_M  # noqa: E402
from defgg_ros.demo import executor_params  # noqa: E402
from defgg_ros.nodes.executor_node import ExecutorNode  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

SCENE = ROOT / "sim_bringup" / "scenes" / "demo.yaml"


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", type=Path, default=SCENE, help="scene YAML (default: the demo's)")
    parser.add_argument("--table-before-2026-11-28", dest="old_table", action="store_true",
                        help="the demo table as it was (1.2 x 1.0 m about (0.45, 0)): the bin's walls hung 7 cm "
                             "over its edge (the scene files no longer do; the table is swapped in here)")
    parser.add_argument("--trials", type=int, default=20, help="picks, each in a fresh cell (~21 CPU s each)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the grasp offsets and turns")
    parser.add_argument("--object", default="rubber_block", help="scene object to pick (default rubber_block)")
    parser.add_argument("--slot", type=int, default=2, help="bin quadrant slot (the rubber block is the demo's 3rd)")
    parser.add_argument("--force-n", type=float, default=1.2, help="grip force a finger (N)")
    parser.add_argument("--offset-mm", type=float, default=8.0, help="largest grasp offset from the top centre")
    parser.add_argument("--yaw-deg", type=float, default=30.0, help="largest grasp turn from the block's yaw")
    parser.add_argument("--settle-s", type=float, default=4.0, help="sim time after the sequence ends")
    return parser.parse_args(argv)


def one_trial(args, config, release_max_z_m, rng):
    scene = load_scene(args.scene)
    if args.old_table:
        scene = dataclasses.replace(scene, table_size_m=(1.2, 1.0, 0.05), table_center_xy_m=(0.45, 0.0))
    angle = rng.uniform(0, 2 * np.pi)
    offset = rng.uniform(0, args.offset_mm) * 1e-3 * np.array([np.cos(angle), np.sin(angle)])
    yaw_offset = np.radians(rng.uniform(-args.yaw_deg, args.yaw_deg))
    placed = pick_into_bin(scene, args.object, config, args.slot, offset, yaw_offset, args.force_n,
                           release_max_z_m, args.settle_s)
    return placed, offset, yaw_offset


def main(argv=None) -> int:
    args = parse_args(argv)
    params = executor_params(load_node_set("sim_cell"))
    config, release_max_z_m = ExecutorNode._sequence_config(params), float(params["place_position_m"][2])
    rng = np.random.default_rng(args.seed)
    counts = {"in the bin": 0, "under the table": 0, "elsewhere": 0, "pick failed": 0}
    table = "table before 2026-11-28" if args.old_table else "table of the scene"
    print(f"{args.object}: {args.trials} picks, force {args.force_n} N a finger, slot {args.slot}, seed {args.seed}, "
          f"{table}")
    for i in range(args.trials):
        t0 = time.process_time()
        r, offset, yaw_offset = one_trial(args, config, release_max_z_m, rng)
        where = ("pick failed" if not r.success else "in the bin" if r.in_bin else
                 "under the table" if r.final_m[2] < -OFF_TABLE_DEPTH_M else "elsewhere")
        counts[where] += 1
        f = r.final_m
        print(f"{i:3d} offset ({offset[0] * 1e3:+5.1f}, {offset[1] * 1e3:+5.1f}) mm yaw {np.degrees(yaw_offset):+5.1f} "
              f"deg: {where:15s} end ({f[0]:.3f}, {f[1]:.3f}, {f[2]:.3f}) m, lowest {r.lowest_z_m:.3f} m, fastest "
              f"after release {r.fastest_after_release_mps:.2f} m/s {r.failure_reason[:60]} "
              f"[{time.process_time() - t0:.0f} CPU s]", flush=True)
    print("summary: " + ", ".join(f"{k} {v}/{args.trials}" for k, v in counts.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())

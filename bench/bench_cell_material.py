"""What the simulated cell's object material changes in a pick: the legacy material (friction 0.8 x 0.8 =
0.64, Poisson's ratio 0.4) against the shipped weights' protocol's (defgraspsim: pads 1.0 x object 0.7 = 0.7,
Poisson's ratio 0.3; defgg_ros/sim/cell/objects.MATERIAL).

Each pick runs in one process (defgg_ros.bringup.cell_sequence.CellSequenceDriver, the executor's sequence and
parameters of the sim cell), in a fresh cell of its scene: a grasp at the object's top centre (moved by
--offset-mm in --picks directions, the first at the centre), closing across its x side with the fem_v5 pair's
grip rule (defgraspsim, friction 0.7: half of FOS * m * g / 0.7 a finger), placed in the bin as the demo places
it. Prints per pick: success, the gripper width closed on the object, held after lift / transfer, how far the
object slid in the hand between the lift and the release (mm), whether it ended in the bin; then a summary per
material.

    .venv/bin/python bench/bench_cell_material.py [--material legacy defgraspsim] [--picks 1]
"""
import argparse
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pybullet as p

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.bringup.cell_sequence import CellSequenceDriver  # noqa: E402
from defgg_ros.bringup.demo_geometry import bin_place_xy, in_bin, release_tcp_z  # noqa: E402
from defgg_ros.bringup.demo_in_process import MAX_SEQUENCE_SIM_S, closing_width_m  # noqa: E402
from defgg_ros.bringup.node_set import load_node_set  # noqa: E402
from defgg_ros.control.kinematics import PandaKinematics  # noqa: E402
from defgg_ros.control.pick_place import PickPlaceSequence  # noqa: E402
from defgg_ros.control.sequence_types import GraspTarget, PlaceTarget  # noqa: E402
from defgg_ros.demo import executor_params  # noqa: E402
from defgg_ros.grip_force import LabelGripRule  # noqa: E402
from defgg_ros.nodes.executor_node import ExecutorNode  # noqa: E402
from defgg_ros.sim import physics  # noqa: E402
from defgg_ros.sim.cell import objects as cell_objects  # noqa: E402
from defgg_ros.sim.cell.sim_cell import SimCell  # noqa: E402
from defgg_ros.sim.scene_spec import load_scene  # noqa: E402

SCENES = ROOT / "sim_bringup" / "scenes"
PICKS = (("soft_box", "foam_block"), ("rigid_box", "wooden_block"), ("demo", "sponge"), ("demo", "foam_cube"),
         ("demo", "rubber_block"), ("demo", "wooden_can"))
GRIP_RULE = LabelGripRule("defgraspsim", 0.7)    # the fem_v5 pair's (models/defgg_cnn.md)


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--material", nargs="+", default=["legacy", "defgraspsim"], choices=sorted(physics.MATERIALS),
                        help="the cell objects' materials to compare (physics.MATERIALS)")
    parser.add_argument("--picks", type=int, default=1, help="picks per object: the centre, then offset ones")
    parser.add_argument("--offset-mm", type=float, default=6.0, help="grasp offset of the 2nd.. picks")
    parser.add_argument("--only", default="", help="scene:object to run alone (e.g. demo:rubber_block)")
    return parser.parse_args(argv)


def in_hand_m(cell, index) -> np.ndarray:
    """The object's centroid in the TCP frame."""
    tcp, quat = cell.tcp_pose()
    rotation = np.asarray(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
    return rotation.T @ (cell.object_poses()[index][0] - tcp)


def one_pick(scene_name, name, config, release_max_z_m, offset_xy_m, slot=0) -> dict:
    scene = load_scene(SCENES / f"{scene_name}.yaml")
    index = [o.name for o in scene.objects].index(name)
    spec = scene.objects[index]
    cell = SimCell(scene)
    try:
        start, _ = cell.object_poses()[index]
        force_n = GRIP_RULE.finger_force_n(spec.youngs_modulus_pa, spec.mass_kg)
        grasp = GraspTarget((start[0] + offset_xy_m[0], start[1] + offset_xy_m[1], spec.height_m), spec.yaw_rad,
                            closing_width_m(spec), spec.youngs_modulus_pa, force_n)
        bins = asdict(scene.bin)
        x, y = bin_place_xy(bins, slot)
        place = PlaceTarget((x, y, release_tcp_z(spec.height_m, bins, release_max_z_m)), None)
        sequence = PickPlaceSequence(PandaKinematics(), config, grasp, place)
        in_hand = {}          # phase -> [object in the TCP frame] while the fingers hold it

        def record(c):
            if sequence.phase in ("lift", "transfer"):
                in_hand.setdefault(sequence.phase, []).append(in_hand_m(c, index))

        outcome = CellSequenceDriver(cell, sequence).run(MAX_SEQUENCE_SIM_S, on_period=record)
        moved = [v for phase in ("lift", "transfer") for v in in_hand.get(phase, [])]
        slip_mm = float(np.linalg.norm(moved[-1] - moved[0]) * 1e3) if moved else float("nan")
        final = cell.object_poses()[index][0]
        return {"success": outcome.success, "width_mm": outcome.gripper_width_closed_m * 1e3, "force_n": force_n,
                "held_lift": outcome.held_after_lift, "held_transfer": outcome.held_after_transfer,
                "slip_mm": slip_mm, "in_bin": bool(in_bin(final, bins)), "reason": outcome.failure_reason}
    finally:
        cell.close()


def main(argv=None) -> int:
    args = parse_args(argv)
    params = executor_params(load_node_set("sim_cell"))
    config, release_max_z_m = ExecutorNode._sequence_config(params), float(params["place_position_m"][2])
    picks = [tuple(args.only.split(":"))] if args.only else PICKS
    angles = np.linspace(0, 2 * np.pi, max(args.picks - 1, 1), endpoint=False)
    offsets = [(0.0, 0.0)] + [(args.offset_mm * 1e-3 * np.cos(a), args.offset_mm * 1e-3 * np.sin(a))
                              for a in angles][:args.picks - 1]
    for material in args.material:
        cell_objects.MATERIAL = physics.MATERIALS[material]     # what the cell's objects and fingers are made of
        m = cell_objects.MATERIAL
        print(f"material {material}: pads {m.finger_friction}, objects {m.object_friction}, "
              f"nu {m.poisson_ratio or 'the default 0.4'}", flush=True)
        for scene_name, name in picks:
            for offset in offsets:
                t0 = time.process_time()
                r = one_pick(scene_name, name, config, release_max_z_m, offset)
                print(f"  {scene_name}:{name:13s} offset ({offset[0] * 1e3:+4.1f}, {offset[1] * 1e3:+4.1f}) mm "
                      f"force {r['force_n']:.2f} N: success {r['success']!s:5s} width {r['width_mm']:5.1f} mm "
                      f"held lift/transfer {r['held_lift']!s:5s}/{r['held_transfer']!s:5s} slip {r['slip_mm']:5.2f} mm "
                      f"in bin {r['in_bin']!s:5s} {r['reason'][:60]} [{time.process_time() - t0:.0f} CPU s]",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

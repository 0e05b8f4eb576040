"""What the executor's pre-grasp opening does to the grasp search (issue 47): dense bins and the ring's hole.

  .venv/bin/python bench/bench_pre_grasp_opening.py [--seeds 10]

Dense bins: 24 generated objects in a bin (perception/tabletop_scenes.bin_clutter_objects, 5-8 cm tall among
1-2 cm ones, seeds 0..N-1), rendered overhead, perceived and planned (top_k 5); per seed, how many distinct
objects the top five land on (ground truth of the render), under three pre-grasp opening rules given to the
planner's pad-sweep check: the shipped one (control/gripper_rule.pre_grasp_opening_m: the grasp's opening +
10 mm), the hand's full 80 mm (the rule until 2026-11-29), and none (pads checked only just outside the
opening: what the planner did before 896ec39, blind to the fingers' sweep).

The ring's hole in the simulator: vertical rays through common_ring's rigid collision shape (the cell's V-HACD
pieces, sim/meshes.convex_decomposition) at radii inside its 17.5 mm hole: how many of 24 are blocked.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M  # noqa: E402
from defgg_ros.control.gripper_rule import pre_grasp_opening_m  # noqa: E402
from defgg_ros.model.inference import GraspPredictor  # noqa: E402
from defgg_ros.perception import tabletop_scenes as ts  # noqa: E402
from defgg_ros.perception.tabletop import perceive  # noqa: E402
from defgg_ros.planning import tabletop_grasps as tg  # noqa: E402

RULES = {"shipped (+10 mm)": pre_grasp_opening_m, "full 80 mm": lambda w: GRIPPER_MAX_WIDTH_M,
         "no sweep": lambda w: 0.0}
HOLE_RADII_M = (0.010, 0.0125, 0.015, 0.0165)


def top_five_objects(model, seed: int) -> list:
    """The ground-truth objects (render labels) the top five grasps of bin `seed` land on."""
    small = ts.bin_clutter_objects(24, seed=seed, tall_m=(0.05, 0.08))
    scene = ts.overhead_072(small + (ts.Compound(ts.bin_walls(), name="bin"),))
    frame = ts.render(scene, seed=seed)
    view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    on = []
    for grasp in tg.plan_tabletop_grasps(view, model, None, top_k=5):
        uv = tg.image_projection(grasp, frame.base_T_camera, frame.camera_k)
        on.append(int(frame.labels[int(round(uv["v_px"])), int(round(uv["u_px"]))]))
    return on


def ring_hole_blocked() -> list:
    """Per radius in HOLE_RADII_M: how many of 24 vertical rays hit common_ring's cell collision shape."""
    import pybullet as p

    from defgg_ros.sim import meshes
    from defgg_ros.sim import objects as sim_objects

    surface = sim_objects.get_shape("common_ring").surface()
    surface.apply_translation(-surface.bounds.mean(axis=0))
    client = p.connect(p.DIRECT)
    try:
        shape = p.createCollisionShape(p.GEOM_MESH, fileName=str(meshes.convex_decomposition(
            meshes.tetrahedralize(surface))), physicsClientId=client)
        body = p.createMultiBody(0.05, shape, -1, [0, 0, 0], physicsClientId=client)
        angles = np.linspace(0.0, 2 * math.pi, 24, endpoint=False)
        return [sum(p.rayTest([r * math.cos(a), r * math.sin(a), 0.1], [r * math.cos(a), r * math.sin(a), -0.1],
                              physicsClientId=client)[0][0] == body for a in angles) for r in HOLE_RADII_M]
    finally:
        p.disconnect(client)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=10, help="dense bins 0..N-1")
    args = parser.parse_args(argv)
    model = GraspPredictor.from_checkpoint(ROOT / "models" / "defgg_cnn.pt", num_threads=1)
    shipped = tg.pre_grasp_opening_m
    try:
        for name, rule in RULES.items():
            tg.pre_grasp_opening_m = rule      # the planner's pad sweep reads the rule from its module
            distinct = [len(set(top_five_objects(model, seed))) for seed in range(args.seeds)]
            print(f"{name:17s} distinct objects in the top five, seeds 0..{args.seeds - 1}: {distinct}; "
                  f">= 4 in {sum(d >= 4 for d in distinct)} of {args.seeds}", flush=True)
    finally:
        tg.pre_grasp_opening_m = shipped
    blocked = ring_hole_blocked()
    print("common_ring's hole in the cell (V-HACD pieces), rays blocked of 24 at r " +
          ", ".join(f"{r * 1e3:.1f} mm: {b}" for r, b in zip(HOLE_RADII_M, blocked)) + " (the hole ends at 17.5 mm)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Issue 47's generated real shapes, and what they give: low objects from 0.72 m, parts of one object, hollow
objects, a table curving up at its far edge, bin clutter (perception/tabletop_scenes.py; no timings).

  .venv/bin/python bench/bench_real_shapes.py            # the figures docs/perception.md quotes
  .venv/bin/python bench/bench_real_shapes.py --seeds 3  # fewer frames per case

Per case: how many frames pass its check. Low objects: a grasp whose centre is on the object. Shapes: one object
in view holding >= 70 % of the object's pixels. Table warps: exactly the real objects. Bin: the top five grasps
on >= 4 distinct objects, none on the bin.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _on(grasps, frame) -> list:
    from defgg_ros.planning.tabletop_grasps import image_projection

    out = []
    for grasp in grasps:
        uv = image_projection(grasp, frame.base_T_camera, frame.camera_k)
        v = min(frame.labels.shape[0] - 1, max(0, int(round(uv["v_px"]))))
        u = min(frame.labels.shape[1] - 1, max(0, int(round(uv["u_px"]))))
        out.append(int(frame.labels[v, u]))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=8, help="frames (noise seeds) per case")
    parser.add_argument("--model", default=str(ROOT / "models" / "defgg_cnn.pt"))
    args = parser.parse_args(argv)
    import torch

    from defgg_ros.model.inference import GraspPredictor
    from defgg_ros.perception import tabletop_scenes as ts
    from defgg_ros.perception.tabletop import TabletopConfig, perceive
    from defgg_ros.planning.tabletop_grasps import plan_tabletop_grasps

    torch.set_num_threads(1)
    model = GraspPredictor.from_checkpoint(args.model)
    seeds = range(args.seeds)

    def view_of(frame, config=None):
        return perceive(frame.depth_m, frame.camera_k, frame.base_T_camera, config)

    print("| case | frames passing |\n|---|---|")
    for h in (0.015, 0.02):
        for obj in (ts.Box((0.50, 0.01), (0.06, 0.04, h), yaw_rad=0.4, name="block"),
                    ts.Cylinder((0.49, -0.02), 0.025, h, name="puck"),
                    ts.Box((0.52, 0.0), (0.09, 0.03, h), yaw_rad=-0.8, name="bar")):
            good = 0
            for seed in seeds:
                frame = ts.render(ts.overhead_072([obj]), seed=seed)
                good += _on(plan_tabletop_grasps(view_of(frame), model, None, top_k=1), frame)[:1] == [1]
            print(f"| {obj.name} {h * 100:.1f} cm from 0.72 m: best grasp on it | {good} of {len(seeds)} |")
    shapes = {"drill from 0.72 m": ts.overhead_072([ts.drill_like()]),
              "drill from the tilted camera": ts.cluttered_table(objects=(ts.drill_like((0.5, 0.0)),)),
              "mug from 0.72 m": ts.overhead_072([ts.mug_like(yaw_rad=0.4)]),
              "mug from the tilted camera": ts.cluttered_table(objects=(ts.mug_like((0.5, 0.0), yaw_rad=1.2),)),
              "cup (4 mm bottom) from 0.72 m": ts.overhead_072([ts.HollowCylinder((0.5, 0.0), 0.035, 0.09,
                                                                                  bottom_m=0.004)]),
              "bowl from 0.72 m": ts.overhead_072([ts.HollowCylinder((0.5, 0.0), 0.07, 0.05, bottom_m=0.005)])}
    for name, scene in shapes.items():
        good, counts = 0, []
        for seed in seeds:
            frame = ts.render(scene, seed=seed)
            view = view_of(frame)
            mine = view.labels[frame.labels == 1]
            counts.append(len(view.object_ids))
            good += len(view.object_ids) == 1 and np.mean(mine > 0) > 0.7
        print(f"| {name}: one object | {good} of {len(seeds)} (objects per frame: {sorted(set(counts))}) |")
    for rise in (0.012, 0.018, 0.025):
        good = 0
        for seed in seeds:
            scene = ts.overhead_072([ts.Box((0.5, 0.0), (0.05, 0.04, 0.04))], table_warp=ts.curved_table_warp(rise))
            good += len(view_of(ts.render(scene, seed=seed)).object_ids) == 1
        print(f"| table {rise * 100:.1f} cm up at its far edge: no phantom | {good} of {len(seeds)} |")
    for tall, rule in (((0.05, 0.08), "half_height"), ((0.04, 0.06), "half_height"), ((0.04, 0.06), "below_surface")):
        good = 0
        for seed in seeds:
            small = ts.bin_clutter_objects(24, seed=seed, tall_m=tall)
            frame = ts.render(ts.overhead_072(small + (ts.Compound(ts.bin_walls(), name="bin"),)), seed=seed)
            on = _on(plan_tabletop_grasps(view_of(frame, TabletopConfig(grasp_height_rule=rule)), model, None, 5),
                     frame)
            good += len(on) == 5 and all(1 <= label <= len(small) for label in on) and len(set(on)) >= 4
        print(f"| bin, tall ones {tall[0] * 100:.0f}-{tall[1] * 100:.0f} cm, {rule}: top five on >= 4 objects | "
              f"{good} of {len(seeds)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

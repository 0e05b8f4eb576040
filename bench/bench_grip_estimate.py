"""How well the cell's mass estimate (planning/grip_estimate.py) knows the objects' volumes, on rendered D435
frames with sensor noise: the cluttered table at 640x480, 848x480 and 1280x720 (tilted camera, touching
objects) and each of its objects alone under an overhead camera.

  .venv/bin/python bench/bench_grip_estimate.py [--seeds 3]

Prints per object its true volume, what a top-down height map can at best see (the column under the object's
top surface: a lying cylinder or a ball counts solid down to the table) and the estimate per view (median over
the noise seeds, as % of the true volume). An object perception did not separate is '-'. The estimate's mass
is that volume x object_density_kg_m3; the labels' finger force grows in proportion to it.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.perception import tabletop_scenes as ts  # noqa: E402
from defgg_ros.perception.tabletop import TabletopError, perceive  # noqa: E402
from defgg_ros.planning.grip_estimate import object_volume_m3  # noqa: E402


def true_volume_m3(obj) -> float:
    if isinstance(obj, ts.Box):
        return float(np.prod(obj.size_m))
    if isinstance(obj, ts.Cylinder):
        return math.pi * obj.radius_m ** 2 * obj.height_m
    if isinstance(obj, ts.LyingCylinder):
        return math.pi * obj.radius_m ** 2 * obj.length_m
    if isinstance(obj, ts.Sphere):
        return 4 / 3 * math.pi * obj.radius_m ** 3
    raise TypeError(type(obj).__name__)


def column_volume_m3(obj) -> float:
    """Volume under the top surface, down to the table (what a top-down height map can see at best)."""
    if isinstance(obj, ts.LyingCylinder):      # per length: 2r * r (lower half's box) + half the circle
        return (2 + math.pi / 2) * obj.radius_m ** 2 * obj.length_m
    if isinstance(obj, ts.Sphere):             # a cylinder of the ball's radius up to its top, less the cap
        r = obj.radius_m
        return math.pi * r ** 2 * obj.center_m[2] + 2 / 3 * math.pi * r ** 3
    return true_volume_m3(obj)


def estimated_volumes(scene, seed: int) -> dict:
    """object index -> estimated volume (m^3) of the perceived object most of its pixels went to."""
    frame = ts.render(scene, seed=seed)
    try:
        view = perceive(frame.depth_m, frame.camera_k, frame.base_T_camera)
    except TabletopError:
        return {}
    out = {}
    for index in range(len(scene.objects)):
        on = (frame.labels == index + 1) & (view.labels > 0)
        if on.sum() < 50:
            continue
        label = int(np.bincount(view.labels[on]).argmax())
        out[index] = object_volume_m3(view.grid_height_m, view.grid_labels, label)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3, help="noise seeds per view (median over them)")
    args = ap.parse_args(argv)
    if args.seeds < 1:
        ap.error("--seeds must be >= 1")
    objects = ts.cluttered_objects()
    views = {f"tilted {w}x{h}": ts.cluttered_table(w, h) for w, h in ts.MODES}
    results = {name: [estimated_volumes(scene, s) for s in range(args.seeds)] for name, scene in views.items()}
    overhead = []
    for obj in objects:
        single = [estimated_volumes(ts.overhead_single(obj), s) for s in range(args.seeds)]
        overhead.append([r.get(0) for r in single])
    names = list(views) + ["overhead alone"]
    print(f"{'object':<14} {'true cm3':>8} {'column':>7} " + " ".join(f"{n:>17}" for n in names))
    for i, obj in enumerate(objects):
        true = true_volume_m3(obj)
        cells = []
        for name in views:
            values = [r[i] for r in results[name] if i in r]
            cells.append(f"{100 * np.median(values) / true:.0f} %" if values else "-")
        values = [v for v in overhead[i] if v is not None]
        cells.append(f"{100 * np.median(values) / true:.0f} %" if values else "-")
        print(f"{obj.name:<14} {1e6 * true:>8.1f} {100 * column_volume_m3(obj) / true:>6.0f}% "
              + " ".join(f"{c:>17}" for c in cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())

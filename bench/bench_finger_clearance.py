"""Cost of the grasp service's finger-clearance and square-contact steps (grasping/finger_clearance.py,
grasping/contact_angle.py).

GraspPredictor.predict with the shipped Def-GG-CNN, 1 torch thread, in three modes: network only,
finger_clearance_opening_m = 0.08 m, and that plus contact_angle=True (the cell's configuration),
on two 640x480 synthetic scenes:
  bench   the PlanGrasp bench's scene (two boxes and a cylinder): grasps the 80 mm opening clears
  wide    one 12 x 11 cm box: no grasp can be cleared (the search's worst case)
Prints median / p99 / max per mode and the extra median costs, interleaved in rounds.

    .venv/bin/python bench/bench_finger_clearance.py [--runs 200]
"""
import argparse
import time
from pathlib import Path

import numpy as np
from bench_plan_grasp import scene

from defgg_ros.model.inference import GraspPredictor
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render

ROOT = Path(__file__).resolve().parents[1]
OPENING_M = 0.08


def wide_scene():
    depth_m, truth = render(SyntheticScene(objects=(
        SceneObject(center_xy_m=(0.0, 0.0), height_m=0.05, size_xy_m=(0.12, 0.11), yaw_rad=0.3),)))
    return depth_m, np.where(truth > 0, 2e5, 0.0).astype(np.float32), truth, default_camera_k()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=200, help="predictions per scene and mode")
    args = parser.parse_args(argv)
    predictor = GraspPredictor.from_checkpoint(ROOT / "models" / "defgg_cnn.pt", num_threads=1)
    scenes = {"bench": scene(), "wide": wide_scene()}
    modes = {"network": (0.0, False), "clearance": (OPENING_M, False), "+contact": (OPENING_M, True)}
    times = {(name, mode): [] for name in scenes for mode in modes}
    clear = {}
    for _ in range(args.runs):
        for (name, mode), samples in times.items():
            depth, moduli, labels, k = scenes[name]
            opening, contact = modes[mode]
            start = time.perf_counter()
            best = predictor.predict(depth, moduli, k, labels, top_k=1, finger_clearance_opening_m=opening,
                                     contact_angle=contact).best
            samples.append(time.perf_counter() - start)
            clear[(name, mode)] = best.fingers_clear
    print(f"GraspPredictor.predict, {args.runs} runs per row, 1 torch thread, opening {OPENING_M * 1000:.0f} mm")
    print(f"{'scene':6s} {'mode':>10s} {'median ms':>10s} {'p99 ms':>8s} {'max ms':>8s}  best grasp clear")
    for (name, mode), samples in times.items():
        ms = np.asarray(samples) * 1e3
        print(f"{name:6s} {mode:>10s} {np.median(ms):10.2f} {np.percentile(ms, 99):8.2f} "
              f"{ms.max():8.2f}  {clear[(name, mode)]}")
    for name in scenes:
        base = np.median(times[(name, "network")])
        print(f"{name}: clearance step adds {(np.median(times[(name, 'clearance')]) - base) * 1e3:+.2f} ms, "
              f"with square contacts {(np.median(times[(name, '+contact')]) - base) * 1e3:+.2f} ms (median)")


if __name__ == "__main__":
    main()

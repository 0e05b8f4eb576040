"""An object's own shadow off the camera's axis (docs/perception.md "Limits"): the generated overhead single
objects planned where the cluttered table puts them and moved under the camera.

  .venv/bin/python bench/bench_off_axis_shadow.py

Each object of perception/tabletop_scenes.cluttered_objects alone under a camera 0.55 m above (0.5, 0)
(`overhead_single`), perceived and planned (top_k 1): its grasp's opening, or why it has none. Unseen space is
never free, so an object far off the axis loses the space its far side hides.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.model.inference import GraspPredictor  # noqa: E402
from defgg_ros.perception import tabletop_scenes as ts  # noqa: E402
from defgg_ros.perception.tabletop import perceive  # noqa: E402
from defgg_ros.planning.tabletop_grasps import plan_tabletop  # noqa: E402

UNDER_THE_CAMERA_XY_M = (0.5, 0.0)


def planned(model, obj, seed: int) -> str:
    frame = ts.render(ts.overhead_single(obj), seed=seed)
    plan = plan_tabletop(perceive(frame.depth_m, frame.camera_k, frame.base_T_camera), model, None, top_k=1)
    if plan.grasps:
        return f"grasp {plan.grasps[0].width_m * 1e3:.1f} mm"
    if not plan.rejected:
        return "nothing perceived"       # e.g. the shiny can's top under the camera: no return (docs "Limits")
    return "no grasp (" + ", ".join(sorted(set(plan.rejected.values()))) + ")"


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    model = GraspPredictor.from_checkpoint(ROOT / "models" / "defgg_cnn.pt", num_threads=1)
    for seed, obj in enumerate(ts.cluttered_objects()):
        if not hasattr(obj, "center_xy_m"):
            continue
        centred = dataclasses.replace(obj, center_xy_m=UNDER_THE_CAMERA_XY_M)
        print(f"{obj.name:13s} at ({obj.center_xy_m[0]:.3f}, {obj.center_xy_m[1]:.3f}): {planned(model, obj, seed):28s}"
              f" under the camera: {planned(model, centred, seed)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

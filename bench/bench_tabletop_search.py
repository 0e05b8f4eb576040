"""The tabletop planner's search in process: CPU per search, and the grasps of a fixed set of frames.

  .venv/bin/python bench/bench_tabletop_search.py                       # CPU ms per stage and top_k
  .venv/bin/python bench/bench_tabletop_search.py --grasps-out a.json   # the grasps of 68 frame x top_k cases
  .venv/bin/python bench/bench_tabletop_search.py --compare a.json      # ... and how many differ from a.json

CPU (time.process_time, one torch thread) on the PlanGrasp bench's cluttered table (bench_plan_grasp.scene),
median over --frames freshly prepared frames (each its own network pass, so no search reuses another frame's
work): the network stage (TabletopPlanner.network), a top_k 1 search, then a top_k 5 search on the same frame
(what the node's worker does when a client asks for five: they share each peak's feasibility), and a top_k 5
search on a frame of its own. Pause background jobs first: the figures are CPU time but share caches and cores.

The grasp cases (--grasps-out / --compare) are the cluttered table at 640x480, 848x480 and 1280x720 under three
noise seeds and the overhead single objects of the cluttered scene, each searched at top_k 1, 3, 5 and 10 on one
prepared frame: written at one commit and compared at another, they show whether a change kept every grasp.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

MODES = ((640, 480), (1280, 720))
TOP_KS = (1, 3, 5, 10)


def timed(fn, *args):
    """(fn(*args), its CPU ms)."""
    start = time.process_time()
    result = fn(*args)
    return result, 1e3 * (time.process_time() - start)


def timings(planner, frames: int) -> None:
    from bench_plan_grasp import scene

    print("CPU ms, median per freshly prepared frame")
    print("| resolution | network stage | top_k 1 | then top_k 5 (same frame) | top_k 5 alone |")
    print("|---|---|---|---|---|")
    for mode in MODES:
        depth, moduli, k, pose = scene(*mode)
        objects = planner.perceive(depth, k, pose, moduli)
        rows = []
        for _ in range(frames):
            prepared, network = timed(planner.network, objects)
            first = timed(planner.search, prepared, 1)[1]
            then = timed(planner.search, prepared, 5)[1]
            alone = timed(planner.search, planner.network(objects), 5)[1]
            rows.append((network, first, then, alone))
        med = np.median(np.asarray(rows), axis=0)
        print(f"| {mode[0]}x{mode[1]} | {med[0]:.1f} | {med[1]:.1f} | {med[2]:.1f} | {med[3]:.1f} |")


def grasp_cases(planner) -> dict:
    from bench_plan_grasp import scene

    from defgg_ros.perception import tabletop_scenes as ts

    frames = [(f"clutter {w}x{h} seed {seed}", *scene(w, h, seed=seed)) for w, h in ts.MODES for seed in (0, 1, 2)]
    for index, obj in enumerate(ts.cluttered_objects()):
        frame = ts.render(ts.overhead_single(obj), seed=index)
        frames.append((f"single {obj.name}", frame.depth_m, None, frame.camera_k, frame.base_T_camera))
    out = {}
    for name, depth, moduli, k, pose in frames:
        try:
            prepared = planner.prepare(depth, k, pose, moduli)
        except ValueError as exc:
            out[name] = str(exc)
            continue
        for top_k in TOP_KS:
            try:
                out[f"{name} / top_k {top_k}"] = [repr(g) for g in planner.search(prepared, top_k).grasps]
            except ValueError as exc:
                out[f"{name} / top_k {top_k}"] = str(exc)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=20, help="freshly prepared frames per resolution")
    parser.add_argument("--model", default=str(ROOT / "models" / "defgg_cnn.pt"))
    parser.add_argument("--grasps-out", type=Path, help="write the grasp cases to this JSON file (no timings)")
    parser.add_argument("--compare", type=Path, help="compare the grasp cases with this file (no timings)")
    args = parser.parse_args(argv)
    import torch

    from defgg_ros.model.inference import GraspPredictor
    from defgg_ros.planning.tabletop_planner import TabletopPlanner

    torch.set_num_threads(1)
    planner = TabletopPlanner(GraspPredictor.from_checkpoint(args.model))
    if args.grasps_out or args.compare:
        cases = grasp_cases(planner)
        if args.grasps_out:
            args.grasps_out.write_text(json.dumps(cases, indent=0))
            print(f"{len(cases)} cases written to {args.grasps_out}")
        if args.compare:
            reference = json.loads(args.compare.read_text())
            differ = sorted(key for key in reference.keys() | cases.keys() if reference.get(key) != cases.get(key))
            shown = f": {differ[:5]}" if differ else ""
            print(f"{len(cases)} cases, {len(differ)} differ from {args.compare}{shown}")
            return 1 if differ else 0
        return 0
    timings(planner, args.frames)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

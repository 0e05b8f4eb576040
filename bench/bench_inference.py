"""Forward latency of the reference GG-CNN vs our network and inference path.

Prints, for 1 and 2 CPU threads, median and p99 latency over --runs forwards
of a 300x300 batch-1 input for:
  reference   the reference GG-CNN (conv 9/5/3 + transposed conv 3/5/9, 2x2 heads; 1 channel), eager
  ours-eager  our default network (bilinear decoder, depth + stiffness), eager PyTorch
  ours-ts     the same weights as frozen TorchScript (what GraspPredictor uses)
  predict     GraspPredictor.predict on a 640x480 scene (crop, encodings, forward, post-processing)
plus parameter counts and peak activation memory of one forward. Variants
are measured round-robin in small blocks so a busy machine slows all alike.

    .venv/bin/python bench/bench_inference.py            # full run (>= 200 runs each)
    .venv/bin/python bench/bench_inference.py --runs 20  # quick look
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from defgg_ros.constants import CAMERA_FX_PX  # noqa: E402
from defgg_ros.model.checkpoint import make_random_checkpoint  # noqa: E402
from defgg_ros.model.inference import GraspPredictor  # noqa: E402
from defgg_ros.model.network import GGCNN, GGCNNConfig, parameter_count  # noqa: E402
from defgg_ros.model.runtime import torchscript  # noqa: E402

BLOCK = 10  # forwards per variant before switching to the next one


def cell_scene():
    depth = np.full((480, 640), 0.40, np.float32)
    mask = np.zeros((480, 640), np.int32)
    mask[200:260, 420:500] = 1
    depth[mask > 0] = 0.36
    moduli = np.where(mask > 0, 2e5, 0.0).astype(np.float32)
    k = np.array([[CAMERA_FX_PX, 0, 320.0], [0, CAMERA_FX_PX, 240.0], [0, 0, 1]])
    return depth, moduli, k, mask


def peak_forward_memory_mb(fn, x) -> float:
    """Peak of allocated-minus-freed CPU memory during one forward (profiler events)."""
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU], profile_memory=True) as prof:
        fn(x)
    events = sorted((e for e in prof.events() if e.cpu_memory_usage), key=lambda e: e.time_range.start)
    usage = np.cumsum([e.cpu_memory_usage for e in events]) if events else np.zeros(1)
    return float(usage.max()) / 1e6


def measure(variants: dict, runs: int) -> dict:
    times = {name: [] for name in variants}
    block = min(BLOCK, runs)
    with torch.inference_mode():
        for fn in variants.values():
            for _ in range(min(5, runs)):
                fn()
        while min(len(t) for t in times.values()) < runs:
            for name, fn in variants.items():
                for _ in range(block):
                    t0 = time.perf_counter()
                    fn()
                    times[name].append(time.perf_counter() - t0)
    return {name: {"median_ms": float(np.median(t) * 1e3), "p99_ms": float(np.percentile(t, 99) * 1e3),
                   "runs": len(t)} for name, t in times.items()}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, default=200, help="forwards per variant and thread count (default 200)")
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="torch thread counts to measure")
    p.add_argument("--json", help="also write the figures to this JSON file")
    args = p.parse_args(argv)

    torch.manual_seed(0)
    reference = GGCNN(GGCNNConfig(input_channels=1, architecture="ggcnn")).eval()
    ours = GGCNN(GGCNNConfig(input_channels=2)).eval()
    x1, x2 = torch.rand(1, 1, 300, 300), torch.rand(1, 2, 300, 300)
    ours_ts = torchscript(ours, x2)
    with tempfile.TemporaryDirectory() as tmp:
        predictor = GraspPredictor.from_checkpoint(make_random_checkpoint(Path(tmp) / "m.pt"))
    scene = cell_scene()
    with torch.inference_mode():
        max_diff = float((ours_ts(x2) - ours(x2)).abs().max())
    variants = {"reference": lambda: reference(x1), "ours-eager": lambda: ours(x2),
                "ours-ts": lambda: ours_ts(x2), "predict": lambda: predictor.predict(*scene)}
    result = {"parameters": {"reference": parameter_count(reference), "ours": parameter_count(ours)},
              "peak_forward_memory_mb": {}, "torchscript_max_abs_diff": max_diff,
              "predictor_runtime": predictor.runtime, "latency": {}}
    with torch.inference_mode():
        result["peak_forward_memory_mb"] = {"reference": peak_forward_memory_mb(reference, x1),
                                            "ours-eager": peak_forward_memory_mb(ours, x2)}
    for threads in args.threads:
        torch.set_num_threads(threads)
        result["latency"][threads] = measure(variants, args.runs)

    print(f"parameters: reference GG-CNN {result['parameters']['reference']:,}, ours {result['parameters']['ours']:,}")
    print("peak activation memory per forward (MB): "
          + ", ".join(f"{k} {v:.1f}" for k, v in result["peak_forward_memory_mb"].items()))
    print(f"TorchScript vs eager max |diff| = {max_diff:.2e}; predictor runtime = {predictor.runtime}")
    print(f"{'threads':>7} {'variant':<11} {'median ms':>10} {'p99 ms':>8} {'runs':>5}")
    for threads, rows in result["latency"].items():
        for name, r in rows.items():
            print(f"{threads:>7} {name:<11} {r['median_ms']:>10.2f} {r['p99_ms']:>8.2f} {r['runs']:>5}")
        ref_ms = rows["reference"]["median_ms"]
        print(f"{threads:>7} speed-up vs reference (median): forward {ref_ms / rows['ours-ts']['median_ms']:.1f}x, "
              f"full predict {ref_ms / rows['predict']['median_ms']:.1f}x")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

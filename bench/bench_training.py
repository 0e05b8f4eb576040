"""Training throughput (images/s) of our network and the reference GG-CNN.

Each step = load + augment + encode a batch from a synthetic dataset in the
real format, forward, GG-CNN loss, backward, Adam step — the same code as
defgg-train. Prints images/s per architecture and thread count.

    .venv/bin/python bench/bench_training.py --steps 20
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from defgg_ros.data.augment import AugmentConfig  # noqa: E402
from defgg_ros.data.dataset import GraspDataset  # noqa: E402
from defgg_ros.data.format import list_scene_ids  # noqa: E402
from defgg_ros.data.synthetic import write_synthetic_dataset  # noqa: E402
from defgg_ros.model.network import GGCNN, GGCNNConfig  # noqa: E402
from defgg_ros.train.metrics import grasp_loss  # noqa: E402


def throughput(dataset, architecture: str, batch_size: int, steps: int) -> dict:
    torch.manual_seed(0)
    model = GGCNN(GGCNNConfig(input_channels=2, architecture=architecture)).train()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    data_s = compute_s = 0.0
    for step in range(steps + 1):  # step 0 is warm-up
        t0 = time.perf_counter()
        items = [dataset[(step * batch_size + i) % len(dataset)] for i in range(batch_size)]
        x, y = torch.stack([it["x"] for it in items]), torch.stack([it["y"] for it in items])
        t1 = time.perf_counter()
        loss = grasp_loss(model(x), y)["loss"]
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        t2 = time.perf_counter()
        if step:
            data_s, compute_s = data_s + t1 - t0, compute_s + t2 - t1
    n = steps * batch_size
    return {"images_per_s": n / (data_s + compute_s), "compute_only_images_per_s": n / compute_s,
            "data_ms_per_image": 1e3 * data_s / n}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=20, help="timed steps per configuration (default 20)")
    p.add_argument("--batch-size", type=int, default=8)
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        write_synthetic_dataset(tmp, n_objects=4, trials_per_scene=16)
        dataset = GraspDataset(tmp, list_scene_ids(tmp), augment=AugmentConfig(), samples_per_scene=50)
        print(f"{'threads':>7} {'architecture':<15} {'images/s':>9} {'compute-only':>13} {'data ms/img':>12}")
        for threads in args.threads:
            torch.set_num_threads(threads)
            for arch in ("ggcnn_bilinear", "ggcnn"):
                r = throughput(dataset, arch, args.batch_size, args.steps)
                print(f"{threads:>7} {arch:<15} {r['images_per_s']:>9.1f} {r['compute_only_images_per_s']:>13.1f} "
                      f"{r['data_ms_per_image']:>12.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

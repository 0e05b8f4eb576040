"""Grasp ranking on the clipped vs the unclipped quality map, on a model's validation and test scenes.

The network's quality output is linear; where it overshoots 1 over an object, the map clipped to
[0, 1] is a plateau of ties. Ranking on the clipped map resolved them in raster order (the plateau's
top-left edge); since 2026-11-28 the ranking reads the quality before the clip (grasping/postprocess.py).
This prints, per model and split, the top-1 rectangle accuracy (the training's validation metric) under
both rankings, and how often the clipped ranking's top-1 grasp was a tie at quality 1.0; with --eval,
also the share of an evaluation's graded (trials.jsonl) or planned (plans.json) grasps at reported quality 1.0
(possibly such a tie).

    .venv/bin/python bench/bench_rank_clip.py     # the shipped pair on models/train_data_fem_v5.tar.gz
    .venv/bin/python bench/bench_rank_clip.py --eval results/sim_v4/trials.jsonl.gz --models
    git show acb5d4f:results/sim_v5/plans.json > /tmp/clipped_plans.json     # sim_v5's discarded first start
    .venv/bin/python bench/bench_rank_clip.py --eval /tmp/clipped_plans.json --models
"""
from __future__ import annotations

import argparse
import collections
import json
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from defgg_ros.atomic import read_jsonl  # noqa: E402
from defgg_ros.grasping.postprocess import maps_from_network  # noqa: E402
from defgg_ros.grasping.rectangles import rectangle_match  # noqa: E402
from defgg_ros.model.inference import GraspPredictor  # noqa: E402
from defgg_ros.model.preprocess import network_input  # noqa: E402
from defgg_ros.train.config import TrainConfig  # noqa: E402
from defgg_ros.train.metrics import predicted_rect  # noqa: E402
from defgg_ros.train.trainer import Trainer  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--archive", type=Path, default=ROOT / "models/train_data_fem_v5.tar.gz",
                   help="frozen training data (defgg-eval freeze); its train_data/ is read")
    p.add_argument("--models", nargs="*", type=Path,
                   default=[ROOT / "models/defgg_cnn.pt", ROOT / "models/ggcnn_depth_only.pt"])
    p.add_argument("--seed", type=int, default=0, help="the training's split seed (the model cards: 0)")
    p.add_argument("--eval", nargs="*", type=Path, default=[],
                   help="evaluation files (trials.jsonl[.gz] or plans.json): share of grasps at quality 1.0")
    return p.parse_args(argv)


def split_samples(data_root: Path, uses_stiffness: bool, seed: int, out_dir: Path) -> dict:
    """The validation and test scenes as the training split them (same fractions and seed)."""
    trainer = Trainer(TrainConfig(uses_stiffness=uses_stiffness, seed=seed), data_root, out_dir, show_progress=False)
    return {"val": trainer.val_set.samples, "test": trainer.test_set.samples}


def score(predictor: GraspPredictor, samples) -> dict:
    hits = {"unclipped": [], "clipped": []}
    ties = 0
    for s in samples:
        raw = predictor.raw_maps(network_input(s.depth_m, s.youngs_modulus_image_pa, predictor.uses_stiffness))
        maps = maps_from_network(raw, predictor.postprocess)
        hits["unclipped"].append(rectangle_match(predicted_rect(maps, s.camera_k, s.depth_m), s.positives))
        maps.q_unclipped = maps.q          # the ranking before 2026-11-28
        rect = predicted_rect(maps, s.camera_k, s.depth_m)
        hits["clipped"].append(rectangle_match(rect, s.positives))
        ties += bool(maps.q[int(rect.center_v_px), int(rect.center_u_px)] >= 1.0)
    return {"n": len(samples), "ties": ties, **{k: float(np.mean(v)) for k, v in hits.items()}}


def _qualities(path: Path):
    """(model, reported quality) of each graded trial (trials.jsonl[.gz]) or planned grasp (plans.json)."""
    if path.name.endswith("plans.json"):
        for plan in json.loads(path.read_text(encoding="utf-8")):
            for grasp in plan["grasps"]:
                yield plan["view"]["model"], grasp["quality"]
        return
    for r in read_jsonl(path):
        quality = (r.get("grasp") or {}).get("quality")
        if quality is not None and r.get("success") is not None:
            yield r["model"], quality


def print_eval_ties(path: Path) -> None:
    """Per model: graded trials (or planned grasps) whose reported (clipped) quality is 1.0."""
    at_one, counted = collections.Counter(), collections.Counter()
    for model, quality in _qualities(path):
        counted[model] += 1
        at_one[model] += quality >= 1.0
    what = "planned" if path.name.endswith("plans.json") else "graded"
    for model in sorted(counted):
        print(f"{path}: {model}: {at_one[model]} of {counted[model]} {what} grasps at quality 1.0 "
              f"({100 * at_one[model] / counted[model]:.0f} %)")


def main(argv=None) -> int:
    args = parse_args(argv)
    for path in args.eval:
        print_eval_ties(path)
    with tempfile.TemporaryDirectory() as tmp:
        with tarfile.open(args.archive) as tar:
            tar.extractall(tmp, filter="data")
        data_root = Path(tmp) / "train_data"
        print(f"data: {args.archive.relative_to(ROOT) if args.archive.is_relative_to(ROOT) else args.archive}")
        print("| model | split | samples | top-1 accuracy, ranked on clipped q | ranked on unclipped q | "
              "clipped ranking's top-1 a tie at q = 1 |")
        print("|---|---|---|---|---|---|")
        for path in args.models:
            predictor = GraspPredictor.from_checkpoint(path, num_threads=1)
            splits = split_samples(data_root, predictor.uses_stiffness, args.seed, Path(tmp) / "run")
            for split, samples in splits.items():
                r = score(predictor, samples)
                print(f"| {path.name} | {split} | {r['n']} | {100 * r['clipped']:.1f} % | "
                      f"{100 * r['unclipped']:.1f} % | {r['ties']} of {r['n']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""defgg-train: train the Def-GG-CNN (or the depth-only GG-CNN baseline).

Examples::

    defgg-train --data datasets/fem_v1 --out runs/defgg            # depth + stiffness
    defgg-train --data datasets/fem_v1 --out runs/baseline --no-stiffness
    defgg-train --data datasets/fem_v1 --out runs/defgg --resume   # after a kill
    torchrun --standalone --nproc_per_node 2 -m defgg_ros.train.cli --data ... --out ...   # DDP (gloo)
"""
from __future__ import annotations

import argparse
import json
import sys

import torch

from defgg_ros.cli_help import HelpFormatter
from defgg_ros.data.augment import AugmentConfig
from defgg_ros.data.format import DatasetError
from defgg_ros.data.labels import LABEL_RULES
from defgg_ros.model.network import ARCHITECTURES
from defgg_ros.train.config import TrainConfig
from defgg_ros.train.trainer import (
    BEST_FILE,
    CURVES_FILE,
    METRICS_FILE,
    MODEL_FILE,
    RESPONSE_FILE,
    STATE_FILE,
    TrainingError,
    train,
)

DEFAULTS = TrainConfig()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="defgg-train", formatter_class=HelpFormatter,
        description="Train the Def-GG-CNN (depth + stiffness) or, with --no-stiffness, the depth-only GG-CNN "
                    "baseline on the same data and schedule. Scenes are split by object (validation/test objects "
                    "are never seen in training). The dataset may still be growing: the run freezes the trials it "
                    "uses in its state file.",
        epilog=f"Outputs in --out: {MODEL_FILE} (latest epoch), {BEST_FILE} (best validation rectangle metric), "
               f"{STATE_FILE} (resume state), {METRICS_FILE}, {CURVES_FILE}, {RESPONSE_FILE}.\n"
               "Distributed: torchrun --standalone --nproc_per_node N -m defgg_ros.train.cli ... "
               "(gloo on CPU; the batch size is per process).")
    p.add_argument("--data", required=True, help="dataset root written by defgg-datagen (has dataset.json)")
    p.add_argument("--out", required=True, help="run folder for checkpoints, metrics and figures")
    p.add_argument("--no-stiffness", action="store_true", help="train the depth-only baseline (1 input channel)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out from its state file (same data and hyper-parameters; "
                        "--epochs may be raised); starts fresh if there is no state yet")
    p.add_argument("--epochs", type=int, default=DEFAULTS.epochs, help="number of epochs (default %(default)s)")
    p.add_argument("--batch-size", type=int, default=DEFAULTS.batch_size, help="images per step and process")
    p.add_argument("--lr", type=float, default=DEFAULTS.learning_rate, help="Adam learning rate")
    p.add_argument("--positive-weight", type=float, default=DEFAULTS.positive_weight,
                   help="loss weight of positive-grasp pixels vs background; 1 = GG-CNN's plain MSE "
                        "(default %(default)s)")
    p.add_argument("--samples-per-scene", type=int, default=DEFAULTS.samples_per_scene,
                   help="augmented copies of each training scene per epoch (default %(default)s)")
    p.add_argument("--seed", type=int, default=DEFAULTS.seed, help="seed of init, order, augmentation and split")
    p.add_argument("--split-seed", type=int, default=None, metavar="SEED",
                   help="seed of the object split alone (default: --seed); fix it to compare training seeds "
                        "on the same validation objects")
    p.add_argument("--val-fraction", type=float, default=DEFAULTS.val_fraction, help="fraction of OBJECTS for val")
    p.add_argument("--test-fraction", type=float, default=DEFAULTS.test_fraction, help="fraction of OBJECTS for test")
    p.add_argument("--val-objects", nargs="+", default=[], metavar="NAME",
                   help="a fixed split instead of the fractions: these validation objects, the --test-objects (none "
                        "by default), every other object trains; e.g. a run's object_split.val from its "
                        "metrics.json, to keep validation by object while the data or the test part changes")
    p.add_argument("--test-objects", nargs="+", default=[], metavar="NAME",
                   help="with --val-objects: the objects held out as the test part (default: none)")
    p.add_argument("--architecture", choices=ARCHITECTURES, default=DEFAULTS.architecture,
                   help="ggcnn_bilinear (fast decoder, default) or ggcnn (the reference GG-CNN)")
    p.add_argument("--no-augment", action="store_true", help="disable random rotations, zooms and shifts")
    p.add_argument("--label-rule", choices=LABEL_RULES, default=DEFAULTS.label_rule,
                   help="positives: 'mean' = mean held acceleration over the 16 shake directions >= 25 m/s^2 "
                        "(the paper's, default); 'every_direction' = that and no measured direction below it "
                        "(the evaluation's shake criterion under legacy, its second table under defgraspsim; "
                        "an experiment)")
    p.add_argument("--max-height-offset-mm", type=float, default=None, metavar="MM",
                   help="positives only from trials whose TCP was within MM of the height the executor grasps "
                        "at on their pixel (an experiment; default: every trial, as in the paper)")
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many optimizer steps (smoke runs)")
    p.add_argument("--checkpoint-every", type=int, default=25, metavar="STEPS",
                   help="also save the resume state every STEPS optimizer steps, so a kill mid-epoch loses at "
                        "most that much work; 0 = only at the end of each epoch (default %(default)s)")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads per process (default %(default)s)")
    p.add_argument("--workers", type=int, default=0, help="data-loading worker processes (default %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def config_from_args(args) -> TrainConfig:
    augment = AugmentConfig(max_rotation_rad=0.0, zoom_range=(1.0, 1.0), max_shift_px=0.0) \
        if args.no_augment else AugmentConfig()
    return TrainConfig(uses_stiffness=not args.no_stiffness, architecture=args.architecture, epochs=args.epochs,
                       batch_size=args.batch_size, learning_rate=args.lr,
                       positive_weight=args.positive_weight, samples_per_scene=args.samples_per_scene,
                       seed=args.seed, split_seed=args.split_seed, val_fraction=args.val_fraction,
                       test_fraction=args.test_fraction, val_objects=tuple(args.val_objects),
                       test_objects=tuple(args.test_objects),
                       augment=augment, max_steps=args.max_steps, label_rule=args.label_rule,
                       max_height_offset_m=None if args.max_height_offset_mm is None
                       else args.max_height_offset_mm / 1000.0)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.threads < 1:
        parser.error(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    try:
        metrics = train(config_from_args(args), args.data, args.out, resume=args.resume, workers=args.workers,
                        checkpoint_every_steps=args.checkpoint_every, show_progress=not args.no_progress)
    except (TrainingError, DatasetError, ValueError) as exc:
        print(f"defgg-train: error: {exc}", file=sys.stderr)
        return 2
    if metrics:
        summary = {"trial_protocol": metrics["data"]["trial_protocol"], "best_epoch": metrics.get("best_epoch"),
                   "val": metrics["history"][-1]["val_per_modulus"],
                   "test": metrics.get("test"), "stiffness_response": metrics.get("stiffness_response")}
        print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

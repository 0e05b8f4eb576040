"""The validation figures of training runs side by side (issue 49 item 2: what each data / split change does).

  .venv/bin/python bench/analyze_training_runs.py RUN_DIR [RUN_DIR ...] [--late-from 21]

Reads each run's metrics.json (written by defgg-train) and prints one row per run: the number of training
objects and trials, the best epoch (the trainer's choice: highest validation accuracy, then lowest loss), the
validation accuracy and loss there, the mean validation accuracy over the late epochs (--late-from to the last:
how steady validation is once training has settled) and the lowest validation loss. The commands that made the
runs of docs/dataset.md are there.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path


def row(run: Path, late_from: int) -> str:
    metrics = json.loads((run / "metrics.json").read_text())
    history = metrics["history"]
    best = next(h for h in history if h["epoch"] == metrics["best_epoch"])
    late = [h["val_accuracy"] for h in history if h["epoch"] >= late_from]
    split = metrics["data"]["object_split"]
    return (f"{run.name:28s} train objects {len(split['train']):2d}  trials {metrics['data']['n_trials']:5d}  "
            f"best epoch {best['epoch']:2d}  val accuracy {best['val_accuracy']:.3f}  val loss {best['val_loss']:.4f}  "
            f"mean val accuracy epochs {late_from}-{history[-1]['epoch']} {statistics.mean(late):.3f}  "
            f"min val loss {min(h['val_loss'] for h in history):.4f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="defgg-train output folders")
    parser.add_argument("--late-from", type=int, default=21, help="first epoch of the late-epoch mean")
    args = parser.parse_args(argv)
    for run in args.runs:
        if not (run / "metrics.json").exists():
            print(f"{run}: no metrics.json (not finished?)", file=sys.stderr)
            continue
        print(row(run, args.late_from))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Would another shake threshold make the labels carry "stiffness changes which grasp is good"?

Reads trial records only (no simulation): for each folder, the signal report's positive rates and oracle gap
(stiffness-aware minus stiffness-blind oracle, best grasp and best five) with the label's threshold moved from
the paper's 25 m/s^2 to each of --thresholds. A threshold is a reading of the same measurements, so this asks
whether the missing gap is an artefact of where 25 m/s^2 falls in our held accelerations (issue 25, try (e)).

  .venv/bin/python bench/analyze_threshold_gap.py datasets/fem_v4 bench/pilots/a_defgraspsim \
      bench/pilots/b_defgraspsim_mu04
(Pilot d's records hold its twist; its shake is a's.)
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from defgg_ros.data.signal import read_trial_records, signal_report  # noqa: E402

DEFAULT_THRESHOLDS = (10.0, 15.0, 20.0, 22.5, 25.0, 27.5, 30.0, 35.0, 40.0)


def rows_for(folder: Path, thresholds) -> list[str]:
    records = read_trial_records(folder)
    lines = []
    for threshold in thresholds:
        report = signal_report(records, threshold_mps2=threshold)
        rates = "/".join(f"{100 * report['positive_rate'][key]['rate']:.0f}" for key in report["positive_rate"])
        oracle = report["oracle"]
        lines.append(f"| {folder.name} | {threshold:g} | {rates} % | {oracle['best']['gap_points']:.1f} | "
                     f"{oracle['top5']['gap_points']:.1f} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="+", type=Path, help="dataset or pilot folders with trial records")
    parser.add_argument("--thresholds", nargs="+", type=float, default=list(DEFAULT_THRESHOLDS),
                        help="mean held acceleration a positive needs, m/s^2 (the paper's: 25)")
    args = parser.parse_args(argv)
    print("| records | threshold (m/s^2) | positive per E (low to high) | oracle gap best (points) | gap top 5 |")
    print("|---|---|---|---|---|")
    for folder in args.folders:
        if not (folder / "trials").is_dir():
            parser.error(f"{folder}: no trials/ folder (a dataset or pilot made by defgg-datagen / pilot_signal.py)")
        print("\n".join(rows_for(folder, args.thresholds)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""`make demo` N times from a fresh state: success rate per object (in the bin) and runs at 4 of 4.

Run: .venv/bin/python bench/bench_demo_repeat.py --runs 20 [--out runs/demo_repeat] [--scene ...]
Each run is a new `defgg-demo` process (a new simulated cell, its own private ROS domain), exactly
what `make demo` starts; the bench reads each run's summary.json and prints, per object, how often
it ended in the bin (the simulator's ground truth) and, for the misses, the phase and reason.
A run that crashes or times out counts as a miss for every object it did not report.
Runs are sequential (two cells at once would compete for the 2 cores and change the timing).
"""
import argparse
import json
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SCENE = ROOT / "sim_bringup" / "scenes" / "demo.yaml"


def run_once(index: int, out_root: Path, scene: str, timeout_s: float, extra: list) -> dict:
    out = out_root / f"run{index:02d}"
    cmd = [sys.executable, "-m", "defgg_ros.demo", "--scene", scene, "--out", str(out), *extra]
    started = time.monotonic()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, cwd=ROOT)
        code, tail = proc.returncode, (proc.stdout + proc.stderr)[-2000:]
    except subprocess.TimeoutExpired as expired:
        code, tail = "timeout", str(expired.stdout or "")[-2000:]
    wall_s = time.monotonic() - started
    summary_path = out / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {"objects": []}
    return {"index": index, "exit": code, "wall_s": wall_s, "objects": summary["objects"], "tail": tail,
            "out": str(out)}


def object_names(scene: str) -> list:
    import yaml

    return [o["name"] for o in yaml.safe_load(Path(scene).read_text())["objects"]]


def report(runs: list, names: list) -> str:
    binned, misses = Counter(), defaultdict(list)
    full = 0
    for run in runs:
        rows = {r["name"]: r for r in run["objects"]}
        ok = 0
        for name in names:
            row = rows.get(name)
            if row is not None and row.get("in_bin"):
                binned[name] += 1
                ok += 1
            else:
                why = (f"{row.get('phase_reached')}: {row.get('failure_reason') or 'ended outside the bin'}"
                       if row else f"not reported (exit {run['exit']})")
                misses[name].append(f"run {run['index']:02d}: {why}")
        full += ok == len(names)
    n = len(runs)
    lines = [f"{n} runs of {', '.join(names)}; {full}/{n} runs with all {len(names)} objects in the bin",
             "| object | in the bin | rate |", "|---|---|---|"]
    lines += [f"| {name} | {binned[name]}/{n} | {100.0 * binned[name] / max(n, 1):.0f} % |" for name in names]
    walls = sorted(r["wall_s"] for r in runs)
    lines.append(f"wall time per run: median {walls[len(walls) // 2]:.0f} s, max {walls[-1]:.0f} s")
    for name in names:
        for miss in misses[name]:
            lines.append(f"miss {name}: {miss}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=20, help="how many demo runs (default 20)")
    parser.add_argument("--scene", default=str(DEFAULT_SCENE), help="scene YAML (default: make demo's)")
    parser.add_argument("--out", default=str(ROOT / "runs" / "demo_repeat"), help="folder for the runs' outputs")
    parser.add_argument("--timeout", type=float, default=3600.0, help="wall seconds allowed per run")
    args, extra = parser.parse_known_args(argv)  # anything else goes to defgg-demo
    out_root = Path(args.out)
    out_root.mkdir(parents=True, exist_ok=True)
    names = object_names(args.scene)
    runs = []
    for i in range(args.runs):
        run = run_once(i, out_root, args.scene, args.timeout, extra)
        runs.append(run)
        got = sum(bool(r.get("in_bin")) for r in run["objects"])
        print(f"run {i:02d}: {got}/{len(names)} in the bin, {run['wall_s']:.0f} s (exit {run['exit']})", flush=True)
        (out_root / "runs.json").write_text(json.dumps(runs, indent=1))
    print(report(runs, names))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Signal pilots: which trial setting gives labels where stiffness changes which grasp is good?

Each try labels the same pilot set (PILOT_OBJECTS x the first CANDIDATES of datasets/fem_v4's candidates x
the four training moduli) under one trial setting, into bench/pilots/<try>/ (a resumable dataset folder),
then prints and writes its signal report (signal.json, signal.md). Trials run the generator's protocol
with its stops (TrialSettings.fast(): a direction ends when the object is lost, the shake ends once the
label is decided or the confident stop imputes the measured mean), as fem_v4 did, so the figures compare
with fem_v4's; measuring every direction cost ~3x more CPU (13-31 s per soft trial).

The gate (the issue on labels that carry the signal): an oracle gap >= 5 points with a within-scene share
>= 30 %; the search stops at the first try that reaches it or after ~8 CPU-hours.

  .venv/bin/python bench/pilot_signal.py --list
  .venv/bin/python bench/pilot_signal.py a_defgraspsim [--workers 2]
  .venv/bin/python bench/pilot_signal.py --summary      # the table of every finished try (bench/pilots/README.md)
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PILOTS = ROOT / "bench" / "pilots"
SOURCE = ROOT / "datasets" / "fem_v4"
# >= 6 objects: four EGAD-like shapes of complexity 4-6, two elongated ones (training objects only).
PILOT_OBJECTS = ("egad_train_06_c4", "egad_train_07_c4", "egad_train_09_c5", "egad_train_10_c6", "ycb_banana",
                 "capsule")
CANDIDATES = 10
GATE_GAP_POINTS, GATE_WITHIN_SHARE = 5.0, 0.30

# name -> (what it tries, TrialSettings overrides, datagen extras)
TRIES = {
    "a_defgraspsim": ("DefGraspSim's protocol: mu 0.7, nu 0.3, fingers force-held at F/2",
                      {"protocol": "defgraspsim"}, {}),
    # (b) as the issue words it: with the force rule's mu following the friction, mu * F = FOS * m * g stays
    # the same and only the squeeze grows; so the force keeps (a)'s mu 0.7 and friction alone holds 4/7 of (a).
    "b_defgraspsim_mu04": ("(a) with effective friction 0.4 but the grip force of mu 0.7: friction alone holds "
                           "FOS*g*0.4/0.7 (8-11 m/s^2), the rest must come from geometry",
                           {"protocol": "defgraspsim", "object_friction": 0.4, "grip_force_friction": 0.7}, {}),
    "b_defgraspsim_mu03": ("(a) with effective friction 0.3", {"protocol": "defgraspsim", "object_friction": 0.3}, {}),
    "c_defgraspsim_fine": ("(a) on finer soft meshes (at most 500 nodes instead of 220), nu 0.3",
                           {"protocol": "defgraspsim"}, {"sim_max_tet_nodes": 500}),
    "d_defgraspsim_twist": ("(a) with the twist in the label (shake positive and mean twist >= 250 rad/s^2; "
                            "oscillating twist as the evaluation's); twist simulated here, shake taken from (a)",
                            {"protocol": "defgraspsim", "twist_oscillation_radps": 40.0},
                            {"tests": ("twist",)}),
    "legacy": ("fem_v4's protocol on the pilot set (the baseline)", {"protocol": "legacy"}, {}),
}
# The label rule a try's signal is computed with (data/signal.py LABEL_RULES); default shake.
LABEL_RULE = {"d_defgraspsim_twist": "shake_and_twist"}
# Tries that simulate only the twist and take each trial's shake from another try with the same settings
# (everything before the tests is identical, and every direction and axis starts again from the state saved
# after the pickup, so one trial with both tests gives the same numbers): the shake is not paid twice.
SHAKE_FROM = {"d_defgraspsim_twist": "a_defgraspsim"}


def seed_candidates(folder: Path) -> None:
    """The pilot's candidates = fem_v4's first CANDIDATES of each object, under the key the generator
    expects for grasps_per_scene=CANDIDATES (so the labels compare with fem_v4's on the same grasps)."""
    from defgg_ros.atomic import write_json_atomic
    from defgg_ros.data.datagen import CANDIDATE_FILE_VERSION, object_seed
    from defgg_ros.sim.objects import get_shape
    from defgg_ros.sim.sampler import SAMPLER_VERSION

    for name in PILOT_OBJECTS:
        src = json.loads((SOURCE / "candidates" / f"{name}.json").read_text(encoding="utf-8"))
        key = dict(src["key"], keep=CANDIDATES)
        assert key["sampler"] == SAMPLER_VERSION and key["seed"] == object_seed(0, name)
        assert key["version"] == CANDIDATE_FILE_VERSION
        assert key["mesh"] == [t.content_hash for t in get_shape(name).tet_parts]
        write_json_atomic(folder / "candidates" / f"{name}.json",
                          {"key": key, "candidates": src["candidates"][:CANDIDATES]})


def run_try(name: str, workers: int, progress: bool) -> None:
    from defgg_ros.data.datagen import DatagenConfig, generate

    what, settings, extras = TRIES[name]
    folder = PILOTS / name
    if not (folder / "candidates").exists():
        seed_candidates(folder)
    cfg = DatagenConfig(out=folder, objects=PILOT_OBJECTS, grasps_per_scene=CANDIDATES, pass_size=1,
                        workers=workers, settings=dict(settings), grasp_height="executor",
                        **extras)
    counts = generate(cfg, progress_bar=progress)
    write_report(name)
    partial = [folder / "signal_partial.json", folder / "signal_partial.md"]
    for path in partial:       # the finished report supersedes the one committed on the way
        path.unlink(missing_ok=True)
    print(json.dumps(counts))


def write_report(name: str, partial: bool = False) -> dict:
    """signal.{json,md} of a try from its trial records (partial: signal_partial.*, for a try still running)."""
    from defgg_ros.atomic import write_json_atomic, write_text_atomic
    from defgg_ros.data.signal import read_trial_records, render_markdown, signal_report, with_shake_from
    from defgg_ros.data.signal_figure import signal_figure

    what, settings, extras = TRIES[name]
    folder = PILOTS / name
    records = read_trial_records(folder)
    if name in SHAKE_FROM:
        records = with_shake_from(records, read_trial_records(PILOTS / SHAKE_FROM[name]))
    report = signal_report(records, LABEL_RULE.get(name, "shake"))
    report["try"] = {"name": name, "what": what, "settings": settings, "extras": extras,
                     "cpu_h": cpu_hours(folder)}
    if name in SHAKE_FROM:
        report["try"]["shake_from"] = SHAKE_FROM[name]
    stem = "signal_partial" if partial else "signal"
    title = f"Pilot {name}{' (partial)' if partial else ''}: {what}"
    write_json_atomic(folder / f"{stem}.json", report)
    write_text_atomic(folder / f"{stem}.md", render_markdown(report, title))
    signal_figure(report, records, folder / f"{stem}.png", title)
    return report
    print((folder / "signal.md").read_text(encoding="utf-8"))
    return report


def cpu_hours(folder: Path) -> float:
    from defgg_ros.data.signal import read_trial_records

    return sum(r.get("cpu_s", 0.0) for r in read_trial_records(folder)) / 3600


README_HEAD = """# Signal pilots (generated by bench/pilot_signal.py --summary; do not edit)

Each try labels the pilot set (6 training objects: four EGAD-like shapes of complexity 4-6, ycb_banana and
capsule; fem_v4's first 10 candidates of each; 2e4/2e5/2e6/2e9 Pa) under one trial setting. Its folder holds
the trial records, `signal.json`, `signal.md` and `signal.png`; `defgg-datagen signal bench/pilots/<try>`
recomputes them (d_defgraspsim_twist simulated only the twist: add `--shake-from bench/pilots/a_defgraspsim
--label shake_and_twist`).
Gate: oracle gap >= 5 points with a within-scene share >= 30 %. Columns: docs/dataset.md, "Signal report".

"""


def baselines() -> list:
    """fem_v4's signal (legacy protocol) over the whole dataset and over the pilot set's trials only (the
    same objects and candidates): the legacy baseline without simulating anything again."""
    from defgg_ros.data.signal import read_trial_records, signal_report

    records = read_trial_records(SOURCE)
    pilot = [r for r in records if r["object_name"] in PILOT_OBJECTS and r["candidate_index"] < CANDIDATES]
    out = []
    for name, what, recs in (("fem_v4", "fem_v4 whole (legacy)", records),
                             ("fem_v4_pilot_set", "fem_v4's labels of the pilot set (legacy)", pilot)):
        report = signal_report(recs)
        report["try"] = {"name": name, "what": what, "cpu_h": sum(r.get("cpu_s", 0.0) for r in recs) / 3600}
        out.append(report)
    return out


def summary() -> str:
    rows = ["| try | what | labelled | positive 2e4/2e5/2e6/2e9 | within-scene (soft) | soft+ & rigid- | "
            "oracle gap best / top5 (points) | near threshold | gate | CPU-h |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    total = 0.0
    tries = [json.loads(path.read_text(encoding="utf-8")) for path in sorted(PILOTS.glob("*/signal.json"))]
    for r in baselines() + tries:
        pos = "/".join(f"{100 * v['rate']:.0f}" for v in r["positive_rate"].values())
        gap, top = r["oracle"]["best"]["gap_points"], r["oracle"]["top5"]["gap_points"]
        share = r["within_scene_share"]["soft"]
        gate = "**yes**" if gap >= GATE_GAP_POINTS and share >= GATE_WITHIN_SHARE else "no"
        if r in tries:
            total += r["try"]["cpu_h"]
        rows.append(f"| {r['try']['name']} | {r['try']['what']} | {r['labelled']} | {pos} % | {100 * share:.1f} % | "
                    f"{100 * r['candidates']['soft_pos_rigid_neg']:.1f} % | {gap:.1f} / {top:.1f} | "
                    f"{100 * r['near_threshold']['all']:.0f} % | {gate} | "
                    f"{r['try']['cpu_h']:.2f} |")
    rows.append(f"\nPilot CPU so far: {total:.2f} CPU-h (budget ~8; the fem_v4 rows are its recorded CPU, not pilots).")
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tries", nargs="*", help=f"tries to run, of: {', '.join(TRIES)}")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--list", action="store_true", help="list the tries")
    ap.add_argument("--summary", action="store_true", help="print the table of finished tries")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--partial", metavar="TRY", help="write TRY's signal_partial.{json,md} from its records so far "
                                                      "(no simulation; for committing a try that is still running)")
    args = ap.parse_args(argv)
    if args.partial:
        if args.partial not in TRIES:
            print(f"pilot_signal: unknown try {args.partial}; known: {', '.join(TRIES)}", file=sys.stderr)
            return 2
        report = write_report(args.partial, partial=True)
        print(f"{report['labelled']} labelled of {report['trials']}: {PILOTS / args.partial}/signal_partial.md")
        return 0
    if args.list:
        for name, (what, settings, extras) in TRIES.items():
            print(f"{name}: {what} {settings} {extras}")
        return 0
    unknown = [t for t in args.tries if t not in TRIES]
    if unknown:
        print(f"pilot_signal: unknown tries {unknown}; known: {', '.join(TRIES)}", file=sys.stderr)
        return 2
    for name in args.tries:
        run_try(name, args.workers, not args.no_progress)
    if args.summary or args.tries:
        from defgg_ros.atomic import write_text_atomic

        text = summary()
        write_text_atomic(PILOTS / "README.md", README_HEAD + text + "\n")
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""docs/results.md, assembled from an evaluation folder's files (tables, summary, figures, manifest).

Every number in the report comes from those files; the only hand-written
part is an optional notes file (analysis), included verbatim and labelled.
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

from defgg_ros.atomic import write_text_atomic
from defgg_ros.data.header import protocol_summary
from defgg_ros.evaluation import report as report_mod
from defgg_ros.evaluation.diagnose import signal_lines
from defgg_ros.evaluation.tasks import shake_success_rule
from defgg_ros.sim.trial_settings import comparable_protocol


def _read(path) -> str | None:
    path = Path(path)
    return path.read_text(encoding="utf-8") if path.is_file() else None


def _rel(target, doc_path) -> str:
    return os.path.relpath(Path(target).resolve(), Path(doc_path).resolve().parent)


def _targets_md(targets: list) -> list:
    if not targets:
        return ["No shake results for both a stiffness-aware model and a baseline yet."]
    lines = ["| object set | with stiffness | no stiffness | margin (pts) | required | verdict | trials "
             "(graded / planned, per model) |", "|---|---|---|---|---|---|---|"]
    for t in targets:
        if t.get("status") == "no data":
            lines.append(f"| {t['set']} | – | – | – | – | no data yet | 0 |")
            continue
        req = f"margin > {t['required_margin_pts']:g}"
        verdict = "met" if t["margin_met"] else "NOT met"
        if "required_success_pct" in t:
            req += f", success ≥ {t['required_success_pct']:g} %"
            verdict = "met" if t["margin_met"] and t["success_met"] else "NOT met"
        if "sign_test_met" in t:
            if t.get("p_objects") is None:
                p = "no pairs" if t["p_sign_test"] is None else f"pairs p = {t['p_sign_test']:.3g}, objects not read"
            else:
                p = f"objects p = {t['p_objects']:.3g}; as independent pairs {t['p_sign_test']:.3g}"
            req += (f", ahead at p < {report_mod.TARGET_SIGN_TEST_P:g} over the five best grasps, objects the "
                    f"independent units ({p})")
            verdict = "met" if t["margin_met"] and t["sign_test_met"] else "NOT met"
        if not t["complete"]:
            verdict += " (partial data: not the full experiment)"
        lines.append(f"| {t['set']} | {t['with_stiffness_pct']:.1f} % | {t['no_stiffness_pct']:.1f} % | "
                     f"{t['margin_pts']:+.1f} | {req} | {verdict} | {t['trials'][0]}/{t['expected'][0]}, "
                     f"{t['trials'][1]}/{t['expected'][1]} |")
    return lines


def _commits_md(manifest: dict) -> str:
    """The code commits the runs into the folder started from (run.json's `commits`, oldest first)."""
    commits = manifest.get("commits", [manifest["commit"]])
    if len(commits) == 1:
        return f"Evaluation code commit: `{commits[0]}`"
    return (f"Evaluation code commits: {len(commits)}, one per run start that found a new one (the evaluation was "
            f"resumed), first `{commits[0]}`, latest run `{manifest['commit']}` (all in `run.json`)")


def _protocol_md(manifest: dict) -> str:
    """The trial protocol the run's trials were made with (run.json records its settings)."""
    recorded = manifest.get("trial_settings")
    if not recorded:
        return "Trial protocol: not recorded in run.json (a run made before run.json recorded it)."
    settings = comparable_protocol(recorded)
    rule = ("held through the pickup and a mean held acceleration >= 25 m/s^2 over the 16 directions (the "
            "label's own criterion; the every-direction rate is the second table)"
            if shake_success_rule(settings["protocol"]) == "mean" else "held at 25 m/s^2 in every direction")
    return f"Trial protocol: {protocol_summary(settings)}. Shake success: {rule}."


def _label_diagnostics(out_dir: Path) -> dict:
    """The training labels' diagnostics (diagnostics.json, written by `defgg-eval report --data DATASET`)."""
    diag = _read(out_dir / "diagnostics.json")
    return (json.loads(diag).get("labels") if diag else None) or {}


def _data_flag(labels: dict) -> str:
    """' --data DATASET' when the report's label diagnostics came from a training dataset, else ''."""
    return f" --data {labels['data_root']}" if labels.get("data_root") else ""


def _carry_lines(labels: dict) -> list:
    """Whether the training labels could have carried the targets' margins."""
    lines = signal_lines(labels.get("signal"), labels.get("data_root"))
    return lines or ["Whether the training labels could carry these margins: run `defgg-eval report --data "
                     "DATASET` for their signal report.", ""]


def distinct_commands(commands) -> list:
    """The evaluation commands that ran trials, without their --workers (speed, never a result), each once."""
    return list(dict.fromkeys(re.sub(r"\s--workers[ =]\d+", "", c) for c in commands if "--plan-only" not in c))


def _first_manifest(seed_runs: dict) -> dict:
    return report_mod.read_manifest(Path(next(iter(seed_runs.values()))))


def _label(manifest: dict) -> str:
    found = re.search(r"--protocol-from[ =](\S+)", manifest.get("command", ""))
    drive = (manifest.get("trial_settings") or {}).get("finger_drive", "speed")
    hand = "pressing" if drive == "press" else "speed-driven"
    return f"{Path(found.group(1)).name}, {hand}" if found else hand


def study_label(seed_runs: dict) -> str:
    """A seed study's short name: the dataset its evaluation took the trial protocol from, and the trial hand."""
    return _label(_first_manifest(seed_runs))


def _study_title(seed_runs: dict) -> str:
    """What sets one seed study apart: its protocol's dataset, the trial hand and its weights' training data."""
    manifest = _first_manifest(seed_runs)
    prints = sorted({m.get("data_fingerprint", "?") for m in manifest.get("models", {}).values()})
    return f"{_label(manifest)} trial hand; training data fingerprint {', '.join(prints)}"


def _seeds_lines(studies: list, figure=None, doc_path=None) -> list:
    """The seed studies' section: [(seed_runs, table_md)], one table per study (a title each when several), and
    the figure of them all (figures.seeds_figure) when given."""
    if not studies:
        return []
    lines = ["## Seeds: how much of the margin is the training seed?", "",
             "Each seed's pair (same data, schedule and validation objects; epochs chosen on validation) evaluated "
             "under the same protocol; the paired margin (points, with stiffness minus depth only) per seed, the mean "
             "over seeds with a 95 % bootstrap interval over objects, and two tests pooled over seeds: **objects**, an "
             "exact sign-flip test of each object's net (only with stiffness − only depth only, summed over the "
             "seeds; objects the independent units), and **pairs**, the sign test on the discordant pairs, which "
             "counts every pair as independent although a view's ranks share its object and the seeds share their "
             "views (smaller than it should be). The shipped pair is the seed its model card names. A seed whose "
             "folder holds fewer trials than the others' is a partial result. The interval resamples objects with "
             "the seeds held fixed, so the spread between seeds is not in it (the per-seed rows show it).", ""]
    if figure is not None and Path(figure).exists():
        lines += [f"![seed studies]({_rel(Path(figure), doc_path)})", ""]
    for seed_runs, table_md in studies:
        runs = " ".join(f"{seed}={out}" for seed, out in seed_runs.items())
        if len(studies) > 1:
            lines += [f"### {_study_title(seed_runs)}", ""]
        lines += [f"`defgg-eval seeds --run {runs}`", "", table_md.strip(), ""]
    return lines


def _cell_lines(cell_dir, doc_path) -> list:
    """The cell experiment's own report (results/cell_experiment/report.md), under a section heading."""
    if cell_dir is None:
        return []
    report = _read(Path(cell_dir) / "report.md")
    if not report:
        return []
    body = report.split("\n", 1)[1].strip() if report.startswith("# ") else report.strip()
    body = body.replace("](per_object.png)", f"]({_rel(Path(cell_dir) / 'per_object.png', doc_path)})")
    return ["## The paper's real-robot experiment in the simulated cell", "", body, ""]


def results_markdown(out_dir, doc_path, notes_path=None, seed_studies=(), cell_dir=None, seeds_figure=None) -> str:
    """The Markdown report; seed_studies: [(seed_runs, table_md)], one per --seeds; seeds_figure: their PNG."""
    out_dir = Path(out_dir)
    manifest = report_mod.read_manifest(out_dir)
    summary = json.loads((out_dir / report_mod.SUMMARY_FILE).read_text())
    tdir = out_dir / report_mod.TABLES_DIR
    objects = {s: [o["name"] for o in objs] for s, objs in manifest["objects"].items()}
    labels = _label_diagnostics(out_dir)
    command = (f"defgg-eval report --out {out_dir} --docs {doc_path}" + _data_flag(labels)
               + (f" --notes {notes_path}" if notes_path else "")
               + "".join(" --seeds " + " ".join(f"{k}={v}" for k, v in runs.items()) for runs, _ in seed_studies)
               + (f" --cell {cell_dir}" if cell_dir is not None else ""))
    lines = [
        "# Results: the paper's experiments in our FEM simulator", "",
        f"*Generated by `{command}` from the files in "
        f"`{out_dir}/`; do not edit by hand.*", "",
        "## How to reproduce", "",
        "1. Evaluation (resumable; rerun the same commands to continue; `--workers N` runs N in parallel; "
        "`results/run_budgeted_eval.sh` runs every step in order, its header says how). The commands run into "
        "this folder so far: "
        + "; ".join(f"`{c}`" for c in distinct_commands(manifest.get("commands", [manifest["command"]]))),
        f"2. Tables, plots and this report: `{command}`",
        f"3. Strategy figure: `defgg-eval strategy --out {out_dir}`",
        "4. Models and their training: see the model cards `models/defgg_cnn.md` and "
        "`models/ggcnn_depth_only.md` (commands, data fingerprint, trials used).", "",
        f"{_commits_md(manifest)}; object pose seed {manifest['seed']}; "
        f"{manifest['grasps_per_object']} best grasps per object and modulus; tasks {', '.join(manifest['tasks'])}.",
        "", _protocol_md(manifest), "",
        "## Models", "", "| name | input | weights sha (16) | training data fingerprint |", "|---|---|---|---|"]
    for name, m in manifest["models"].items():
        lines.append(f"| `{name}` | {'depth + stiffness' if m['uses_stiffness'] else 'depth only'} | `{m['sha']}` | "
                     f"`{m.get('data_fingerprint')}` |")
    lines += ["", "## Objects", ""]
    lines += [f"- **{s}** ({len(names)}): {', '.join(names)}" for s, names in objects.items()]
    lines += ["", "## How complete this is", "",
              f"{summary['records']} trial records, {summary['simulated']} distinct simulations "
              f"({summary['sim_cpu_h']:.2f} CPU-hours); the rest reuse an identical simulation (same grasp) or "
              "record that the model proposed no grasp. Every table cell shows successes/graded trials and, while "
              "incomplete, how many of the planned trials have run. **A cell with fewer trials than planned is a "
              "partial result, not the full experiment.**", ""]
    if manifest.get("quick"):
        lines += ["**WARNING: this run used --quick (0.1 s ramps): a smoke test, not the paper's protocol.**", ""]
    for task in manifest["tasks"]:
        lines += [f"## {task.capitalize()} task", "", _read(tdir / f"{task}.md") or "(no table yet)", ""]
        every = _read(tdir / f"{task}_every_direction.md")   # the second column under the label's own rule
        if every:
            lines += [every, ""]
        by_rank = _read(tdir / f"{task}_by_rank.md")
        if by_rank:
            lines += [by_rank, ""]
    lines += ["## Targets of the issue (shake task, all stiffnesses)", ""] + _targets_md(summary["targets"]) + [""]
    lines += _seeds_lines(list(seed_studies), seeds_figure, doc_path) + _cell_lines(cell_dir, doc_path)
    lines += _carry_lines(labels)
    pairs_md = _read(tdir / "paired.md")
    if pairs_md:
        lines += ["## Are the two models separable on these trials?", "", pairs_md, ""]
    for md in sorted(tdir.glob("sensitivity*.md")):
        lines += ["## Sensitivity to errors in the stiffness input", "", _read(md), "",
                  f"![sensitivity]({_rel(md.with_suffix('.png'), doc_path)})", ""]
        pairs_md = _read(tdir / f"paired_{md.name}")
        if pairs_md:
            lines += [pairs_md, ""]
    strategy = _read(out_dir / "strategy.json")
    if strategy:
        s = json.loads(strategy)
        lines += ["## Strategy figure", "", f"![strategy]({_rel(out_dir / 'strategy.png', doc_path)})", "",
                  f"Best grasp of `{s['model']}` on `{s['object']}`:", ""]
        for e, grasps in s["best_grasps"].items():
            if grasps:
                g = grasps[0]
                lines.append(f"- E = {float(e):.0e} Pa: **{g['strategy']}**, opening {g['width_mm']:.0f} mm of "
                             f"{g['object_extent_along_closing_mm']:.0f} mm object extent along the closing line, "
                             f"{g['offset_from_centre_mm']:.0f} mm from the object centre, quality {g['quality']:.2f}")
        lines.append("")
    mm = _read(tdir / "multimaterial.md")
    if mm:
        lines += ["## Multi-material object", "", mm, ""]
    ceiling_md = _read(out_dir / "ceiling.md")
    if ceiling_md:
        # ceiling.md starts with its own title; the report gives it a section heading instead
        body = ceiling_md.split("\n", 1)[1].strip()
        from defgg_ros.evaluation.ceiling import recorded_commands  # loads the simulator (~0.9 s): only here

        commands = "; ".join(f"`{c}`" for c in recorded_commands(out_dir)) or f"`defgg-eval ceiling --out {out_dir}`"
        lines += ["## What any grasp choice could reach: the sampler's candidates under the task", "",
                  f"Commands (resumable): {commands} (defgg_ros/evaluation/ceiling.py).", "", body, ""]
    diag = _read(out_dir / "diagnostics.md")
    if diag:
        lines += ["## Diagnostics: do the labels depend on the stiffness and on the grasp's place, how repeatable "
                  "is a trial, does the predicted quality rank grasps, and where does the twist fail?",
                  "", diag, ""]
    notes = _read(notes_path) if notes_path else None
    if notes:
        lines += ["## Analysis (written by the engineer, from the numbers above)", "", notes.strip(), ""]
    return "\n".join(lines) + "\n"


def write_results_doc(out_dir, doc_path, notes_path=None, seed_studies=(), cell_dir=None, seeds_figure=None) -> Path:
    write_text_atomic(doc_path, results_markdown(out_dir, doc_path, notes_path, seed_studies, cell_dir, seeds_figure))
    return Path(doc_path)

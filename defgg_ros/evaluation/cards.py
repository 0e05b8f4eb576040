"""Shipped weights in models/ and their model cards, generated from files (never typed by hand).

``ship_model`` copies a training run's best checkpoint to ``models/<name>.pt``
and writes ``models/<name>.train.json``: the provenance of those weights
(command, wall time, git commit, dataset root and fingerprint, the trials per
object x modulus that were used, validation metrics). ``write_card`` renders
``models/<name>.md`` from that file, the checkpoint itself and, when given, an
evaluation folder's summary.json.
"""
from __future__ import annotations

import json
import shutil
import tarfile
from collections import defaultdict
from pathlib import Path

import torch

from defgg_ros.atomic import atomic_path, write_json_atomic, write_text_atomic
from defgg_ros.data.format import read_trials
from defgg_ros.data.header import recorded_grasp_height, recorded_protocol
from defgg_ros.grip_force import LabelGripRule
from defgg_ros.model.checkpoint import load_checkpoint

PROVENANCE_SUFFIX = ".train.json"


class CardError(RuntimeError):
    """A training run or model file that cannot be shipped or described."""


def trial_counts(data_root, manifest: dict) -> dict:
    """{object: {E: {"trials", "labelled", "positive"}}} over the manifest's trials (what training saw)."""
    counts = defaultdict(dict)
    for sid, n in sorted(manifest.items()):
        trials = read_trials(data_root, sid)[:n]
        if not trials:
            continue
        t0 = trials[0]
        labels = [t.label for t in trials]
        counts[t0.object_name][f"{t0.youngs_modulus_pa:.0e}"] = {
            "trials": len(trials), "labelled": sum(lbl is not None for lbl in labels),
            "positive": sum(lbl is True for lbl in labels)}
    return dict(counts)


def training_provenance(run_dir, command: str, wall_s: float, commit: str) -> dict:
    run_dir = Path(run_dir)
    try:
        metrics = json.loads((run_dir / "metrics.json").read_text())
        state = torch.load(run_dir / "state.pt", map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - unreadable, not JSON, or a state.pt weights_only refuses (Unpickling)
        raise CardError(f"{run_dir}: not a finished defgg-train run ({exc})") from None
    fingerprint = metrics["data"]["fingerprint"]
    if state.get("data_fingerprint", fingerprint) != fingerprint:   # a new run began over an old one's files
        raise CardError(f"{run_dir}: state.pt is of data {state['data_fingerprint']}, metrics.json of {fingerprint}: "
                        "files of two runs; train into a fresh folder")
    best_epoch = metrics.get("best_epoch")
    best = next((h for h in metrics["history"] if h["epoch"] == best_epoch), metrics["history"][-1])
    data_root = metrics["data"]["root"]
    return {
        "command": command, "wall_s": float(wall_s), "commit": commit, "run_dir": str(run_dir),
        "data_root": data_root, "data_fingerprint": metrics["data"]["fingerprint"],
        "n_trials": metrics["data"]["n_trials"], "object_split": metrics["data"]["object_split"],
        "scenes": metrics["data"]["scenes"], "train_config": metrics["config"], "best_epoch": best_epoch,
        "epochs_run": len(metrics["history"]), "val_best": best, "test": metrics.get("test"),
        "stiffness_response": metrics.get("stiffness_response"),
        "trial_counts": trial_counts(data_root, state["manifest"]), "manifest": state["manifest"],
    }


CHECKPOINTS = {"best": "best.pt", "last": "model.pt"}


def ship_model(run_dir, name: str, models_dir, provenance: dict, checkpoint: str = "best") -> Path:
    """Copy the run's best (or last-epoch) checkpoint to models_dir/<name>.pt (verified, atomic), with provenance."""
    if checkpoint not in CHECKPOINTS:
        raise CardError(f"checkpoint must be one of {sorted(CHECKPOINTS)}, got {checkpoint!r}")
    src = Path(run_dir) / CHECKPOINTS[checkpoint]
    trained_on = load_checkpoint(src)["data_fingerprint"]   # refuses a corrupt or foreign file before it is shipped
    if "data_fingerprint" in provenance and trained_on != provenance["data_fingerprint"]:
        raise CardError(f"{src} was trained on data {trained_on}, the run's metrics.json says "
                        f"{provenance['data_fingerprint']}: files of two runs; train into a fresh folder")
    dst = Path(models_dir) / f"{name}.pt"
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)
    dst.chmod(0o644)
    payload = load_checkpoint(dst)
    shipped_epoch = payload["meta"].get("epoch")
    prov_path = Path(models_dir) / f"{name}{PROVENANCE_SUFFIX}"
    write_json_atomic(prov_path, {**provenance, "weights_sha256": payload["weights_sha256"],
                                  "shipped_checkpoint": checkpoint, "shipped_epoch": shipped_epoch,
                                  "shipped_metrics": {k: payload["meta"].get(k) for k in
                                                      ("val_accuracy", "val_loss", "val_per_modulus")}})
    prov_path.chmod(0o644)
    return dst


def _grip_rule_text(meta: dict) -> str:
    """The label grip rule the weights record (grip_force.LabelGripRule), as the card states it."""
    rule = LabelGripRule.from_meta(meta)
    recorded = "recorded in the weights" if "label_grip_rule" in meta else \
        "the weights record no rule: trained before 2026-11-27"
    if rule.needs_mass:
        return (f"{rule.protocol}, FOS·m·g/μ with μ {rule.friction:.2f}, the mass estimated from the height map "
                f"({recorded}; docs/real_cell.md)")
    return f"legacy, 2 N + 0.5 N per decade of E a finger ({recorded})"


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def render_card(name: str, models_dir, eval_summary: dict | None = None, eval_dir: str = "",
                seeds_dir=None, seed_table: str | None = None) -> str:
    models_dir = Path(models_dir)
    prov_path = models_dir / f"{name}{PROVENANCE_SUFFIX}"
    if not prov_path.is_file():
        raise CardError(f"{prov_path} missing: ship the model with `defgg-eval ship` first")
    prov = json.loads(prov_path.read_text())
    payload = load_checkpoint(models_dir / f"{name}.pt")
    if payload["weights_sha256"] != prov["weights_sha256"]:
        raise CardError(f"{name}.pt does not match its provenance file (weights changed since shipping)")
    cfg = payload["network_config"]
    uses_stiffness = cfg["input_channels"] == 2
    lines = [f"# Model card: `{name}`", "",
             "*Generated by `defgg-eval card`; do not edit by hand.*", "",
             f"- **Model**: {'Def-GG-CNN (depth + stiffness)' if uses_stiffness else 'GG-CNN baseline (depth only)'}"
             f", architecture `{cfg.get('architecture')}`, {cfg['input_channels']} input channel(s), "
             f"input {cfg.get('input_size_px')} px; encodings {payload['input_normalization']}",
             f"- **Weights**: `models/{name}.pt`, sha256 `{payload['weights_sha256']}`",
             f"- **Produced by commit**: `{prov['commit']}`",
             f"- **Training command**: `{prov['command']}`",
             f"- **Training time**: {prov['wall_s'] / 60:.1f} min wall clock, {prov['epochs_run']} epochs, "
             f"best validation epoch {prov['best_epoch']} (torch threads: 1)",
             f"- **Shipped checkpoint**: {prov.get('shipped_checkpoint', 'best')} (epoch "
             f"{prov.get('shipped_epoch', prov['best_epoch'])})" + (f". {prov['note']}" if prov.get("note") else ""),
             f"- **Grip force the cell closes these grasps with**: {_grip_rule_text(payload['meta'])}",
             f"- **Training data**: `{prov['data_root']}` (frozen for this run at "
             f"{prov['n_trials']} trials), data fingerprint `{prov['data_fingerprint']}`; scenes per split "
             f"{prov['scenes']}", ""]
    lines += _data_section(prov)
    lines += _validation_section(prov)
    lines += _eval_section(name, eval_summary, eval_dir, payload["weights_sha256"][:16])
    if seeds_dir is not None:
        lines += _seeds_section(name, prov, Path(seeds_dir), seed_table)
    return "\n".join(lines) + "\n"


def _data_section(prov) -> list:
    split = prov["object_split"]
    counts = prov["trial_counts"]
    moduli = sorted({e for per in counts.values() for e in per}, key=float)
    header = _generator_header(prov)
    lines = ["## Training data", ""]
    if prov.get("data_source"):
        lines += [f"Source: {prov['data_source']}.", ""]
    if prov.get("data_archive"):
        lines += [f"Shipped: `{prov['data_archive']}` holds exactly these trials (fingerprint verified when it was "
                  f"written). Reproduce the training: `mkdir -p runs/frozen && tar xzf {prov['data_archive']} -C "
                  f"runs/frozen`, then the training command above with `--data runs/frozen/train_data`.", ""]
    if header:
        protocol = recorded_protocol(header)
        lines += [f"Trial protocol of the labels: {protocol.summary()} (docs/dataset.md, 'Trial protocols').", "",
                  f"Generator settings (`dataset.json`, written by `defgg-datagen`): `{json.dumps(header)}`", ""]
        if protocol.name == "defgraspsim":
            lines += ["Grip force of these labels: FOS·m·g/μ, from the object's mass (defgg_ros/grip_force.py). "
                      "Weights trained since 2026-11-27 record the rule (`label_grip_rule`); with the tabletop "
                      "planner the cell then closes each grasp with it, the mass estimated from the height map "
                      "(volume × 1000 kg/m³; Grasp.finger_force_n, docs/real_cell.md). Weights without the record "
                      "are closed with the legacy rule (2 N + 0.5 N per decade of E a finger).", ""]
        if "n_candidates" in header and recorded_grasp_height(header) == "contacts":   # defgg-datagen's
            lines += ["Known limitation of these labels: the candidates sit at their contacts' height, anywhere up "
                      "the object's side, while the evaluation executes a grasp at half the height seen at its "
                      "pixel; moved to that height, half of the off-height soft labels change "
                      "(`docs/archive/notes_height.md`, `bench/README.md`).", ""]
    lines += [f"Objects by split (split by object, seed {prov['train_config']['seed']}): "
             + "; ".join(f"**{k}** ({len(v)}): {', '.join(sorted(v))}" for k, v in split.items()), "",
             "Trials used per object and Young's modulus (positive / labelled):", "",
             "| object | " + " | ".join(f"E = {e} Pa" for e in moduli) + " |", "|---" * (len(moduli) + 1) + "|"]
    totals = defaultdict(lambda: [0, 0])
    for obj in sorted(counts):
        cells = []
        for e in moduli:
            c = counts[obj].get(e)
            cells.append("–" if c is None else f"{c['positive']}/{c['labelled']}")
            if c:
                totals[e][0] += c["positive"]
                totals[e][1] += c["labelled"]
        lines.append(f"| {obj} | " + " | ".join(cells) + " |")
    lines.append("| **total** | " + " | ".join(f"**{totals[e][0]}/{totals[e][1]}**" for e in moduli) + " |")
    return lines + [""]


def _generator_header(prov) -> dict:
    """The training data's generator header: from its folder if present, else from the shipped archive."""
    header_path = Path(prov["data_root"]) / "dataset.json"
    if header_path.is_file():
        return json.loads(header_path.read_text()).get("generator", {})
    archive = Path(prov.get("data_archive") or "")
    if archive.is_file():
        with tarfile.open(archive, "r:gz") as tar:
            member = next((m for m in tar.getmembers() if m.name.endswith("/dataset.json")), None)
            if member is not None:
                return json.loads(tar.extractfile(member).read()).get("generator", {})
    return {}


def _validation_section(prov) -> list:
    best = prov.get("shipped_metrics") or prov["val_best"]
    lines = ["## Validation of the shipped weights (held-out training-set objects, top-1 grasp rectangle metric)",
             "",
             f"Overall: {_pct(best.get('val_accuracy'))}, validation loss {best.get('val_loss', float('nan')):.4f}.",
             "", "| E (Pa) | scenes | rectangle accuracy |", "|---|---|---|"]
    for e, m in best.get("val_per_modulus", {}).items():
        lines.append(f"| {e} | {m['n']} | {_pct(m['accuracy'])} |")
    if prov.get("test"):
        lines += ["", f"Test objects: {_pct(prov['test'].get('accuracy'))} over {prov['test'].get('n')} scenes."]
    if prov.get("stiffness_response"):
        lines += ["", f"Stiffness response of the best-validation checkpoint (epoch {prov['best_epoch']}, computed by "
                  "defgg-train; same depth, only the stiffness input changed): "
                  + "; ".join(f"E={e}: mean |dQ| {v['mean_abs_dq']:.3f}, top-1 shift {v['mean_top1_shift_px']:.1f} px"
                              for e, v in prov["stiffness_response"].items())]
    return lines + [""]


def _eval_section(name, summary, eval_dir, sha16: str) -> list:
    lines = ["## Evaluation in the FEM simulator (held-out object sets)", ""]
    if not summary or summary.get("models", {}).get(name, {}).get("sha") != sha16:
        return lines + ["Not evaluated yet with these weights.", ""]
    lines.append(f"From `{eval_dir}/summary.json` (its report, docs/results.md or docs/results_sim_v*.md, has the "
                 "full tables and how complete each cell is). Success over all stiffnesses:")
    lines += ["", "| task | object set | success | trials graded / planned |", "|---|---|---|---|"]
    for task, cells in summary["tasks"].items():
        for key, c in cells.items():
            parts = key.split("|")
            if len(parts) != 2 or parts[1] != name:
                continue
            rate = "–" if c["success_pct"] is None else f"{c['success_pct']:.1f} %"
            lines.append(f"| {task} | {parts[0]} | {rate} | {c['graded']} / {c['expected']} |")
    return lines + [""]


def _seed_metrics(name: str, seeds_dir: Path) -> list:
    """[(seed, best epoch, best validation accuracy, test accuracy)] of the other seeds' training runs
    (<seeds_dir>/weights_s<seed>/<name>.metrics.json, as results/run_seed_study.sh stores them)."""
    rows = []
    for path in sorted(seeds_dir.glob(f"weights_s*/{name}.metrics.json")):
        metrics = json.loads(path.read_text())
        best = next(e for e in metrics["history"] if e["epoch"] == metrics["best_epoch"])
        rows.append((path.parent.name.removeprefix("weights_s"), metrics["best_epoch"], best.get("val_accuracy"),
                     (metrics.get("test") or {}).get("accuracy")))
    return rows


def _seeds_section(name: str, prov: dict, seeds_dir: Path, seed_table: str | None = None) -> list:
    """The other training seeds (same data, schedule and split): what each gave on validation, and which was
    shipped (chosen on validation only); seed_table: what each seed's pair gave in the simulator
    (`defgg-eval seeds`' table), else a pointer to docs/results.md."""
    rows = _seed_metrics(name, seeds_dir)
    if not rows:
        return []
    seed = prov.get("train_config", {}).get("seed", 0)
    lines = ["## Training seeds", "",
             f"The shipped weights are seed {seed}'s, chosen on validation only (never on the evaluation). The same "
             f"training with other seeds (`{seeds_dir}`, results/run_seed_study.sh) gave:", "",
             "| seed | best validation epoch | validation accuracy | test objects |", "|---|---|---|---|",
             f"| {seed} (shipped) | {prov['best_epoch']} | {_pct(prov['val_best'].get('val_accuracy'))} | "
             f"{_pct((prov.get('test') or {}).get('accuracy'))} |"]
    lines += [f"| {s} | {epoch} | {_pct(val)} | {_pct(test)} |" for s, epoch, val, test in rows]
    if seed_table is None:
        return lines + ["", "What each seed's pair gives in the simulator: docs/results.md, \"Seeds\".", ""]
    return lines + ["", "What each seed's pair gave in the simulator (`defgg-eval seeds`: the paired margin of the "
                    "stiffness-aware model over the depth-only one, shake; docs/results.md, \"Seeds\"):", "",
                    seed_table.rstrip("\n"), ""]


def write_card(name: str, models_dir, eval_dir=None, seeds_dir=None, seed_table: str | None = None) -> Path:
    summary = None
    if eval_dir is not None and (Path(eval_dir) / "summary.json").is_file():
        summary = json.loads((Path(eval_dir) / "summary.json").read_text())
    path = Path(models_dir) / f"{name}.md"
    write_text_atomic(path, render_card(name, models_dir, summary, str(eval_dir or ""), seeds_dir, seed_table))
    path.chmod(0o644)
    return path

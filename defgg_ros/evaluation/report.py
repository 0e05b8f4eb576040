"""Write every output of an evaluation folder from its results file and manifest.

<out>/run.json           manifest (models + weights sha, objects, moduli, grasps, tasks, command, commit)
<out>/trials.jsonl       one record per trial (the only source of every number below)
<out>/tables/<task>.md|.csv, <task>_by_rank.md|.csv, paired.md|.csv, sensitivity.md|.csv|.png,
                         multimaterial.md|.csv
<out>/summary.json       headline numbers + completeness, read by the model cards and docs
"""
from __future__ import annotations

import json
from pathlib import Path

from defgg_ros.atomic import write_json_atomic, write_text_atomic
from defgg_ros.constants import TRAINING_YOUNGS_MODULI_PA
from defgg_ros.data.format import STATUS_OK
from defgg_ros.evaluation import figures, paired, ranks, tables
from defgg_ros.evaluation.store import read_results, results_path

MANIFEST_FILE = "run.json"
SUMMARY_FILE = "summary.json"
TABLES_DIR = "tables"
# Issue targets (shake task, all stiffnesses).
TARGET_MARGIN_COMMON_PTS = 15.0
TARGET_COMMON_SUCCESS_PCT = 75.0
TARGET_SIGN_TEST_P = 0.05      # adversarial set: ahead with a paired sign test p below this


class ReportError(RuntimeError):
    """An evaluation folder without a manifest or results."""


def read_manifest(out_dir) -> dict:
    path = Path(out_dir) / MANIFEST_FILE
    if not path.is_file():
        raise ReportError(f"{path} missing: run `defgg-eval run --out {out_dir}` first")
    return json.loads(path.read_text(encoding="utf-8"))


def _models(manifest) -> tuple:
    names = list(manifest["models"])
    shas = {n: manifest["models"][n]["sha"] for n in names}
    labels = {n: ("with stiffness" if manifest["models"][n]["uses_stiffness"] else "no stiffness") + f" ({n})"
              for n in names}
    return names, shas, labels


def current_records(out_dir) -> list:
    """A results folder's trial records of the weights its run.json names (a retrained model's older trials stay in
    the file); every record when the folder has no run.json."""
    records = read_results(results_path(out_dir))
    if not (Path(out_dir) / MANIFEST_FILE).is_file():
        return records
    return tables.current(records, _models(read_manifest(out_dir))[1])


def _moduli(manifest) -> list:
    moduli = sorted({e for objs in manifest["objects"].values() for o in objs for e in o["moduli_pa"]})
    return moduli or list(TRAINING_YOUNGS_MODULI_PA)


def _expected_main(manifest) -> dict:
    out = {}
    for s, objs in manifest["objects"].items():
        for o in objs:
            for e in o["moduli_pa"]:
                out[(s, e)] = out.get((s, e), 0) + manifest["grasps_per_object"]
    return out


def _has_second_column(records, task: str) -> bool:
    """Whether the task's success has an every-direction column: only where a graded trial carries a
    verdict for it (the defgraspsim shake). A twist record reused from another view copies the field as
    None, and a no-grasp record sets it for any task: neither makes a second column."""
    return any(r.get("task") == task and r.get("status") == STATUS_OK and r.get("success_every_direction") is not None
               for r in records)


def write_outputs(out_dir) -> dict:
    """(Re)write tables, plots and summary.json of `out_dir`; returns the summary."""
    out_dir = Path(out_dir)
    manifest = read_manifest(out_dir)
    models, shas, labels = _models(manifest)
    records = tables.current(read_results(results_path(out_dir)), shas)
    sets = list(manifest["objects"])
    moduli = _moduli(manifest)
    tdir = out_dir / TABLES_DIR
    summary = {"models": manifest["models"], "tasks": {}, "records": len(records),
               "simulated": sum(1 for r in records if r.get("reused_from") is None and r.get("sim_key")),
               "sim_cpu_h": sum(r.get("cpu_s") or 0 for r in records if r.get("reused_from") is None) / 3600}
    expected = _expected_main(manifest)
    for task in manifest["tasks"]:
        cells = tables.main_table(records, task, sets, models, moduli, expected)
        write_text_atomic(tdir / f"{task}.md", tables.main_table_markdown(cells, task, sets, models, moduli, labels))
        write_text_atomic(tdir / f"{task}.csv", tables.main_table_csv(cells, task, sets, models, moduli))
        every_path = tdir / f"{task}_every_direction.md"
        if _has_second_column(records, task):
            every = tables.main_table(records, task, sets, models, moduli, expected, field="success_every_direction")
            write_text_atomic(every_path, tables.main_table_markdown(
                every, task, sets, models, moduli, labels, title=f"**{task.capitalize()} task, held in every "
                "direction** (the second column): success rate in % (successes/graded trials)"))
            summary["tasks"][f"{task}_every_direction"] = {
                f"{s}|{m}": _cell_json(every[(tables.ALL_STIFFNESSES, s, m)]) for s in sets for m in models}
        else:
            every_path.unlink(missing_ok=True)    # a table an earlier report wrote from misread records
        summary["tasks"][task] = {f"{s}|{m}": _cell_json(cells[(tables.ALL_STIFFNESSES, s, m)])
                                  for s in sets for m in models}
        summary["tasks"][task].update({f"{s}|{m}|{e:g}": _cell_json(cells[(e, s, m)])
                                       for s in sets for m in models for e in moduli})
        _write_ranks(records, task, manifest, models, labels, tdir)
    summary["paired"] = _write_paired(records, manifest, labels, tdir)
    if "sensitivity" in manifest["experiments"]:
        summary["sensitivity"] = _write_sensitivity(records, manifest, models, labels, tdir)
    if "multimaterial" in manifest["experiments"]:
        rows = tables.multimaterial_rows(records, manifest["grasps_per_object"])
        write_text_atomic(tdir / "multimaterial.md", tables.multimaterial_markdown(rows, labels))
        write_text_atomic(tdir / "multimaterial.csv", tables.multimaterial_csv(rows))
    summary["targets"] = targets(summary, manifest)
    write_json_atomic(out_dir / SUMMARY_FILE, summary)
    return summary


def _write_ranks(records, task, manifest, models, labels, tdir) -> None:
    sets, n_ranks = list(manifest["objects"]), manifest["grasps_per_object"]
    views = {s: sum(len(o["moduli_pa"]) for o in objs) for s, objs in manifest["objects"].items()}
    cells = ranks.rank_cells(records, task, sets, models, n_ranks, views)
    write_text_atomic(tdir / f"{task}_by_rank.md", ranks.rank_markdown(cells, task, sets, models, n_ranks, labels))
    write_text_atomic(tdir / f"{task}_by_rank.csv", ranks.rank_csv(cells, task, sets, models, n_ranks))


def _stiff_and_base(models: dict) -> tuple:
    """(stiffness-aware model names, baseline names) of a manifest's models, in manifest order."""
    return ([m for m in models if models[m]["uses_stiffness"]], [m for m in models if not models[m]["uses_stiffness"]])


def _write_paired(records, manifest, labels, tdir) -> list:
    """tables/paired.md|.csv: the first stiffness-aware model against the first baseline, trial by trial."""
    stiff, base = _stiff_and_base(manifest["models"])
    if not stiff or not base:
        return []
    rows = paired.paired_rows(records, manifest["tasks"], list(manifest["objects"]), stiff[0], base[0])
    write_text_atomic(tdir / "paired.md", paired.paired_markdown(rows, labels[stiff[0]], labels[base[0]]))
    write_text_atomic(tdir / "paired.csv", paired.paired_csv(rows, stiff[0], base[0]))
    return [{"task": t, "set": s, "grasps": scope, "pairs": p.pairs, "a_only": p.a_only, "b_only": p.b_only,
             "margin_pts": p.margin_pts, "p_sign_test": p.p_value, "objects": len(p.objects),
             "p_objects": p.object_p_value, "interval_objects_pts": p.object_interval_pts()}
            for t, s, scope, p in rows]


def _write_sensitivity(records, manifest, models, labels, tdir) -> dict:
    """Tables and plot per stiffness model; {model: {error: cell}} (n best grasps), plus
    {"<model>|<scope>": ...} for the like-for-like columns (tables.sensitivity_scopes)."""
    stiff, _ = _stiff_and_base(manifest["models"])
    object_set = "common" if "common" in manifest["objects"] else next(iter(manifest["objects"]))
    n_rows = sum(len(o["moduli_pa"]) for o in manifest["objects"][object_set])
    out = {}
    for m in stiff:
        scopes = tables.sensitivity_scopes(records, m, object_set, n_rows, manifest["grasps_per_object"])
        suffix = "" if len(stiff) == 1 else f"_{m}"
        write_text_atomic(tdir / f"sensitivity{suffix}.md", tables.sensitivity_markdown(scopes, labels[m], object_set))
        write_text_atomic(tdir / f"sensitivity{suffix}.csv", tables.sensitivity_csv(scopes, m, object_set))
        figures.sensitivity_plot(scopes, tdir / f"sensitivity{suffix}.png", labels[m])
        for key, (_, cells) in scopes.items():
            out[m if key == "all" else f"{m}|{key}"] = {f"{e:g}": _cell_json(c) for e, c in cells.items()}
        pairs = paired.sensitivity_pairs(records, m, object_set)
        write_text_atomic(tdir / f"paired_sensitivity{suffix}.md",
                          paired.sensitivity_paired_markdown(pairs, labels[m], object_set))
        out[f"{m}|paired"] = {f"{e:g}": {"pairs": p.pairs, "correct_only": p.a_only, "wrong_only": p.b_only,
                                         "margin_pts": p.margin_pts, "p_sign_test": p.p_value} for e, p in pairs}
    return out


def _cell_json(c: tables.Cell) -> dict:
    return {"success_pct": c.rate_pct, "successes": c.success, "graded": c.graded, "sim_failed": c.sim_failed,
            "no_grasp": c.no_grasp, "expected": c.expected}


def targets(summary: dict, manifest: dict) -> list:
    """The issue's targets, each with its numbers and whether the data is complete enough to judge."""
    shake = summary["tasks"].get("shake")
    stiff, base = _stiff_and_base(manifest["models"])
    if not shake or not stiff or not base:
        return []
    out = []
    for s in manifest["objects"]:
        a, b = shake.get(f"{s}|{stiff[0]}"), shake.get(f"{s}|{base[0]}")
        if not a or not b or a["success_pct"] is None or b["success_pct"] is None:
            out.append({"set": s, "status": "no data"})
            continue
        margin = a["success_pct"] - b["success_pct"]
        need = TARGET_MARGIN_COMMON_PTS if s == "common" else 0.0
        item = {"set": s, "with_stiffness_pct": a["success_pct"], "no_stiffness_pct": b["success_pct"],
                "margin_pts": margin, "required_margin_pts": need, "margin_met": margin > need,
                "complete": all(c["graded"] + c["sim_failed"] + c.get("no_grasp", 0) >= c["expected"] for c in (a, b)),
                "trials": [a["graded"], b["graded"]], "expected": [a["expected"], b["expected"]]}
        if s == "common":
            item["required_success_pct"] = TARGET_COMMON_SUCCESS_PCT
            item["success_met"] = a["success_pct"] >= TARGET_COMMON_SUCCESS_PCT
        else:   # ahead, and separable from chance over the five best grasps, objects the independent units
            p = next((r for r in summary.get("paired", []) if r["task"] == "shake" and r["set"] == s
                      and r["grasps"] == paired.ALL_RANKS), None)
            item["p_sign_test"] = None if p is None else p["p_sign_test"]
            item["p_objects"] = None if p is None else p.get("p_objects")
            item["sign_test_met"] = p is not None and item["p_objects"] is not None and \
                p["a_only"] > p["b_only"] and item["p_objects"] < TARGET_SIGN_TEST_P
        out.append(item)
    return out

"""Success by grasp rank: does the model's quality order carry information?

The paper scores the five best grasps together. Split by rank, the same
trials say whether rank 1 really holds more often than rank 5 (if not, the
predicted quality does not order grasps by outcome), and "any rank held" per
view (object x modulus) is what a robot that may retry with the next grasp
would reach. Only the main experiment with the correct stiffness input counts.
"""
from __future__ import annotations

import csv
import io

from defgg_ros.evaluation.tables import Cell, is_graded, is_main_correct_input

ANY_RANK = "any"


def rank_cells(records, task: str, sets, models, n_ranks: int, views_per_set: dict) -> dict:
    """{(set, model, rank or ANY_RANK): Cell}; ranks 0-based, each cell expects one trial per view.

    The ANY_RANK cell counts a view as graded once one of its ranks is graded and
    as a success if any graded rank held; its expected count is the views.
    """
    cells = {(s, m, k): Cell(expected=views_per_set.get(s, 0))
             for s in sets for m in models for k in [*range(n_ranks), ANY_RANK]}
    views = {}
    for r in records:
        if r["task"] != task or not is_main_correct_input(r) or r.get("rank") is None:
            continue
        cell = cells.get((r["object_set"], r["model"], int(r["rank"])))
        if cell is None:
            continue
        cell.add(r)
        views.setdefault((r["object_set"], r["model"], r["object"], r["youngs_modulus_pa"]), []).append(r)
    for (s, m, _obj, _e), recs in views.items():
        graded = [r for r in recs if is_graded(r)]
        if graded:
            cells[(s, m, ANY_RANK)].add({"success": any(bool(r["success"]) for r in graded)})
        elif all(r.get("status") == "no_grasp" for r in recs):
            cells[(s, m, ANY_RANK)].add({"status": "no_grasp"})
        else:
            cells[(s, m, ANY_RANK)].add({"success": None})
    return cells


def rank_markdown(cells: dict, task: str, sets, models, n_ranks: int, model_labels: dict) -> str:
    head = "| object set | model | " + " | ".join(f"rank {k + 1}" for k in range(n_ranks)) + " | any rank held |"
    lines = [f"**{task.capitalize()} task by grasp rank** (all stiffnesses; rank 1 = the model's best grasp; "
             "\"any rank held\" = views (object × E) where at least one of the ranks run held)", "", head,
             "|---" * (n_ranks + 3) + "|"]
    for s in sets:
        for m in models:
            row = [cells[(s, m, k)].markdown() for k in [*range(n_ranks), ANY_RANK]]
            lines.append(f"| {s} | {model_labels.get(m, m)} | " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def rank_csv(cells: dict, task: str, sets, models, n_ranks: int) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["task", "object_set", "model", "rank", "success_pct", "successes", "graded", "sim_failed",
                "no_grasp", "expected_trials"])
    for s in sets:
        for m in models:
            for k in [*range(n_ranks), ANY_RANK]:
                c = cells[(s, m, k)]
                w.writerow([task, s, m, k + 1 if k != ANY_RANK else ANY_RANK,
                            "" if c.rate_pct is None else f"{c.rate_pct:.2f}", c.success, c.graded, c.sim_failed,
                            c.no_grasp, c.expected])
    return buf.getvalue()

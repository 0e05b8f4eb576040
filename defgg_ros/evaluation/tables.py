"""Results file -> the paper's tables (Markdown and CSV), with the trial counts behind every cell.

A cell's success rate is successes / graded trials; trials whose simulation
failed (explosion, time-out) are not grasp outcomes and are counted apart, as
are ranks for which the model proposed no grasp (fewer than the 5 asked for
fit on the object 10 px apart, see grasping.postprocess.find_peaks: there is
no 4th or 5th grasp to try).
Every cell also shows how many trials the full experiment would have, so a
partial run is never read as the full one.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass

from defgg_ros.evaluation.jobs import SENSITIVITY_ERRORS_PCT
from defgg_ros.evaluation.tasks import TASKS

ALL_STIFFNESSES = "all stiffnesses"


@dataclass
class Cell:
    graded: int = 0
    success: int = 0
    sim_failed: int = 0
    expected: int = 0
    field: str = "success"     # record field that holds the grasp outcome
    no_grasp: int = 0          # the model proposed fewer distinct grasps than asked: not a trial

    def add(self, rec: dict) -> None:
        if rec.get("status") == "no_grasp":
            self.no_grasp += 1
        elif rec.get(self.field) is None:
            self.sim_failed += 1
        else:
            self.graded += 1
            self.success += int(bool(rec[self.field]))

    @property
    def rate_pct(self) -> float | None:
        return None if self.graded == 0 else 100.0 * self.success / self.graded

    @property
    def done(self) -> int:
        return self.graded + self.sim_failed + self.no_grasp

    def markdown(self) -> str:
        extra = []
        if self.expected and self.done < self.expected:
            extra.append(f"{self.done} of {self.expected} run")
        if self.sim_failed:
            extra.append(f"{self.sim_failed} sim-failed")
        if self.no_grasp:
            extra.append(f"{self.no_grasp} no grasp")
        if self.graded == 0:
            return "– (" + "; ".join(extra or ["0 run"]) + ")"
        return f"{self.rate_pct:.1f} ({self.success}/{self.graded}" + "".join(f"; {e}" for e in extra) + ")"


def is_main_correct_input(r: dict) -> bool:
    """A trial of the main experiment with the true stiffness input (no sensitivity error)."""
    return r["experiment"] == "main" and float(r.get("input_error_pct") or 0.0) == 0.0


def is_graded(r: dict) -> bool:
    """A grasp outcome: the model proposed the grasp and its simulation finished (success True or False)."""
    return r.get("status") != "no_grasp" and r.get("success") is not None


def e_label(e_pa: float) -> str:
    mantissa, exp = f"{e_pa:.0e}".split("e")
    return f"{mantissa}e{int(exp)}"


def current(records, model_shas: dict) -> list:
    """Records of the given models' current weights only (older weights' trials stay in the file)."""
    return [r for r in records if model_shas.get(r.get("model")) == r.get("model_sha")]


def main_table(records, task: str, sets, models, moduli, expected_per_cell: dict, field: str = "success") -> dict:
    """{(row, set, model): Cell}; rows are moduli then ALL_STIFFNESSES.

    expected_per_cell[(set, e)] = trials the full experiment has per model in that row.
    """
    cells = {}
    for s in sets:
        for m in models:
            for e in moduli:
                cells[(e, s, m)] = Cell(expected=expected_per_cell.get((s, e), 0), field=field)
            cells[(ALL_STIFFNESSES, s, m)] = Cell(expected=sum(expected_per_cell.get((s, e), 0) for e in moduli),
                                                  field=field)
    for r in records:
        if r["experiment"] != "main" or r["task"] != task:
            continue
        for row in (r["youngs_modulus_pa"], ALL_STIFFNESSES):
            cell = cells.get((row, r["object_set"], r["model"]))
            if cell is not None:
                cell.add(r)
    return cells


def main_table_markdown(cells, task: str, sets, models, moduli, model_labels: dict, title: str = "") -> str:
    cols = [(s, m) for s in sets for m in models]
    head = "| E (Pa) | " + " | ".join(f"{s}: {model_labels.get(m, m)}" for s, m in cols) + " |"
    title = title or f"**{task.capitalize()} task**: success rate in % (successes/graded trials)"
    lines = [title, "", head,
             "|---" * (len(cols) + 1) + "|"]
    for row in list(moduli) + [ALL_STIFFNESSES]:
        label = e_label(row) if row != ALL_STIFFNESSES else f"**{ALL_STIFFNESSES}**"
        lines.append(f"| {label} | " + " | ".join(cells[(row, s, m)].markdown() for s, m in cols) + " |")
    return "\n".join(lines) + "\n"


def main_table_csv(cells, task: str, sets, models, moduli) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["task", "object_set", "model", "youngs_modulus_pa", "success_pct", "successes", "graded",
                "sim_failed", "no_grasp", "expected_trials"])
    for s in sets:
        for m in models:
            for row in list(moduli) + [ALL_STIFFNESSES]:
                c = cells[(row, s, m)]
                w.writerow([task, s, m, row if row == ALL_STIFFNESSES else f"{row:g}",
                            "" if c.rate_pct is None else f"{c.rate_pct:.2f}", c.success, c.graded, c.sim_failed,
                            c.no_grasp, c.expected])
    return buf.getvalue()


def sensitivity_cells(records, model: str, object_set: str, expected: int, errors=SENSITIVITY_ERRORS_PCT,
                      task: str = "shake", ranks=None) -> dict:
    """{error_pct: Cell} over all stiffnesses; 0 % comes from the main experiment.

    ranks: only these grasp ranks (0 = a view's best grasp); None takes every rank.
    """
    cells = {float(e): Cell(expected=expected) for e in errors}
    for r in records:
        if r["model"] != model or r["object_set"] != object_set or r["task"] != task:
            continue
        if ranks is not None and r.get("rank", 0) not in ranks:
            continue
        if r["experiment"] == "sensitivity" or is_main_correct_input(r):
            cell = cells.get(float(r["input_error_pct"]))
            if cell is not None:
                cell.add(r)
    return cells


def sensitivity_scopes(records, model: str, object_set: str, n_rows: int, n_best: int) -> dict:
    """{key: (column label, {error_pct: Cell})}: the n best grasps, then like-for-like columns.

    A budgeted run (--ranks) simulates one rank at a time, and the 0 % row comes
    from the main experiment, which may have every rank already; so the rows of
    the first column can differ in trials. Added then: the ranks finished at
    every error ("ranks"), and always each view's best grasp ("best").
    """
    scopes = {"all": (f"{n_best} best grasps", sensitivity_cells(records, model, object_set, n_rows * n_best))}
    if n_best == 1:
        return scopes
    per_rank = [sensitivity_cells(records, model, object_set, n_rows, ranks={r}) for r in range(n_best)]
    finished = 0
    while finished < n_best and all(c.done >= n_rows for c in per_rank[finished].values()):
        finished += 1
    if 1 < finished < n_best:
        scopes["ranks"] = (f"ranks 1–{finished}, run at every error",
                           sensitivity_cells(records, model, object_set, n_rows * finished, ranks=set(range(finished))))
    scopes["best"] = ("best grasp", per_rank[0])
    return scopes


def sensitivity_markdown(scopes: dict, model_label: str, object_set: str) -> str:
    lines = [f"**Sensitivity** ({model_label}, {object_set} set, shake task, all stiffnesses)", "",
             "| stiffness input error (%) | " + " | ".join(f"success, {label} (%)" for label, _ in scopes.values())
             + " |", "|---" * (1 + len(scopes)) + "|"]
    first = next(iter(scopes.values()))[1]
    for e in first:
        lines.append(f"| {e:+g} | " + " | ".join(cells[e].markdown() for _, cells in scopes.values()) + " |")
    done = {c.done for c in first.values()}
    if len(done) > 1 and len(scopes) > 1:
        lines += ["", f"The rows of the first column have run different numbers of trials ({min(done)}–{max(done)}); "
                      "compare rows within the other columns, which are like-for-like."]
    return "\n".join(lines) + "\n"


def sensitivity_csv(scopes: dict, model: str, object_set: str) -> str:
    """One row per grasp scope (see sensitivity_scopes) and error."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["model", "object_set", "grasps", "input_error_pct", "success_pct", "successes", "graded",
                "sim_failed", "expected_trials"])
    for label, cells in scopes.values():
        for e, c in cells.items():
            w.writerow([model, object_set, label, f"{e:g}", "" if c.rate_pct is None else f"{c.rate_pct:.2f}",
                        c.success, c.graded, c.sim_failed, c.expected])
    return buf.getvalue()


def multimaterial_rows(records, expected: int) -> list:
    """Rows (object, soft-part E, model, input, task, Cell, grasps on the soft part / planned grasps)."""
    groups = {}
    for r in records:
        if r["experiment"] != "multimaterial":
            continue
        key = (r["object"], r["youngs_modulus_pa"], r["model"], r["input"], r["task"])
        cell, on_soft = groups.setdefault(key, (Cell(expected=expected), [0, 0]))
        cell.add(r)
        if r.get("grasp"):
            on_soft[0] += int(r["grasp"].get("mask_label") == 2)
            on_soft[1] += 1
    return [(*k, c, tuple(s)) for k, (c, s) in sorted(groups.items(), key=lambda kv: str(kv[0]))]


def multimaterial_markdown(rows, model_labels: dict) -> str:
    lines = ["**Multi-material object** (part 0 rigid at 2e9 Pa; part 1 soft at the given E)", "",
             "| object | soft part E (Pa) | model | stiffness input | task | success (%) | grasps centred on the soft "
             "part |", "|---|---|---|---|---|---|---|"]
    for obj, e, model, inp, task, cell, (soft, total) in rows:
        inp_label = "correct per-part" if inp == "true" else "all rigid (2e9)" if inp.startswith("assume") else inp
        lines.append(f"| {obj} | {e_label(e)} | {model_labels.get(model, model)} | {inp_label} | {task} | "
                     f"{cell.markdown()} | {soft}/{total} |")
    return "\n".join(lines) + "\n"


def multimaterial_csv(rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["object", "soft_part_youngs_modulus_pa", "model", "input", "task", "success_pct", "successes",
                "graded", "sim_failed", "expected_trials", "grasps_on_soft_part", "grasps"])
    for obj, e, model, inp, task, c, (soft, total) in rows:
        w.writerow([obj, f"{e:g}", model, inp, task, "" if c.rate_pct is None else f"{c.rate_pct:.2f}", c.success,
                    c.graded, c.sim_failed, c.expected, soft, total])
    return buf.getvalue()


def tasks_in(records) -> list:
    return [t for t in TASKS if any(r["task"] == t for r in records)]

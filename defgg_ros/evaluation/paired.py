"""Can the trials tell the two models apart? A paired comparison per task and object set.

Both models are run on the same objects, moduli and poses, so their trials pair
up by view and rank (object, E, rank). Only the discordant pairs (one model held,
the other did not) carry information about which model is better; the exact
sign test (McNemar's exact test) on them says whether the split could be chance.
The "margin needed" column answers the question a reader of a close table asks:
with as many discordant pairs as were seen, how many points apart would the
models have to be before the test reports p < 0.05?

Pairs of one view (its five ranks) share an object and a modulus, so they are
not independent draws: the "best grasp" row (one pair per view) is the cleaner
test; the "all ranks" row is reported because it is what the paper's tables sum.
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass

from defgg_ros.evaluation.tables import is_graded, is_main_correct_input

ALPHA = 0.05
Z_95 = 1.959964
BEST_GRASP = "best grasp"
ALL_RANKS = "all ranks"


@dataclass(frozen=True)
class Paired:
    """Counts of paired trials: A = the stiffness-aware model, B = the baseline."""
    both: int
    a_only: int
    b_only: int
    neither: int

    @property
    def pairs(self) -> int:
        return self.both + self.a_only + self.b_only + self.neither

    @property
    def discordant(self) -> int:
        return self.a_only + self.b_only

    @property
    def a_held_pct(self) -> float | None:
        return None if not self.pairs else 100.0 * (self.both + self.a_only) / self.pairs

    @property
    def b_held_pct(self) -> float | None:
        return None if not self.pairs else 100.0 * (self.both + self.b_only) / self.pairs

    @property
    def margin_pts(self) -> float | None:
        return None if not self.pairs else 100.0 * (self.a_only - self.b_only) / self.pairs

    def margin_ci_pts(self) -> tuple | None:
        """Wald 95 % interval of the paired difference of success rates, in points."""
        n = self.pairs
        if not n:
            return None
        d = (self.a_only - self.b_only) / n
        se = math.sqrt(max(self.discordant - (self.a_only - self.b_only) ** 2 / n, 0.0)) / n
        return 100.0 * (d - Z_95 * se), 100.0 * (d + Z_95 * se)

    @property
    def p_value(self) -> float | None:
        return None if not self.pairs else sign_test_p(self.a_only, self.b_only)

    @property
    def margin_needed_pts(self) -> float | None:
        """Smallest |margin| that reaches p < ALPHA with this many discordant pairs (None: none can)."""
        m = self.discordant
        for k in range(m // 2 + 1):   # k = the smaller side of the split
            if sign_test_p(m - k, k) >= ALPHA:
                return None if k == 0 else 100.0 * (m - 2 * (k - 1)) / self.pairs
        return None


def sign_test_p(wins: int, losses: int) -> float:
    """Exact two-sided sign test: P(a split at least this uneven | fair coin over wins + losses)."""
    m = wins + losses
    if m == 0:
        return 1.0
    tail = sum(math.comb(m, k) for k in range(min(wins, losses) + 1)) / 2.0**m
    return min(1.0, 2.0 * tail)


def count_pairs(pairs) -> Paired:
    """Paired counts of (A succeeded, B succeeded) tuples."""
    c = {"both": 0, "a_only": 0, "b_only": 0, "neither": 0}
    for a, b in pairs:
        c["both" if a and b else "a_only" if a else "b_only" if b else "neither"] += 1
    return Paired(**c)


def _count_pairs(outcome_a: dict, outcome_b: dict) -> Paired:
    """Paired counts over the keys both outcome maps ({pairing key: held?}) have."""
    counts = {"both": 0, "a_only": 0, "b_only": 0, "neither": 0}
    for key, a in outcome_a.items():
        if key not in outcome_b:
            continue
        b = outcome_b[key]
        counts["both" if a and b else "a_only" if a else "b_only" if b else "neither"] += 1
    return Paired(**counts)


def _view_rank(r: dict) -> tuple:
    return r["object"], float(r["youngs_modulus_pa"]), int(r.get("rank") or 0)


def paired_counts(records, task: str, object_set: str, model_a: str, model_b: str, best_only: bool) -> Paired:
    """Pair model_a's and model_b's graded main-experiment trials of one task and set by (object, E, rank)."""
    outcome = {model_a: {}, model_b: {}}
    for r in records:
        if (r["task"] != task or r["object_set"] != object_set or r["model"] not in (model_a, model_b)
                or not is_main_correct_input(r) or not is_graded(r)):
            continue
        if best_only and _view_rank(r)[2] != 0:
            continue
        outcome[r["model"]][_view_rank(r)] = bool(r["success"])
    return _count_pairs(outcome[model_a], outcome[model_b])


def sensitivity_pairs(records, model: str, object_set: str, task: str = "shake") -> list:
    """[(error_pct, Paired)]: A = the correct stiffness input, B = the input off by error_pct, same grasp rank.

    The paper's curve says a wrong input costs success (75.9 % at 0 %, 21-25 % at
    +-60 %); pairing each wrong-input trial with the correct-input trial of the
    same view and rank tests that drop trial by trial.
    """
    by_error = {}
    for r in records:
        if r["model"] != model or r["object_set"] != object_set or r["task"] != task or not is_graded(r):
            continue
        if r["experiment"] == "sensitivity" or is_main_correct_input(r):
            by_error.setdefault(float(r["input_error_pct"]), {})[_view_rank(r)] = bool(r["success"])
    correct = by_error.pop(0.0, {})
    rows = [(e, _count_pairs(correct, by_error[e])) for e in sorted(by_error)]
    return [(e, p) for e, p in rows if p.pairs]


def paired_rows(records, tasks, sets, model_a: str, model_b: str) -> list:
    """[(task, set, BEST_GRASP or ALL_RANKS, Paired)] for every task and set with at least one pair."""
    rows = []
    for task in tasks:
        for s in sets:
            for scope, best in ((BEST_GRASP, True), (ALL_RANKS, False)):
                p = paired_counts(records, task, s, model_a, model_b, best)
                if p.pairs:
                    rows.append((task, s, scope, p))
    return rows


def _fmt(x, spec="+.1f") -> str:
    return "–" if x is None else format(x, spec)


def _fmt_p(p) -> str:
    """Two decimals, three near the 0.05 bar (0.0507 must not read as 0.05)."""
    return _fmt(p, ".3f" if p is not None and 0.01 <= p < 0.1 else ".2f")


def paired_markdown(rows, label_a: str, label_b: str) -> str:
    lines = [f"**Paired comparison**: A = {label_a}, B = {label_b}; trials paired by object, modulus and rank; "
             "margin = A − B in points (Wald 95 % interval, pairs taken as independent: an object's views share its "
             "shape, so it is narrower than the bootstrap over objects of the seed table; read p); p = exact "
             "two-sided sign test on the discordant "
             f"pairs; \"margin needed\" = the smallest margin that would reach p < {ALPHA:g} with this many "
             "discordant pairs (\"none\": no split of so few can)", "",
             "| task | object set | grasps | pairs | both held | only A | only B | neither | margin (pts) | "
             "95 % interval | p | margin needed (pts) |", "|---" * 12 + "|"]
    for task, s, scope, p in rows:
        ci = p.margin_ci_pts()
        interval = f"{ci[0]:+.1f} … {ci[1]:+.1f}" if ci else "–"
        lines.append(f"| {task} | {s} | {scope} | {p.pairs} | {p.both} | {p.a_only} | {p.b_only} | {p.neither} | "
                     f"{_fmt(p.margin_pts)} | {interval} | {_fmt_p(p.p_value)} | "
                     f"{'none' if p.margin_needed_pts is None else format(p.margin_needed_pts, '.1f')} |")
    return "\n".join(lines) + "\n"


def sensitivity_paired_markdown(rows, model_label: str, object_set: str) -> str:
    lines = [f"**Does a wrong stiffness input cost grasps?** ({model_label}, {object_set} set, shake; each "
             "wrong-input trial paired with the correct-input trial of the same object, modulus and rank; "
             "margin = correct − wrong in points; p = exact two-sided sign test on the discordant pairs)", "",
             "| input error (%) | pairs | both held | only correct | only wrong | neither | margin (pts) | "
             "95 % interval | p |", "|---" * 9 + "|"]
    for e, p in rows:
        ci = p.margin_ci_pts()
        lines.append(f"| {e:+g} | {p.pairs} | {p.both} | {p.a_only} | {p.b_only} | {p.neither} | "
                     f"{_fmt(p.margin_pts)} | {ci[0]:+.1f} … {ci[1]:+.1f} | {_fmt_p(p.p_value)} |")
    if len(rows) > 1:   # many rows, many chances: chance alone puts one of ten rows under p = 0.05 four times in ten
        lines += ["", f"{len(rows)} error levels are tested, so a single row is significant at a family-wise "
                      f"{ALPHA:g} only with p < {ALPHA / len(rows):.3g} (Bonferroni)."]
    return "\n".join(lines) + "\n"


def paired_csv(rows, model_a: str, model_b: str) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["task", "object_set", "grasps", "model_a", "model_b", "pairs", "both", "a_only", "b_only",
                "neither", "margin_pts", "ci_low_pts", "ci_high_pts", "p_sign_test", "margin_needed_pts"])
    for task, s, scope, p in rows:
        ci = p.margin_ci_pts()
        w.writerow([task, s, scope, model_a, model_b, p.pairs, p.both, p.a_only, p.b_only, p.neither,
                    f"{p.margin_pts:.2f}", f"{ci[0]:.2f}", f"{ci[1]:.2f}", f"{p.p_value:.4f}",
                    "" if p.margin_needed_pts is None else f"{p.margin_needed_pts:.2f}"])
    return buf.getvalue()

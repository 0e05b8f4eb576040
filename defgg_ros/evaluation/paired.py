"""Can the trials tell the two models apart? A paired comparison per task and object set.

Both models are run on the same objects, moduli and poses, so their trials pair
up by view and rank (object, E, rank). Only the discordant pairs (one model held,
the other did not) carry information about which model is better; the exact
sign test (McNemar's exact test) on them says whether the split could be chance.
The "margin needed" column answers the question a reader of a close table asks:
with as many discordant pairs as were seen, how many points apart would the
models have to be before the test reports p < 0.05?

Pairs of one view (its five ranks) share an object and a modulus, and an object's
views share its shape, so pairs are not independent draws: a test on the pairs
overstates what they show (the adversarial shake's 479 pairs come from 24
objects). Every row therefore also gives the test with **objects** as the
independent units: an exact sign-flip test of the summed per-object net
(only A - only B; under no difference each object's net is as likely negative as
positive), and a 95 % bootstrap interval of the margin over objects. The issue's
"p < 0.05" target reads the objects' test.
"""
from __future__ import annotations

import csv
import io
import math
import random
from dataclasses import dataclass

from defgg_ros.evaluation.tables import is_graded, is_main_correct_input

ALPHA = 0.05
Z_95 = 1.959964
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
BEST_GRASP = "best grasp"
ALL_RANKS = "all ranks"


@dataclass(frozen=True)
class Paired:
    """Counts of paired trials: A = the stiffness-aware model, B = the baseline."""
    both: int
    a_only: int
    b_only: int
    neither: int
    objects: tuple = ()     # (object, a_only, b_only, pairs) per object: the independent units

    @property
    def object_p_value(self) -> float | None:
        """Exact two-sided sign-flip test over objects of the summed net (a_only - b_only); None without objects."""
        return None if not self.objects else sign_flip_p([a - b for _, a, b, _ in self.objects])

    def object_interval_pts(self, resamples: int = BOOTSTRAP_RESAMPLES) -> tuple | None:
        """95 % bootstrap interval of the margin (points) resampling objects; None with fewer than two objects."""
        if len(self.objects) < 2:
            return None

        def margin(drawn):
            pairs = sum(o[3] for o in drawn)
            return 100.0 * sum(o[1] - o[2] for o in drawn) / pairs if pairs else None
        return bootstrap_interval(list(self.objects), margin, resamples)

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


def sign_flip_p(nets) -> float:
    """Exact two-sided p of |sum of nets| under independent random signs of each unit's net (its size fixed): the
    permutation distribution, counted exactly by summing over the units (integer nets)."""
    sizes = [abs(int(n)) for n in nets if n]
    observed = abs(sum(int(n) for n in nets))
    ways = {0: 1}
    for size in sizes:
        step = {}
        for total, count in ways.items():
            for signed in (total + size, total - size):
                step[signed] = step.get(signed, 0) + count
        ways = step
    return sum(c for total, c in ways.items() if abs(total) >= observed) / 2.0 ** len(sizes)


def bootstrap_interval(units: list, statistic, resamples: int = BOOTSTRAP_RESAMPLES,
                       seed: int = BOOTSTRAP_SEED) -> tuple | None:
    """95 % percentile interval of statistic(units drawn with replacement) (draws giving None are left out)."""
    if not units or resamples <= 0:
        return None
    rng = random.Random(seed)
    draws = sorted(m for m in (statistic(rng.choices(units, k=len(units))) for _ in range(resamples))
                   if m is not None)
    if not draws:
        return None
    return draws[int(0.025 * (len(draws) - 1))], draws[int(round(0.975 * (len(draws) - 1)))]


def object_nets(by_object: dict) -> tuple:
    """Per object (sorted by name) of {object: [(a held, b held)]}: pairs only A held minus pairs only B held."""
    return tuple(sum(a and not b for a, b in pairs) - sum(b and not a for a, b in pairs)
                 for _, pairs in sorted(by_object.items()))


def count_pairs(pairs) -> Paired:
    """Paired counts of (A succeeded, B succeeded) tuples."""
    c = {"both": 0, "a_only": 0, "b_only": 0, "neither": 0}
    for a, b in pairs:
        c["both" if a and b else "a_only" if a else "b_only" if b else "neither"] += 1
    return Paired(**c)


def _count_pairs(outcome_a: dict, outcome_b: dict) -> Paired:
    """Paired counts over the keys both outcome maps ({(object, ...): held?}) have, with the per-object counts."""
    counts = {"both": 0, "a_only": 0, "b_only": 0, "neither": 0}
    per_object = {}
    for key, a in outcome_a.items():
        if key not in outcome_b:
            continue
        b = outcome_b[key]
        kind = "both" if a and b else "a_only" if a else "b_only" if b else "neither"
        counts[kind] += 1
        obj = per_object.setdefault(key[0], [0, 0, 0])
        obj[0] += kind == "a_only"
        obj[1] += kind == "b_only"
        obj[2] += 1
    return Paired(**counts, objects=tuple((o, *c) for o, c in sorted(per_object.items())))


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
             "margin = A − B in points. Objects are the independent units (a view's ranks share its object and "
             "modulus, an object's views its shape): the 95 % interval is a bootstrap over objects and "
             "**p (objects)** an exact sign-flip test of the per-object nets (only A − only B); p (pairs) = exact "
             "two-sided sign test on the discordant pairs as if they were independent (smaller than it should be); "
             f"\"margin needed\" = the smallest margin that would reach p (pairs) < {ALPHA:g} with this many "
             "discordant pairs (\"none\": no split of so few can)", "",
             "| task | object set | grasps | pairs | objects | both held | only A | only B | neither | margin (pts) | "
             "95 % over objects | p (objects) | p (pairs) | margin needed (pts) |", "|---" * 14 + "|"]
    for task, s, scope, p in rows:
        ci = p.object_interval_pts()
        interval = f"{ci[0]:+.1f} … {ci[1]:+.1f}" if ci else "–"
        lines.append(f"| {task} | {s} | {scope} | {p.pairs} | {len(p.objects)} | {p.both} | {p.a_only} | {p.b_only} "
                     f"| {p.neither} | {_fmt(p.margin_pts)} | {interval} | {_fmt_p(p.object_p_value)} | "
                     f"{_fmt_p(p.p_value)} | "
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
    w.writerow(["task", "object_set", "grasps", "model_a", "model_b", "pairs", "objects", "both", "a_only",
                "b_only", "neither", "margin_pts", "ci_objects_low_pts", "ci_objects_high_pts", "p_objects",
                "p_sign_test", "wald_ci_low_pts", "wald_ci_high_pts", "margin_needed_pts"])
    for task, s, scope, p in rows:
        ci, wald = p.object_interval_pts(), p.margin_ci_pts()
        w.writerow([task, s, scope, model_a, model_b, p.pairs, len(p.objects), p.both, p.a_only, p.b_only,
                    p.neither, f"{p.margin_pts:.2f}", "" if ci is None else f"{ci[0]:.2f}",
                    "" if ci is None else f"{ci[1]:.2f}", f"{p.object_p_value:.4f}", f"{p.p_value:.4f}",
                    f"{wald[0]:.2f}", f"{wald[1]:.2f}",
                    "" if p.margin_needed_pts is None else f"{p.margin_needed_pts:.2f}"])
    return buf.getvalue()

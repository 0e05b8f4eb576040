"""How much of the stiffness input's margin is the training seed? (issue 49, the seed study)

Each seed's pair (the stiffness-aware model and the depth-only one, same data, schedule and split) is evaluated
in its own folder; within a folder the two models' trials pair up by (object, E, rank) as in `paired`. Per seed
and object set this reports the paired margin (points) and its sign test; over the seeds, the mean margin with a
95 % bootstrap interval over **objects** (an object's trials are not independent draws: they share its shape, so
objects are what the interval resamples), and two tests pooled over the seeds: the exact sign-flip test over
objects of each object's net (only A - only B, summed over the seeds; objects the independent units, as in
`paired`), and the sign test on the discordant pairs, which counts every pair as independent although a view's
ranks share an object and every seed is evaluated on the same views (it is smaller than it should be). The
interval holds the seeds fixed (the spread between seeds is in the per-seed rows, not in it).

While the seeds' evaluations run, they cover different views: every seed is then compared on the views
(object, E, rank) that every seed with trials has (`matched`), so a partial seed is not set against the
shipped seed's five ranks (a rank-1 grasp succeeds more often than a rank-5 one).
"""
from __future__ import annotations

from dataclasses import dataclass

from defgg_ros.evaluation.paired import (
    Paired,
    bootstrap_interval,
    count_pairs,
    object_nets,
    sign_flip_p,
    sign_test_p,
)
from defgg_ros.evaluation.tables import is_graded, is_main_correct_input

BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0


@dataclass(frozen=True)
class SeedRow:
    seed: str
    counts: Paired


@dataclass(frozen=True)
class SeedSummary:
    object_set: str
    rows: tuple                 # SeedRow per seed, in the order given
    mean_margin_pts: float | None
    interval_pts: tuple | None  # 95 % bootstrap over objects of the mean margin
    pooled: Paired              # discordant pairs summed over the seeds
    objects: int
    matched_views: int | None = None   # compared on this many views that every seed with trials has
    object_nets: tuple = ()            # per object: only A - only B summed over the seeds

    @property
    def pooled_p(self) -> float:
        return sign_test_p(self.pooled.a_only, self.pooled.b_only)

    @property
    def pooled_object_p(self) -> float:
        return sign_flip_p(self.object_nets)


def view_outcomes(records, task: str, object_set: str, model_a: str, model_b: str) -> dict:
    """(object, E, rank) -> (a held, b held) over the views both models have a graded main trial for."""
    outcome = {model_a: {}, model_b: {}}
    for r in records:
        if (r["task"] != task or r["object_set"] != object_set or r["model"] not in outcome
                or not is_main_correct_input(r) or not is_graded(r)):
            continue
        key = (r["object"], float(r["youngs_modulus_pa"]), int(r.get("rank") or 0))
        outcome[r["model"]][key] = bool(r["success"])
    return {key: (a, outcome[model_b][key]) for key, a in outcome[model_a].items() if key in outcome[model_b]}


def object_outcomes(views: dict, keep=None) -> dict:
    """object -> [(a held, b held)] of views ((object, E, rank) -> pair), only the keys in `keep` if given."""
    by_object = {}
    for key, pair in sorted(views.items()):
        if keep is None or key in keep:
            by_object.setdefault(key[0], []).append(pair)
    return by_object


def _counts(pairs) -> Paired:
    return count_pairs(pairs)


def _mean_margin(per_seed_objects: list, objects: list) -> float | None:
    """Mean over the seeds of each seed's paired margin over `objects` (an object drawn twice counts twice)."""
    margins = []
    for by_object in per_seed_objects:
        pairs = [p for o in objects for p in by_object.get(o, [])]
        if pairs:
            margins.append(_counts(pairs).margin_pts)
    return sum(margins) / len(margins) if margins else None


def summarise(seed_records: dict, object_set: str, task: str = "shake", model_a: str = "defgg_cnn",
              model_b: str = "ggcnn_depth_only", resamples: int = BOOTSTRAP_RESAMPLES,
              matched: bool = True) -> SeedSummary:
    """seed_records: {seed label: that seed's trial records}. matched: only the views every seed with trials
    has (module docstring); False: each seed's own views."""
    views = {seed: view_outcomes(recs, task, object_set, model_a, model_b) for seed, recs in seed_records.items()}
    present = [set(v) for v in views.values() if v]
    keep = set.intersection(*present) if matched and present else None
    per_seed = {seed: object_outcomes(v, keep) for seed, v in views.items()}
    rows = tuple(SeedRow(seed, _counts([p for pairs in objs.values() for p in pairs]))
                 for seed, objs in per_seed.items())
    objects = sorted(set().union(*per_seed.values())) if per_seed else []
    pooled = Paired(*(sum(getattr(r.counts, f) for r in rows) for f in ("both", "a_only", "b_only", "neither")))
    mean = _mean_margin(list(per_seed.values()), objects)
    interval = bootstrap_interval(objects, lambda drawn: _mean_margin(list(per_seed.values()), drawn), resamples,
                                  BOOTSTRAP_SEED)
    nets = object_nets({o: [p for by_object in per_seed.values() for p in by_object.get(o, [])] for o in objects})
    return SeedSummary(object_set, rows, mean, interval, pooled, len(objects), None if keep is None else len(keep),
                       nets)


def _held(c: Paired) -> str:
    """Success rates of the two models over the same pairs (the target's "common >= 75 %" reads here)."""
    return f"{c.a_held_pct:.1f} % / {c.b_held_pct:.1f} %" if c.pairs else ""


def seeds_markdown(summaries) -> str:
    """One table: a row per seed and object set, then the mean, its interval and the pooled test."""
    lines = ["| object set | seed | pairs | held: with stiffness / depth only | with stiffness only | depth only only "
             "| margin (pts) | sign test p |",
             "|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        for row in s.rows:
            c = row.counts
            margin = "" if c.margin_pts is None else f"{c.margin_pts:+.1f}"
            lines.append(f"| {s.object_set} | {row.seed} | {c.pairs} | {_held(c)} | {c.a_only} | {c.b_only} | "
                         f"{margin} | {c.p_value:.3g} |" if c.pairs
                         else f"| {s.object_set} | {row.seed} | 0 | | | | | |")
        mean = "" if s.mean_margin_pts is None else f"{s.mean_margin_pts:+.1f}"
        interval = "" if s.interval_pts is None else f" (95 % over {s.objects} objects: {s.interval_pts[0]:+.1f} … " \
                                                       f"{s.interval_pts[1]:+.1f})"
        seeds = sum(1 for row in s.rows if row.counts.pairs)     # the mean is over the seeds with pairs
        lines.append(f"| {s.object_set} | **mean of {seeds} seeds** | {s.pooled.pairs} | {_held(s.pooled)} | "
                     f"{s.pooled.a_only} | {s.pooled.b_only} | {mean}{interval} | objects {s.pooled_object_p:.3g}; "
                     f"pairs {s.pooled_p:.3g} (pooled) |")
    notes = [f"{s.object_set}: every seed on the same {s.matched_views} views (object, E, rank) that each seed with "
             "trials has" for s in summaries if s.matched_views is not None]
    return "\n".join(lines) + "\n" + ("\n" + "; ".join(notes) + ".\n" if notes else "")

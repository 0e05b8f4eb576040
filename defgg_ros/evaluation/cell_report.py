"""The cell experiment's report (issue 49 item 3): per-object success per stiffness input, the paper's figure,
and the paired comparison of the correct input against each wrong one.

Pairs: pick i of an object meets the same pose under every case, so "correct" and "rigid" (or "soft") pair up by
(object, pick). Only the discordant pairs (one case picked it, the other not) say which input is better; the
exact sign test on them is McNemar's exact test, which takes the picks as independent. An object's picks share
its shape, so objects are the independent units: p (objects) is the exact sign-flip test of each object's net
(A only - B only), and the margin's 95 % interval a bootstrap over objects, resampling objects with replacement
and pooling their pairs. With fewer than MIN_OBJECTS_WITH_A_DIFFERENCE objects where the inputs differed at all,
the bootstrap can only replay those few objects' margins (one object's 1 vs 1 gave [+0.0, +0.0]): no interval.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from pathlib import Path

from defgg_ros.atomic import read_jsonl, write_text_atomic
from defgg_ros.evaluation.paired import Paired, count_pairs, object_nets, sign_flip_p, sign_test_p

CASES = ("correct", "rigid", "soft")
MEASURED = "measured"
# The paper's real robot closes the same gripper on every grasp, so its stiffness input only changes which grasp
# the network chooses. Our cell also closes with the labels' force and speed for the input modulus (FOS(E)), so a
# wrong input changes both. A grasp-only case plans with the wrong input and closes as for the object's true
# modulus: the grasp channel alone; "rigid" vs "rigid_grasp" is then the force channel alone (same plan input).
GRASP_ONLY_SUFFIX = "_grasp"
GRASP_ONLY_CASES = ("rigid_grasp", "soft_grasp")
RECORDS_NAME = "records.jsonl"
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
FIGURE_NAME, GRASP_FIGURE_NAME, REPORT_NAME = "per_object.png", "grasp_channel.png", "report.md"
# Two plans chose the same grasp when their centres are this close and their angles this near (modulo pi).
SAME_GRASP_POSITION_M, SAME_GRASP_ANGLE_RAD = 0.005, math.radians(10.0)
# The squeeze table pools the objects below this modulus (soft and 2e6 Pa: a number expected) apart from the
# rigid ones (2e9 Pa: 'rigid' expected).
RIGID_CLASS_PA = 1e9
REPEATABLE_SPREAD = 1.2     # issue 49 item 4: estimates repeatable to 20 %


def plain_case(case: str) -> str:
    """The case a grasp-only case plans like ("rigid_grasp" -> "rigid"); any other case is its own."""
    return case[:-len(GRASP_ONLY_SUFFIX)] if case in GRASP_ONLY_CASES else case


def with_plain_substitutes(records) -> list:
    """The records plus, once a grasp-only run exists, the plain picks that stand for grasp-only ones: where the
    wrong input is the object's own modulus (rigid on a 2e9 Pa object, soft on a 2e4 Pa one) the grasp-only case
    is the plain case (same plan, same grip) and was not run again."""
    if not any(r.get("case") in GRASP_ONLY_CASES for r in records):
        return list(records)
    stand_ins, recorded = [], outcomes(records)
    for r in recorded.values():
        case = f"{r['case']}{GRASP_ONLY_SUFFIX}"
        key = f"{r['object']}|{case}|{r['pick']}"
        if (case in GRASP_ONLY_CASES and r.get("input_youngs_modulus_pa") == r.get("youngs_modulus_pa")
                and key not in recorded):   # a pick that ran is never replaced by a copy
            stand_ins.append({**r, "case": case, "key": key, "stands_in_for": r["key"]})
    return list(records) + stand_ins


def records_files(out: Path) -> list:
    """OUT/records.jsonl and any other run's records beside it (records_<name>.jsonl: the measured case)."""
    return sorted(Path(out).glob("records*.jsonl"))


def read_records(out: Path) -> list:
    """Every record of a run's folder (records*.jsonl); [] when it has none."""
    return [r for path in records_files(out) for r in read_jsonl(path)]


def outcomes(records) -> dict:
    """key -> the pick's record with an outcome (the last one if a key was recorded twice)."""
    return {r["key"]: r for r in records if not r.get("cell_error")}


def success_table(records) -> dict:
    """object -> case -> [successes, picks] over the picks with an outcome."""
    table = {}
    for r in outcomes(records).values():
        cell = table.setdefault(r["object"], {}).setdefault(r["case"], [0, 0])
        cell[0] += bool(r["success"])
        cell[1] += 1
    return table


def complete_totals(records, cases) -> tuple:
    """({case: [successes, picks]}, number of sets) over the (object, pick) sets that have an outcome in every one
    of `cases`: the average a partial run can show without mixing objects that only some cases reached."""
    by_set = {}
    for r in outcomes(records).values():
        by_set.setdefault((r["object"], r["pick"]), {})[r["case"]] = bool(r["success"])
    complete = [s for s in by_set.values() if all(c in s for c in cases)]
    return {c: [sum(s[c] for s in complete), len(complete)] for c in cases}, len(complete)


def case_pairs(records, case_a: str, case_b: str) -> list:
    """[(a record, b record)] of the picks (object, pick) both cases have an outcome for, in key order. A pick is
    not paired with its own stand-in (with_plain_substitutes): a wrong input against its grasp-only case where the
    wrong input is the object's own modulus is one pick, not two, and would count as a pair that cannot differ."""
    by_key = {(r["object"], r["pick"], r["case"]): r for r in outcomes(records).values()}
    pairs = []
    for (name, pick, case), a in sorted(by_key.items(), key=lambda item: item[0]):
        b = by_key.get((name, pick, case_b))
        if case == case_a and b is not None and b.get("stands_in_for") != a["key"] and same_body_and_weights(a, b):
            pairs.append((a, b))
    return pairs


def same_body_and_weights(a: dict, b: dict) -> bool:
    """False when both picks record the object body's or the weights' hash and they differ (records before
    2026-12-01 carry none: their pairs are taken as they are; cell_experiment.md says what that cost)."""
    return all(a.get(f) is None or b.get(f) is None or a[f] == b[f] for f in ("mesh_sha256", "model_sha256"))


def paired_by_object(records, case_a: str, case_b: str) -> dict:
    """object -> [(a succeeded, b succeeded)] over case_pairs."""
    out = {}
    for a, b in case_pairs(records, case_a, case_b):
        out.setdefault(a["object"], []).append((bool(a["success"]), bool(b["success"])))
    return out


MIN_OBJECTS_WITH_A_DIFFERENCE = 5


def bootstrap_margin_ci(by_object: dict, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED):
    """95 % percentile interval (points) of the pooled paired margin, resampling objects; None without pairs or
    with fewer than MIN_OBJECTS_WITH_A_DIFFERENCE objects that have a discordant pair."""
    names = sorted(n for n, pairs in by_object.items() if pairs)
    differing = sum(1 for n in names if any(a != b for a, b in by_object[n]))
    if not names or differing < MIN_OBJECTS_WITH_A_DIFFERENCE:
        return None
    rng = random.Random(seed)
    margins = []
    for _ in range(resamples):
        drawn = [rng.choice(names) for _ in names]
        margins.append(count_pairs([p for n in drawn for p in by_object[n]]).margin_pts)
    margins.sort()
    return margins[int(0.025 * (resamples - 1))], margins[int(round(0.975 * (resamples - 1)))]


@dataclass(frozen=True)
class Comparison:
    case_a: str
    case_b: str
    counts: Paired
    interval_pts: tuple | None
    objects: int
    nets: tuple = ()            # per object: A only - B only

    @property
    def p_value(self) -> float:
        return sign_test_p(self.counts.a_only, self.counts.b_only)

    @property
    def object_p_value(self) -> float:
        return sign_flip_p(self.nets)


def compare(records, case_a: str, case_b: str, only=None) -> Comparison:
    """case_a vs case_b over every object (or the names in `only`)."""
    by_object = {n: p for n, p in paired_by_object(records, case_a, case_b).items() if only is None or n in only}
    pairs = [p for ps in by_object.values() for p in ps]
    return Comparison(case_a, case_b, count_pairs(pairs), bootstrap_margin_ci(by_object), len(by_object),
                      object_nets(by_object))


def _pct(cell) -> str:
    return "–" if not cell or not cell[1] else f"{100 * cell[0] / cell[1]:.0f} % ({cell[0]}/{cell[1]})"


def _ci(interval) -> str:
    return "–" if interval is None else f"[{interval[0]:+.1f}, {interval[1]:+.1f}]"


def per_object_figure(table: dict, objects, path: Path, cases=CASES, totals=None) -> None:
    """The paper's figure: success rate per object, one bar per stiffness input (labelled successes/picks), the
    average over the complete pick sets (`totals`, from complete_totals) in the last column."""
    # matplotlib: +0.3 CPU-s at import (0.44 vs 0.17 s measured), so only here, for the figure
    from defgg_ros.evaluation.figures import _save, plt

    names = [o.name for o in objects if o.name in table]
    totals, sets = totals or ({c: [0, 0] for c in cases}, 0)
    columns = names + ["average"]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.62 * len(columns) * len(cases) / 1.5), 3.8))
    width = 0.8 / len(cases)
    labels = {"correct": "correct E", "rigid": "all assumed rigid", "soft": "all assumed soft",
              MEASURED: "measured E (squeeze)", "rigid_grasp": "rigid, gripped as true E",
              "soft_grasp": "soft, gripped as true E"}
    for k, case in enumerate(cases):
        cells = [table[name].get(case, [0, 0]) for name in names] + [totals[case]]
        xs = [i + (k - (len(cases) - 1) / 2) * width for i in range(len(columns))]
        rates = [100.0 * s / n if n else float("nan") for s, n in cells]
        ax.bar(xs, rates, width, label=labels.get(case, case))
        for x, rate, (s, n) in zip(xs, rates, cells):
            if n:   # a 0 % bar is invisible: its count says it ran
                ax.text(x, rate + 1.5, f"{s}/{n}", ha="center", va="bottom", fontsize=5, rotation=90)
    ax.set_xticks(range(len(columns)))
    number = {o.name: i + 1 for i, o in enumerate(objects)}     # the report table's numbers
    ax.set_xticklabels([f"{number[n]}\n{n.replace('common_', '').replace('egad_test_', 'egad ')}" if n != "average"
                        else f"avg\n({sets} complete)" for n in columns], fontsize=7, rotation=60)
    ax.set_ylabel("grasp success rate per object [%]")
    ax.set_ylim(0, 112)
    ax.grid(True, axis="y", linestyle="--", alpha=0.5)
    ax.legend(fontsize=8, ncol=len(cases), loc="upper center", bbox_to_anchor=(0.5, 1.18))
    _save(fig, path)


def comparisons(cases) -> list:
    """(A, B) pairs to compare: correct against every other input; measured against the two wrong ones; a wrong
    input against its grasp-only case (the same plan input, only the grip differs: the force channel)."""
    out = [("correct", c) for c in cases if c != "correct"]
    if MEASURED in cases:
        out += [(MEASURED, c) for c in ("rigid", "soft") if c in cases]
    out += [(plain_case(c), c) for c in GRASP_ONLY_CASES if c in cases and plain_case(c) in cases]
    return out


def _comparison_rows(records, objects, cases) -> list:
    soft = {o.name for o in objects if o.soft}
    stiff = {o.name for o in objects if not o.soft}
    rows = []
    for case_a, case_b in comparisons(cases):
        for scope, only in (("all", None), ("soft objects", soft), ("stiff objects", stiff)):
            c = compare(records, case_a, case_b, only)
            margin = "–" if c.counts.margin_pts is None else f"{c.counts.margin_pts:+.1f}"
            rows.append(f"| {case_a} vs {case_b} | {scope} | {c.objects} | {c.counts.pairs} | {c.counts.a_only} / "
                        f"{c.counts.b_only} | {margin} | {_ci(c.interval_pts)} | {c.object_p_value:.3g} | "
                        f"{c.p_value:.3g} |")
    return rows


def same_grasp(a: dict, b: dict, position_m: float = SAME_GRASP_POSITION_M,
               angle_rad: float = SAME_GRASP_ANGLE_RAD) -> bool:
    """Did two picks' plans choose the same grasp (centre within position_m, angle within angle_rad, modulo pi)?"""
    ga, gb = a.get("grasp"), b.get("grasp")
    if not ga or not gb:
        return False
    d_angle = abs((ga["angle_rad"] - gb["angle_rad"] + math.pi / 2) % math.pi - math.pi / 2)
    return math.hypot(ga["x_m"] - gb["x_m"], ga["y_m"] - gb["y_m"]) <= position_m and d_angle <= angle_rad


def rerun_lines(earlier, rerun) -> list:
    """A rerun of picks against an earlier run (the same keys: object, case, pick at the same seeded pose): how
    many ended the same way and chose the same grasp, and each pick that ended otherwise."""
    before, after = outcomes(earlier), outcomes(rerun)
    keys = sorted(set(before) & set(after))
    if not keys:
        return ["no pick has an outcome in both runs"]
    same = [k for k in keys if bool(before[k]["success"]) == bool(after[k]["success"])]
    grasp = sum(same_grasp(before[k], after[k]) for k in keys)
    lines = [f"the same outcome in {len(same)} of {len(keys)} picks run in both; the same grasp in {grasp} of "
             f"{len(keys)}"]
    for k in keys:
        if k not in same:
            lines.append(f"  {k}: {'held' if before[k]['success'] else 'missed'} -> "
                         f"{'held' if after[k]['success'] else 'missed'}"
                         f"{' (the same grasp)' if same_grasp(before[k], after[k]) else ' (another grasp)'}"
                         f"{': ' + after[k]['failure_reason'][:80] if after[k].get('failure_reason') else ''}")
    return lines


def channel_rows(records, cases) -> list:
    """Through which channel an input changed the outcome: of the discordant pairs, how many had the same grasp
    (then only the closing force, finger_force_n from the modulus, or chance differed) and how many another."""
    rows = []
    for case_a, case_b in comparisons(cases):
        counts = {"same": [0, 0, 0], "other": [0, 0, 0]}     # [pairs, a only, b only]
        for a, b in case_pairs(records, case_a, case_b):
            c = counts["same" if same_grasp(a, b) else "other"]
            c[0] += 1
            c[1] += bool(a["success"]) and not b["success"]
            c[2] += bool(b["success"]) and not a["success"]
        rows.append(f"| {case_a} vs {case_b} | {counts['same'][0]} | {counts['same'][1]} / {counts['same'][2]} | "
                    f"{counts['other'][0]} | {counts['other'][1]} / {counts['other'][2]} |")
    return rows


def repeat_pairs(records) -> list:
    """Pairs of picks that ran the same input at the same pose: correct with rigid on a 2e9 Pa object, correct
    with soft on a 2e4 Pa one (the paper's design has them too). What differs between the two is the cell's
    run-to-run noise alone (wall-clock threads, a fresh cell each). Stand-ins (copies) are not repeats."""
    by_key = {(r["object"], r["pick"], r["case"]): r for r in outcomes(records).values() if "stands_in_for" not in r}
    pairs = []
    for (name, pick, case), a in sorted(by_key.items()):
        if case != "correct":
            continue
        for other in ("rigid", "soft"):
            b = by_key.get((name, pick, other))
            if b is not None and b.get("input_youngs_modulus_pa") == a.get("input_youngs_modulus_pa"):
                pairs.append((a, b))
    return pairs


def repeat_line(records) -> str:
    """One sentence: how often the same input at the same pose ended the same way."""
    pairs = repeat_pairs(records)
    if not pairs:
        return ""
    agree = sum(bool(a["success"]) == bool(b["success"]) for a, b in pairs)
    same = sum(same_grasp(a, b) for a, b in pairs)
    return (f"Run-to-run noise (the same input at the same pose, twice: correct and rigid on the 2e9 Pa objects, "
            f"correct and soft on the 2e4 Pa ones): {agree} of {len(pairs)} pairs ended the same way "
            f"({len(pairs) - agree} discordant); the two plans chose the same grasp in {same} of {len(pairs)}.")


# The squeeze's laws in the report's column order (docs/squeeze.md), with the columns' names.
SQUEEZE_LAWS = (("flat", "flat law"), ("hertz", "point law"), ("hertz-line", "line law"), ("section", "section law"),
                ("unrecorded", "point or flat law, not recorded"))


def squeeze_law(squeeze: dict) -> str:
    """The law a squeeze's estimate used: recorded as contact_law since the result carries it; before, read off
    the executor's grasp for the squeeze: no contact radii, the flat law; no line lengths on record (a build with
    Hertz's point law at every curved pad), the point law; a line length > 0, the line law. The first measured
    picks kept no grasp: "unrecorded" (the point law at curved pads, the flat law at flat ones). Records made
    between the section law and its recording (results/cell_measured_section) cannot tell it from the others."""
    if squeeze.get("contact_law"):
        return squeeze["contact_law"]
    grasp = squeeze.get("grasp")
    if grasp is None:
        return "unrecorded"
    if not grasp.get("contact_radii_m"):
        return "flat"
    return "hertz-line" if any(v > 0 for v in grasp.get("contact_line_lengths_m", ())) else "hertz"


def squeeze_laws_present(records) -> list:
    """The (law, column name) of SQUEEZE_LAWS that some successful squeeze of the records used, in that order."""
    used = {squeeze_law(r["squeeze"]) for r in outcomes(records).values()
            if r.get("squeeze") and r["squeeze"]["success"]}
    return [(law, name) for law, name in SQUEEZE_LAWS if law in used]


def _squeezes(records, name: str) -> list:
    """The object's successful squeezes (measured case, one per pick with an outcome)."""
    return [r["squeeze"] for r in outcomes(records).values()
            if r["object"] == name and r.get("squeeze") and r["squeeze"]["success"]]


def _estimate_counts(found: list, true_pa: float) -> list:
    """[within x3, called rigid, n] of a set of squeezes."""
    within = sum(1 / 3 <= s["measured_youngs_modulus_pa"] / true_pa <= 3 and not s["rigid"] for s in found)
    return [within, sum(bool(s["rigid"]) for s in found), len(found)]


def _counts_cell(counts: list) -> str:
    return " / ".join(map(str, counts)) if counts[2] else "-"


def estimate_spread(found: list) -> float | None:
    """max / min of an object's estimates read as numbers (rigid verdicts left out): the squeeze's repeatability
    over its picks (each pick its own pose and grasp; issue 49 item 4 asks for 20 %, i.e. <= 1.2); None below two."""
    numbers = [s["measured_youngs_modulus_pa"] for s in found if not s["rigid"]]
    return max(numbers) / min(numbers) if len(numbers) >= 2 else None


def squeeze_rows(records, objects, laws) -> list:
    """The measured case's estimates per object: median estimate, its ratio to the true modulus, the spread over
    its picks (estimate_spread), how many within a factor 3 (issue 49 item 4's target) or called rigid; then the
    same split by the law each estimate used (squeeze_law; `laws`: the columns, squeeze_laws_present), and those
    pooled over the soft objects and over the rigid ones (with how many objects' spreads are within 20 %)."""
    rows, pooled, spreads = [], {}, {True: [], False: []}
    for obj in objects:
        found = _squeezes(records, obj.name)
        if not found:
            continue
        true_pa = obj.youngs_modulus_pa
        estimates = sorted(s["measured_youngs_modulus_pa"] for s in found)
        median = estimates[len(estimates) // 2]
        within, rigid, _ = _estimate_counts(found, true_pa)
        spread = estimate_spread(found)
        if spread is not None:
            spreads[true_pa < RIGID_CLASS_PA].append(spread)
        by_law = []
        for law, _ in laws:
            counts = _estimate_counts([s for s in found if squeeze_law(s) == law], true_pa)
            key = (true_pa < RIGID_CLASS_PA, law)
            pooled[key] = [a + b for a, b in zip(pooled.get(key, [0, 0, 0]), counts)]
            by_law.append(_counts_cell(counts))
        spread_cell = "-" if spread is None else f"{spread:.2f}"
        rows.append(f"| {obj.name} | {true_pa:.0e} | {median:.2g} | {median / true_pa:.2g} | {spread_cell} "
                    f"| {within}/{len(found)} | {rigid}/{len(found)} | {' | '.join(by_law)} |")
    if not rows:
        return rows
    for kind, soft in (("soft and 2e6 Pa objects", True), ("rigid (2e9 Pa) objects", False)):
        cells = [_counts_cell(pooled.get((soft, law), [0, 0, 0])) for law, _ in laws]
        repeatable = sum(x <= REPEATABLE_SPREAD for x in spreads[soft])
        spread_cell = f"{repeatable} of {len(spreads[soft])} ≤ {REPEATABLE_SPREAD}" if spreads[soft] else "-"
        rows.append(f"| **{kind}** | | | | {spread_cell} | | | {' | '.join(cells)} |")
    return rows


def mass_rows(records, objects) -> list:
    """Per object, the inference node's mass estimate (the height map's volume x density: what the labels' grip
    force FOS(E) m g / mu / 2 is computed from) against the cell's true mass: median over every planned grasp."""
    rows = []
    for obj in objects:
        true_kg = getattr(obj, "mass_kg", None)
        estimates = sorted(r["grasp"]["estimated_mass_kg"] for r in records
                           if r.get("object") == obj.name and (r.get("grasp") or {}).get("estimated_mass_kg"))
        if not estimates or not true_kg:
            continue
        median = estimates[len(estimates) // 2]
        rows.append(f"| {obj.name} | {true_kg * 1e3:.1f} | {median * 1e3:.1f} | {median / true_kg:.2f} | "
                    f"{estimates[0] / true_kg:.2f} .. {estimates[-1] / true_kg:.2f} | {len(estimates)} |")
    return rows


def present_cases(table: dict) -> list:
    """The cases the success table holds, in the report's column order."""
    return [c for c in (*CASES, MEASURED, *GRASP_ONLY_CASES) if any(c in v for v in table.values())]


def report_markdown(records, objects, planned_picks: int | None = None) -> str:
    """The results: the per-object table (objects: the experiment's, with name, youngs_modulus_pa and soft) and
    the paired comparisons."""
    records = with_plain_substitutes(records)
    table = success_table(records)
    cases = present_cases(table)
    done = len(outcomes(records))
    stand_ins = sum(1 for r in outcomes(records).values() if "stands_in_for" in r)
    errors = sum(1 for r in records if r.get("cell_error"))
    planned = (planned_picks or max((r["pick"] + 1 for r in records), default=0)) * len(objects) * len(cases)
    walls = sorted(r["wall_s"] for r in outcomes(records).values() if r.get("wall_s") and "stands_in_for" not in r)
    copies = (f", {stand_ins} of them a plain pick standing in for its grasp-only case (the same plan and grip: "
              f"not run again), so {done - stand_ins} picks ran") if stand_ins else ""
    lines = [f"Picks with an outcome: **{done} of {planned}** planned ({len(objects)} objects × {len(cases)} "
             f"cases × {planned_picks or '?'} picks{copies}); cell failures recorded (retried): {errors}.",
             f"Wall time per pick (bring-up, plan, pick, settle, tear-down): median "
             f"{walls[len(walls) // 2]:.0f} s, max {walls[-1]:.0f} s." if walls else "", "",
             "| # | object | E (Pa) | " + " | ".join(cases) + " |",
             "|---|---|---|" + "---|" * len(cases)]
    for i, obj in enumerate(objects):
        if obj.name in table:
            lines.append(f"| {i + 1} | {obj.name} | {obj.youngs_modulus_pa:.0e} | "
                         + " | ".join(_pct(table[obj.name].get(c)) for c in cases) + " |")
    totals = {c: [sum(v.get(c, [0, 0])[0] for v in table.values()), sum(v.get(c, [0, 0])[1] for v in table.values())]
              for c in cases}
    lines.append("| | **all picks** | | " + " | ".join(_pct(totals[c]) for c in cases) + " |")
    complete, sets = complete_totals(records, cases)
    lines.append(f"| | **{sets} complete sets** (object and pose in every case) | | "
                 + " | ".join(_pct(complete[c]) for c in cases) + " |")
    lines += ["", "Paired comparison (pairs = the same object at the same pose; margin = success rate with input A "
                  "minus with input B, points; 95 % bootstrap interval over objects, – with fewer than "
                  f"{MIN_OBJECTS_WITH_A_DIFFERENCE} objects where the inputs differed; p (objects) = exact sign-flip "
                  "test of each object's net, objects the independent units; p (picks) = exact sign test (McNemar) "
                  "on the discordant pairs as if the picks were independent):", "",
              "| A vs B | objects | n objects | pairs | A only / B only | margin A − B (pts) | 95 % CI | p (objects) "
              "| p (picks) |",
              "|---|---|---|---|---|---|---|---|---|", *_comparison_rows(records, objects, cases)]
    if any(c in cases for c in GRASP_ONLY_CASES):
        lines += ["", f"Figures: `{FIGURE_NAME}` (the paper's three inputs and the squeeze), `{GRASP_FIGURE_NAME}` "
                      "(the paper's protocol, one grip: correct against the wrong inputs gripped as the true "
                      "modulus)."]
    lines += ["", "The two channels of the stiffness input: the network's grasp and the closing force (the planner's "
                  "finger_force_n follows the modulus). Pairs whose plans chose the same grasp (centre within "
                  f"{SAME_GRASP_POSITION_M * 1e3:.0f} mm, angle within {math.degrees(SAME_GRASP_ANGLE_RAD):.0f}°) "
                  "differ only in force (or by chance: on a 2e9 Pa object correct and rigid are the same input); the "
                  "others in the grasp too:", "",
              "| A vs B | pairs, same grasp | A only / B only | pairs, other grasp | A only / B only |",
              "|---|---|---|---|---|", *channel_rows(records, cases)]
    repeat = repeat_line(records)
    if repeat:
        lines += ["", repeat]
    laws = squeeze_laws_present(records)
    lines += _table(squeeze_rows(records, objects, laws),
                    "The squeeze's estimates (measured case; a factor 3 of the true modulus is issue 49 item 4's "
                    "target, 2e9 Pa should read rigid; spread: max / min of an object's estimates read as numbers "
                    "over its picks, each its own pose and grasp, the item's 20 % is ≤ 1.2). The columns after "
                    "'called rigid' split the squeezes by the law "
                    "the estimate used (docs/squeeze.md; within ×3 / called rigid / n): both pads on flat faces "
                    "(and every rigid verdict), point contacts (Hertz), a pad along a line, the perceived section's "
                    "model, or not recorded (the first measured picks):",
                    "| object | true E (Pa) | median estimate (Pa) | ratio | spread | within ×3 | called rigid | "
                    + " | ".join(name for _, name in laws) + " |")
    lines += _table(mass_rows(records, objects),
                    "The grip force's mass (the inference node's estimate from the height map, every planned grasp) "
                    "against the cell's true mass:",
                    "| object | true mass (g) | median estimate (g) | ratio | ratio, min .. max | grasps |")
    return "\n".join(lines) + "\n"


def _table(rows: list, caption: str, header: str) -> list:
    """A captioned markdown table after a blank line; nothing without rows."""
    if not rows:
        return []
    return ["", caption, "", header, "|" + "---|" * header.count(" | ") + "---|", *rows]


def joined_records(out: Path, with_dirs=()) -> list:
    """OUT's records and those of other runs' folders (other cases at the same seeded poses, e.g. the three inputs
    beside a measured-case run), so the paired comparisons see both; a pick recorded in two of them is refused."""
    records = read_records(out)
    seen = {r["key"] for r in records}
    for folder in with_dirs:
        extra = read_records(Path(folder))
        if not extra:
            raise OSError(f"{folder} holds no records*.jsonl")
        twice = sorted(seen & {r["key"] for r in extra})
        if twice:
            raise ValueError(f"{folder} records picks {out} (or an earlier folder) records too, e.g. {twice[0]}: "
                             "join runs of other cases only")
        seen |= {r["key"] for r in extra}
        records += extra
    return records


def write_report(out: Path, objects, planned_picks: int | None = None, with_dirs=()) -> str:
    """OUT/per_object.png and the results part of OUT/report.md (between the markers; the rest is kept); with_dirs:
    other runs' folders whose records join OUT's (joined_records)."""
    records = joined_records(out, with_dirs)
    filled = with_plain_substitutes(records)      # report_markdown fills its own copy
    table = success_table(filled)
    cases = present_cases(table)
    # the paper's figure (its three inputs and the squeeze), and the paper's protocol (one grip) on its own
    for name, shown in ((FIGURE_NAME, [c for c in cases if c not in GRASP_ONLY_CASES]),
                        (GRASP_FIGURE_NAME, [c for c in ("correct", *GRASP_ONLY_CASES) if c in cases])):
        if len(shown) > 1 or (name == FIGURE_NAME and shown):
            per_object_figure(table, objects, Path(out) / name, shown, complete_totals(filled, shown))
    body = report_markdown(records, objects, planned_picks)
    if with_dirs:
        body = f"Joined with the records of {', '.join(map(str, with_dirs))} (the same seeded poses).\n" + body
    path = Path(out) / REPORT_NAME
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    begin, end = "<!-- results: defgg-cell-experiment report -->", "<!-- end of results -->"
    if begin in text and end in text:
        text = text.split(begin)[0] + begin + "\n" + body + end + text.split(end, 1)[1]
    else:
        text = text + ("\n" if text else "") + begin + "\n" + body + end + "\n"
    write_text_atomic(path, text)
    return body

"""The signal report: do a dataset's labels carry "stiffness changes which grasp is good"?

Read from the trial records alone (trials/*.jsonl or *.jsonl.gz of a dataset or pilot folder), so it can
be recomputed by anyone. Figures, per the issue that asked for them (docs/dataset.md, "Signal report"):

- per modulus: labelled trials and positive rate;
- within-scene share: of the soft trials' held-acceleration variance (mean over the directions; a lift
  failure holds 0), the part that lies within one object x modulus (the mean per-scene variance over the
  variance of all trials), pooled over the soft moduli and per modulus. Low = where a soft object is grasped
  barely matters, only which object it is;
- monotone / reversal rates over candidates labelled at every modulus: monotone = labels never go from
  positive to negative as E rises; soft->rigid reversal = positive at a soft modulus and negative at the
  stiffest (the paper's pinch grasp that fails on a stiff object), also for the softest alone; the converse
  = negative at a soft modulus and positive at the stiffest;
- the oracle gap: success of a stiffness-aware oracle (the best candidates per object x E) minus a
  stiffness-blind one (the same candidates for every E of an object, best on average over the moduli),
  for the best grasp and the best five; both choose among the candidates labelled at every modulus; also
  per object, to show where a gap comes from;
- near the threshold: the share of labelled trials held within 2.5 m/s^2 (10 %) of 25 m/s^2, whose labels
  a small change in the measurement flips (bench/bench_label_repeatability.py measures how often it does);
- the friction limit: Spearman correlation, over the softest modulus's scenes, between 2 mu F / m (the
  tangential acceleration friction alone can hold) and the scene's mean held acceleration.
"""
from __future__ import annotations

import functools
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from defgg_ros.atomic import read_jsonl
from defgg_ros.constants import (
    MAX_SOFT_BODY_YOUNGS_MODULUS_PA,
    SHAKE_POSITIVE_THRESHOLD_MPS2,
    STATUS_LIFT_FAILED,
    STATUS_OK,
    TWIST_POSITIVE_THRESHOLD_RADPS2,
)
from defgg_ros.sim.material import MATERIALS

TOP_K = 5
NEAR_THRESHOLD_BAND_MPS2 = 2.5    # +-10 % of the 25 m/s^2 threshold
# Label rules: "shake" = the dataset's label (mean held acceleration >= 25 m/s^2); "shake_and_twist" = that
# and a mean held angular acceleration over the six twist axes >= half the paper's 500 rad/s^2 limit (the
# shake's rule for the twist: contact area matters most in torsion).
LABEL_RULES = ("shake", "shake_and_twist")
# For records that do not state it (fem_v1-v4): the legacy material's 0.8 x 0.8.
LEGACY_EFFECTIVE_FRICTION = MATERIALS["legacy"].effective_friction


class SignalError(ValueError):
    """The folder holds no trial records the report can use."""


def read_trial_records(root) -> list[dict]:
    """Every complete trial record (dict) under <root>/trials, plain or sealed (gzip) JSON lines; a torn
    last line of a growing file (a run killed mid-write) is skipped."""
    folder = Path(root) / "trials"
    files = sorted(folder.glob("*.jsonl")) + sorted(folder.glob("*.jsonl.gz"))
    if not files:
        raise SignalError(f"no trial files in {folder}")
    return [record for path in files for record in read_jsonl(path)]


def with_shake_from(twist_records: list[dict], shake_records: list[dict]) -> list[dict]:
    """Twist-only records (a try that simulated only the twist) completed with the shake of the same trial id
    from another folder with the same settings: everything before the tests is identical and each test starts
    from the state after the pickup, so this is the record one trial with both tests gives. Status: the shake's,
    unless the twist's run failed. Twist records without a shake yet are left out."""
    shake = {r["trial_id"]: r for r in shake_records}
    out = []
    for r in twist_records:
        s = shake.get(r["trial_id"])
        if s is None:
            continue
        status = s["status"] if r["status"] == STATUS_OK else r["status"]
        out.append(dict(s, status=status, twist_accels_radps2=r.get("twist_accels_radps2"),
                        cpu_s=s.get("cpu_s", 0.0) + r.get("cpu_s", 0.0)))
    return out


def held_mps2(record: dict) -> float | None:
    """Mean held acceleration of a labelled trial (0 for a lift failure), None for a sim failure."""
    if record["status"] == STATUS_LIFT_FAILED:
        return 0.0
    accels = record.get("shake_accels_mps2")
    if record["status"] != STATUS_OK or not accels:
        return None
    return float(np.mean(accels))


def is_positive(record: dict, label_rule: str = "shake",
                threshold_mps2: float = SHAKE_POSITIVE_THRESHOLD_MPS2) -> bool | None:
    """The label of a record under a label rule (None for a simulation failure); threshold_mps2: the mean
    held acceleration a positive needs (the paper's 25 m/s^2; others only to ask what another would carry)."""
    value = held_mps2(record)
    if value is None:
        return None
    if label_rule == "shake_and_twist":
        twist = record.get("twist_accels_radps2")
        if record["status"] == STATUS_OK and not twist:
            raise SignalError(f"{record.get('trial_id', record['scene_id'])}: no twist recorded, so the "
                              "shake_and_twist label cannot be computed")
        return value >= threshold_mps2 and (
            record["status"] == STATUS_OK and float(np.mean(twist)) >= TWIST_POSITIVE_THRESHOLD_RADPS2)
    return value >= threshold_mps2


def signal_report(records: list[dict], label_rule: str = "shake",
                  threshold_mps2: float = SHAKE_POSITIVE_THRESHOLD_MPS2) -> dict:
    """Every figure of the report, as plain JSON-able numbers, under a label rule (LABEL_RULES) and a shake
    threshold (the near-threshold band stays around the paper's 25 m/s^2)."""
    if label_rule not in LABEL_RULES:
        raise SignalError(f"unknown label rule {label_rule!r}; known: {', '.join(LABEL_RULES)}")
    unshaken = sum(r["status"] == STATUS_OK and not r.get("shake_accels_mps2") for r in records)
    if unshaken:   # else only their lift failures would be labelled, a report of nothing
        raise SignalError(f"{unshaken} of {len(records)} trials ran without a shake recorded (a try that simulated "
                          "only the twist: take each trial's shake from the try with its settings, --shake-from)")
    rows = [r for r in records if held_mps2(r) is not None]
    if not rows:
        raise SignalError("no labelled trial (ok or lift_failed) among the records")
    moduli = sorted({float(r["youngs_modulus_pa"]) for r in rows})
    label = functools.partial(is_positive, label_rule=label_rule, threshold_mps2=threshold_mps2)
    return {
        "trials": len(records),
        "labelled": len(rows),
        "label_rule": label_rule,
        "threshold_mps2": threshold_mps2,
        "moduli_pa": moduli,
        "protocols": sorted({_protocol_of(r) for r in rows}),
        "positive_rate": _positive_rates(rows, moduli, label),
        "within_scene_share": _within_scene_shares(rows, moduli),
        "candidates": _candidate_figures(rows, moduli, label),
        "oracle": _oracle_figures(rows, moduli, label),
        "friction_limit_spearman": _friction_limit_spearman(rows, moduli),
        "near_threshold": _near_threshold_shares(rows, moduli),
    }


def _protocol_of(record: dict) -> str:
    return str(record.get("sim", {}).get("settings", {}).get("protocol", "legacy"))


def _positive_rates(rows, moduli, label) -> dict:
    out = {}
    for e in moduli:
        labels = [label(r) for r in rows if float(r["youngs_modulus_pa"]) == e]
        out[modulus_key(e)] = {"n": len(labels), "positive": sum(labels), "rate": sum(labels) / len(labels)}
    return out


def _near_threshold_shares(rows, moduli) -> dict:
    """Share of the labelled trials (all, and per modulus) whose held acceleration lies within
    NEAR_THRESHOLD_BAND_MPS2 of the threshold: labels a 10 % change in the measurement would flip."""
    def share(vals):
        return float(np.mean([abs(v - SHAKE_POSITIVE_THRESHOLD_MPS2) < NEAR_THRESHOLD_BAND_MPS2 for v in vals]))

    out = {"band_mps2": NEAR_THRESHOLD_BAND_MPS2, "all": share([held_mps2(r) for r in rows])}
    for e in moduli:
        out[modulus_key(e)] = share([held_mps2(r) for r in rows if float(r["youngs_modulus_pa"]) == e])
    return out


def _within_scene_shares(rows, moduli) -> dict:
    soft = [e for e in moduli if e <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA]
    groups = {"soft": soft, **{modulus_key(e): [e] for e in moduli}}
    return {name: _within_share([r for r in rows if float(r["youngs_modulus_pa"]) in es])
            for name, es in groups.items()}


def _within_share(rows) -> float | None:
    """Mean within-scene variance (scenes weighted equally) over the variance of all the rows (None with
    no variance): the share of the spread that choosing where to grasp an object could explain."""
    by_scene = defaultdict(list)
    for r in rows:
        by_scene[r["scene_id"]].append(held_mps2(r))
    values = np.array([v for vs in by_scene.values() for v in vs])
    total = float(np.var(values)) if len(values) else 0.0
    if total <= 0:
        return None
    return float(np.mean([np.var(vs) for vs in by_scene.values()])) / total


def _label_table(rows, moduli, label) -> dict:
    """(object, candidate) -> {E: label} for candidates labelled at every modulus."""
    table = defaultdict(dict)
    for r in rows:
        table[(r["object_name"], int(r["candidate_index"]))][float(r["youngs_modulus_pa"])] = label(r)
    return {k: v for k, v in table.items() if len(v) == len(moduli)}


def _candidate_figures(rows, moduli, label) -> dict:
    table = _label_table(rows, moduli, label)
    n = len(table)
    if n == 0 or len(moduli) < 2:
        return {"n": n}
    stiffest, softest = moduli[-1], moduli[0]
    soft = [e for e in moduli if e <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA and e != stiffest]
    monotone = sum(all(not (lab[a] and not lab[b]) for a, b in zip(moduli, moduli[1:]))
                   for lab in table.values())
    soft_to_rigid = sum(any(lab[e] for e in soft) and not lab[stiffest] for lab in table.values())
    softest_to_rigid = sum(lab[softest] and not lab[stiffest] for lab in table.values())
    converse = sum(any(not lab[e] for e in soft) and lab[stiffest] for lab in table.values())
    same_soft = sum(len({lab[e] for e in soft}) == 1 for lab in table.values())
    return {"n": n, "monotone": monotone / n, "soft_pos_rigid_neg": soft_to_rigid / n,
            "softest_pos_rigid_neg": softest_to_rigid / n, "softest_pos_rigid_neg_count": softest_to_rigid,
            "soft_neg_rigid_pos": converse / n, "same_label_every_soft_modulus": same_soft / n}


def _oracle_figures(rows, moduli, label) -> dict:
    """Stiffness-aware vs stiffness-blind oracle success (fractions), best grasp and best TOP_K."""
    table = _label_table(rows, moduli, label)
    by_object = defaultdict(dict)
    for (obj, cand), labels in table.items():
        by_object[obj][cand] = labels
    if not by_object:
        return {"objects": 0}
    out = {"objects": len(by_object), "per_object": {}}
    for k in (1, TOP_K):
        aware, blind = [], []
        name = "best" if k == 1 else f"top{k}"
        for obj, cands in sorted(by_object.items()):
            kk = min(k, len(cands))
            # aware: the kk best for this E (labels are 0/1, so: positives first)
            obj_aware = [min(kk, sum(labels[e] for labels in cands.values())) / kk for e in moduli]
            mean_over_e = sorted((np.mean([labels[e] for e in moduli]) for labels in cands.values()),
                                 reverse=True)
            aware += obj_aware
            blind += [float(np.mean(mean_over_e[:kk]))] * len(moduli)
            out["per_object"].setdefault(obj, {"candidates": len(cands)})[f"{name}_gap_points"] = \
                100 * (float(np.mean(obj_aware)) - float(np.mean(mean_over_e[:kk])))
        out[name] = {"aware": float(np.mean(aware)), "blind": float(np.mean(blind)),
                     "gap_points": 100 * (float(np.mean(aware)) - float(np.mean(blind)))}
    return out


def _friction_limit_spearman(rows, moduli) -> float | None:
    softest = [r for r in rows if float(r["youngs_modulus_pa"]) == moduli[0]]
    limit, held = defaultdict(list), defaultdict(list)
    for r in softest:
        mass = r.get("sim", {}).get("mass_kg")
        if not mass or not r.get("grasp_force_n"):
            continue
        mu = r.get("sim", {}).get("effective_friction", LEGACY_EFFECTIVE_FRICTION)
        limit[r["scene_id"]].append(2 * mu * r["grasp_force_n"] / mass)
        held[r["scene_id"]].append(held_mps2(r))
    scenes = sorted(limit)
    if len(scenes) < 3:
        return None
    return spearman([np.mean(limit[s]) for s in scenes], [np.mean(held[s]) for s in scenes])


def spearman(x, y) -> float:
    """Spearman's rank correlation (average ranks for ties)."""
    rx, ry = _ranks(np.asarray(x, float)), _ranks(np.asarray(y, float))
    if rx.std() == 0 or ry.std() == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def _ranks(v: np.ndarray) -> np.ndarray:
    order = np.argsort(v, kind="mergesort")
    ranks = np.empty(len(v))
    ranks[order] = np.arange(len(v), dtype=float)
    for value in np.unique(v):      # ties share their mean rank
        tied = v == value
        ranks[tied] = ranks[tied].mean()
    return ranks


def modulus_key(e: float) -> str:
    """The report's key of a modulus: 2e4, 2e9 (its JSON and the tables)."""
    return f"{e:.0e}".replace("e+0", "e")


def _points(x: float) -> str:
    """Points to one decimal, without the '-0.0' of a float error below zero."""
    return f"{round(x, 1) + 0.0:.1f}"


def _pct(x) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f} %"


# What a report says the labels can carry: the pilots' gate (bench/pilot_signal.py), and the share of trials
# near the threshold above which a within-scene share is mostly label noise (fem_v4: 24 %, pilot a: 60 %).
CARRY_GAP_POINTS, CARRY_WITHIN_SHARE, NOISY_NEAR_SHARE = 5.0, 0.30, 0.40


def what_labels_carry(report: dict) -> list[str]:
    """Plain statements, from the report's figures alone, of what a network trained on these labels can and
    cannot learn from them (the dataset card prints them under the report)."""
    rates = {e: report["positive_rate"][modulus_key(e)]["rate"] for e in report["moduli_pa"]}
    rate_text = " / ".join(f"{100 * r:.0f}" for r in rates.values())
    lines = [f"- Can carry: how often a grasp of an object holds at each modulus ({rate_text} % positive at "
             f"{' / '.join(f'{e:.0e}' for e in rates)} Pa) and which objects are hard to hold."]
    o, within = report["oracle"], report["within_scene_share"]["soft"]
    if o.get("objects"):
        gap = max(o["best"]["gap_points"], o[f"top{TOP_K}"]["gap_points"])
        carries = gap >= CARRY_GAP_POINTS and within is not None and within >= CARRY_WITHIN_SHARE
        verdict = "Can" if carries else "Cannot"
        lines.append(f"- {verdict} carry \"stiffness changes which grasp is good\": a perfect stiffness-aware choice "
                     f"of grasps beats a perfect stiffness-blind one by at most {_points(gap)} points (best grasp or "
                     f"best {TOP_K}; the bar is {CARRY_GAP_POINTS:g} points with a within-scene share of "
                     f"{100 * CARRY_WITHIN_SHARE:.0f} %, here {_pct(within)}). "
                     + ("" if carries else "A stiffness input can then add little over depth alone on these labels."))
    near = report.get("near_threshold")
    if near and near["all"] is not None and near["all"] >= NOISY_NEAR_SHARE:
        lines.append(f"- Noisy: {_pct(near['all'])} of the trials are held within {near['band_mps2']:g} m/s^2 of the "
                     f"threshold, where a 10 % change flips the label; the within-scene share is then mostly that "
                     f"noise, not where the object is grasped.")
    return lines


def render_markdown(report: dict, title: str = "Signal report") -> str:
    """The report as Markdown (the dataset card embeds it)."""
    lines = [f"## {title}", "",
             f"{report['labelled']} labelled of {report['trials']} trials; protocol(s): "
             f"{', '.join(report['protocols'])}; label rule: {report.get('label_rule', 'shake')}.", "",
             "| E (Pa) | labelled | positive | within-scene share of held-acceleration variance |",
             "|---|---|---|---|"]
    for e in report["moduli_pa"]:
        pr, within = report["positive_rate"][modulus_key(e)], report["within_scene_share"][modulus_key(e)]
        lines.append(f"| {e:.0e} | {pr['n']} | {_pct(pr['rate'])} | {_pct(within)} |")
    c, o = report["candidates"], report["oracle"]
    lines += ["", f"- Within-scene share, soft moduli pooled: **{_pct(report['within_scene_share']['soft'])}**."]
    if c.get("n") and "monotone" in c:
        lines += [f"- Candidates labelled at every modulus: {c['n']}. Monotone in E: {_pct(c['monotone'])}; "
                  f"positive at a soft E and negative at the stiffest: {_pct(c['soft_pos_rigid_neg'])} "
                  f"(at the softest: {c['softest_pos_rigid_neg_count']}, {_pct(c['softest_pos_rigid_neg'])}); "
                  f"the converse: {_pct(c['soft_neg_rigid_pos'])}; same label at every soft E: "
                  f"{_pct(c['same_label_every_soft_modulus'])}."]
    if o.get("objects"):
        for name, label in (("best", "best grasp"), (f"top{TOP_K}", f"best {TOP_K} grasps")):
            lines.append(f"- Oracle, {label}: stiffness-aware {_pct(o[name]['aware'])}, stiffness-blind "
                         f"{_pct(o[name]['blind'])}: **gap {_points(o[name]['gap_points'])} points** "
                         f"({o['objects']} objects).")
        ahead = sorted(((obj, f) for obj, f in o.get("per_object", {}).items()
                        if max(f["best_gap_points"], f[f"top{TOP_K}_gap_points"]) >= 0.05),   # shows as 0.1
                       key=lambda item: -item[1]["best_gap_points"] - item[1][f"top{TOP_K}_gap_points"])
        listed = ", ".join(f"{obj} {_points(f['best_gap_points'])} / {_points(f[f'top{TOP_K}_gap_points'])}"
                           for obj, f in ahead)
        lines.append(f"- Where the stiffness-aware oracle is ahead (points, best / best {TOP_K}): "
                     f"{listed or 'no object'}; level on the other {o['objects'] - len(ahead)} object(s).")
    near = report.get("near_threshold")
    if near:
        per_e = ", ".join(f"{e:.0e}: {_pct(near[modulus_key(e)])}" for e in report["moduli_pa"])
        lines.append(f"- Held within {near['band_mps2']:g} m/s^2 of the 25 m/s^2 threshold (labels a 10 % change "
                     f"flips): **{_pct(near['all'])}** ({per_e}).")
    rho = report["friction_limit_spearman"]
    if rho is not None:
        lines.append(f"- Spearman (softest E, per scene) between the friction limit 2 mu F / m and the mean "
                     f"held acceleration: {rho:.2f}.")
    lines += ["", "What these labels can and cannot carry:", "", *what_labels_carry(report)]
    return "\n".join(lines) + "\n"

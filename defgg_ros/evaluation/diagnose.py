"""Why the models do (not) differ: numbers from the training labels and from the planned grasps.

1. Labels (the dataset): per modulus, how many trials are labelled and
   positive; and, because the generator tries the SAME candidate grasps of an
   object at every modulus, how often a candidate's label changes with E.
   If labels hardly depend on E, no network can learn to use stiffness.
   And, within one object and modulus, whether nearby candidates (centres
   < 10 px apart, angles < 20 deg) share a label more often than distant ones:
   if not, the labels have no spatial order that a quality map could learn.
2. Plans (an evaluation's trial records): how far each model's best grasp
   moves between moduli on the same object. The depth-only model cannot
   move it (its input is the same); the stiffness-aware model moves it only
   if it learned to.
3. Repeatability (an evaluation's trial records): a sensitivity trial whose
   grasp landed on the same pixel as its view's correct-input trial differs
   from it only by the network's regressed width and angle (a fraction of a
   mm or degree); how often the outcome still differs is the noise floor of
   every comparison in the tables.
4. Ranking (an evaluation's trial records): within one view, when two of a
   model's grasps ended differently, how often the one that held had the
   higher predicted quality (50 % = the quality map does not order grasps).
5. Twist by axis (an evaluation's trial records): per modulus, how often a
   lifted object holds the full twist amplitude about each axis of the hand
   (x = the closing line, y = across it, z = the approach axis), both
   models' grasps pooled: which rotation a grasp loses says whether the
   grip's friction (about y and z) or its torsion (about x) gives way.
"""
from __future__ import annotations

import itertools
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from defgg_ros.constants import MAX_SOFT_BODY_YOUNGS_MODULUS_PA, TWIST_ACCEL_LIMIT_RADPS2
from defgg_ros.data.format import STATUS_LIFT_FAILED, STATUS_OK, list_scene_ids, read_scene, read_trials
from defgg_ros.data.labels import height_offset_m, measured_mean_mps2
from defgg_ros.data.signal import TOP_K, SignalError, signal_report, what_labels_carry
from defgg_ros.evaluation.tables import is_main_correct_input
from defgg_ros.evaluation.tasks import LIMIT_TOLERANCE


def label_stats(data_root) -> dict:
    """Counts per modulus and label agreement of the same candidate across moduli."""
    per_e = defaultdict(lambda: {"trials": 0, "labelled": 0, "positive": 0, "sim_failed": 0})
    by_candidate = defaultdict(dict)          # (object, candidate) -> {E: label}
    shake_means = defaultdict(list)
    labelled_by_scene = []                    # each scene's labelled trials, for the locality check
    with_offsets = []                         # and their height offsets from the executor's grasp height
    records = []                              # every trial as its record, for the signal report
    for sid in list_scene_ids(data_root):
        trials = read_trials(data_root, sid)
        records += [t.to_json() for t in trials]
        labelled = [t for t in trials if t.label is not None]
        labelled_by_scene.append(labelled)
        if labelled:
            depth_m = read_scene(Path(data_root) / "scenes" / f"{sid}.npz").depth_m
            with_offsets.append((labelled, [height_offset_m(t, depth_m) for t in labelled]))
        for t in trials:
            e = f"{t.youngs_modulus_pa:.0e}"
            s = per_e[e]
            s["trials"] += 1
            if t.label is None:
                s["sim_failed"] += 1
                continue
            s["labelled"] += 1
            s["positive"] += int(t.label)
            by_candidate[(t.object_name, t.candidate_index)][e] = t.label
            if t.shake_mean_mps2 is not None:
                shake_means[e].append(t.shake_mean_mps2)
    locality = _label_locality(labelled_by_scene)
    choice = _grasp_choice(labelled_by_scene)
    by_height = _positive_rate_by_height_offset(with_offsets)
    pairs = defaultdict(lambda: [0, 0])       # (E1, E2) -> [same label, compared]
    for labels in by_candidate.values():
        for e1, e2 in itertools.combinations(sorted(labels, key=float), 2):
            pairs[(e1, e2)][0] += int(labels[e1] == labels[e2])
            pairs[(e1, e2)][1] += 1
    return {
        "per_modulus": {e: {**v, "positive_rate": v["positive"] / v["labelled"] if v["labelled"] else None,
                            "mean_shake_mps2": float(np.mean(shake_means[e])) if shake_means[e] else None}
                        for e, v in sorted(per_e.items(), key=lambda kv: float(kv[0]))},
        "objects": len({o for o, _ in by_candidate}),
        "candidates_with_several_moduli": sum(1 for v in by_candidate.values() if len(v) > 1),
        "label_agreement": {f"{a} vs {b}": {"same": s, "compared": n, "rate": s / n if n else None}
                            for (a, b), (s, n) in sorted(pairs.items())},
        "locality": locality,
        "grasp_choice": choice,
        "positive_rate_by_height_offset_mm": by_height,
        "signal": _signal(records),
        "data_root": str(data_root),
    }


def _signal(records: list) -> dict | None:
    """The dataset's signal report (data.signal) from its trial records: can its labels carry a
    stiffness-aware margin at all?"""
    try:
        return signal_report(records)
    except SignalError:
        return None


NEAR_PX, NEAR_DEG, FAR_PX = 10.0, 20.0, 30.0
SAME_HEIGHT_M, APART_HEIGHT_M = 0.003, 0.010
LOCALITY_KINDS = ("near", "near_same_height", "near_height_apart", "far")
HEIGHT_OFFSET_BINS_M = (-0.010, -0.003, 0.003, 0.010)


def _body(trials) -> str:
    return "soft" if trials[0].youngs_modulus_pa <= MAX_SOFT_BODY_YOUNGS_MODULUS_PA else "rigid"


def _label_locality(labelled_by_scene) -> dict:
    """Same-label rate of candidate pairs of one scene, near (centres < NEAR_PX, angles < NEAR_DEG) and far
    (centres >= FAR_PX), over the scenes that have both labels (elsewhere every pair agrees trivially).
    Near pairs are also split by their TCP heights: < SAME_HEIGHT_M vs >= APART_HEIGHT_M apart (the
    image-space grasp has no height; the sampler's candidates do)."""
    out = {body: {**{k: [0, 0] for k in LOCALITY_KINDS}, "scenes": 0} for body in ("soft", "rigid")}
    for trials in labelled_by_scene:
        if len({t.label for t in trials}) < 2:
            continue
        body = out[_body(trials)]
        body["scenes"] += 1
        for a, b in itertools.combinations(trials, 2):
            dist = math.hypot(a.rect.center_u_px - b.rect.center_u_px, a.rect.center_v_px - b.rect.center_v_px)
            near = dist < NEAR_PX and _grasp_turn_deg(a.rect.angle_rad, b.rect.angle_rad) < NEAR_DEG
            dz = abs(a.position_m[2] - b.position_m[2])
            if near:
                kinds = ["near"] + (["near_same_height"] if dz < SAME_HEIGHT_M else
                                    ["near_height_apart"] if dz >= APART_HEIGHT_M else [])
            else:
                kinds = ["far"] if dist >= FAR_PX else []
            for kind in kinds:
                body[kind][0] += int(a.label == b.label)
                body[kind][1] += 1
    return {name: {"scenes": b["scenes"], **{k: {"same": s, "pairs": n, "rate": s / n if n else None}
                                             for k in LOCALITY_KINDS for s, n in [b[k]]}}
            for name, b in out.items()}


def _positive_rate_by_height_offset(scenes_with_offsets) -> dict:
    """Positive rate of the labelled trials per bin of height_offset_m (trial TCP minus the executor's
    height on its pixel), soft and rigid. scenes_with_offsets: [(trials, offsets_m)]."""
    edges = (-math.inf, *HEIGHT_OFFSET_BINS_M, math.inf)
    out = {}
    for trials, offsets in scenes_with_offsets:
        body = out.setdefault(_body(trials), [[0, 0] for _ in range(len(edges) - 1)])
        for t, dz in zip(trials, offsets):
            i = next(k for k in range(len(edges) - 1) if edges[k] <= dz < edges[k + 1])
            body[i][0] += int(t.label)
            body[i][1] += 1
    names = [f"< {1000 * edges[1]:g}", *(f"{1000 * lo:g} to {1000 * hi:g}" for lo, hi in
                                         zip(edges[1:-2], edges[2:-1])), f">= {1000 * edges[-2]:g}"]
    return {body: {n: {"positive": p, "trials": k} for n, (p, k) in zip(names, bins)} for body, bins in out.items()}


def _grasp_choice(labelled_by_scene) -> dict:
    """Per body kind, how much of the held shake acceleration the choice of grasp decides: the share
    of its variance that lies within a scene (object x modulus) rather than between scenes, the median
    spread within a scene, and how often a random vs the best of a scene's candidates is positive."""
    out = {}
    for name in ("soft", "rigid"):
        scenes = [t for t in labelled_by_scene if t and _body(t) == name]
        held = [np.array([measured_mean_mps2(t.shake_accels_mps2, (t.sim or {}).get("shake_measured"))
                          for t in trials]) for trials in scenes]
        several = [h for h in held if len(h) > 1]
        if not several:
            continue
        everything = np.concatenate(held)
        within = sum(float(np.sum((h - h.mean()) ** 2)) for h in held)
        total = float(np.sum((everything - everything.mean()) ** 2))
        out[name] = {
            "scenes": len(scenes), "trials": int(everything.size),
            "within_scene_share": within / total if total else None,
            "median_within_scene_sd_mps2": float(np.median([h.std(ddof=1) for h in several])),
            "scenes_with_both_labels": sum(len({t.label for t in trials}) == 2 for trials in scenes),
            "random_candidate_positive": float(np.mean([np.mean([t.label for t in trials]) for trials in scenes])),
            "best_candidate_positive": float(np.mean([any(t.label for t in trials) for trials in scenes])),
        }
    return out


def plan_shifts(plans) -> dict:
    """Per model: mean distance (mm) between its rank-0 grasp at each modulus and at the stiffest one.

    plans: entries of plans.json ({"view": View.to_json(), "grasps": [PlannedGrasp.to_json(), ...]}).
    """
    best = defaultdict(dict)                  # (model, object) -> {E: grasp}
    for entry in plans:
        v = entry["view"]
        if v["experiment"] == "main" and entry["grasps"]:
            best[(v["model"], v["object_name"])][v["youngs_modulus_pa"]] = entry["grasps"][0]
    out = defaultdict(lambda: defaultdict(list))
    for (model, _), grasps in best.items():
        ref_e = max(grasps)
        ref = grasps[ref_e]
        for e, g in grasps.items():
            if e == ref_e:
                continue
            d_mm = 1000 * math.dist(g["position_m"][:2], ref["position_m"][:2])
            out[model][f"{e:.0e}"].append((d_mm, abs(g["width_m"] - ref["width_m"]) * 1000))
    return {m: {e: {"objects": len(v), "mean_shift_mm": float(np.mean([d for d, _ in v])),
                    "moved_over_5mm": sum(d > 5 for d, _ in v),
                    "mean_width_change_mm": float(np.mean([w for _, w in v]))}
                for e, v in sorted(per.items(), key=lambda kv: float(kv[0]))} for m, per in out.items()}


def _grasp_turn_deg(a_rad: float, b_rad: float) -> float:
    """Angle between two parallel-jaw grasp directions (the same grasp after a half turn), in [0, 90]."""
    turn = abs(a_rad - b_rad) % math.pi
    return math.degrees(min(turn, math.pi - turn))


def _main_key(r) -> tuple:
    return r["model"], r["object_set"], r["object"], r["youngs_modulus_pa"], r["rank"], r["task"]


def replicate_flips(records) -> dict | None:
    """Sensitivity trials on the same grasp pixel as their view's correct-input (main) trial: how many,
    how far their width and angle moved, and how often the outcome differs. None without such pairs."""
    main = {_main_key(r): r for r in records if r["experiment"] == "main" and r.get("grasp")}
    widths_mm, angles_deg, differ = [], [], 0
    for r in records:
        m = main.get(_main_key(r)) if r["experiment"] == "sensitivity" and r.get("grasp") else None
        if m is None or r.get("success") is None or m.get("success") is None or r.get("reused_from"):
            continue
        g, h = r["grasp"], m["grasp"]
        if (g["center_u_px"], g["center_v_px"]) != (h["center_u_px"], h["center_v_px"]):
            continue
        widths_mm.append(1000 * abs(g["width_m"] - h["width_m"]))
        angles_deg.append(_grasp_turn_deg(g["yaw_rad"], h["yaw_rad"]))
        differ += int(r["success"] != m["success"])
    if not widths_mm:
        return None
    return {"pairs": len(widths_mm), "outcome_differs": differ, "rate": differ / len(widths_mm),
            "median_width_change_mm": float(np.median(widths_mm)),
            "median_angle_change_deg": float(np.median(angles_deg))}


def quality_ranking(records) -> dict | None:
    """Per "task|set|model": over pairs of one view's graded main-experiment grasps (correct input)
    whose outcomes differ, how many have the higher predicted quality on the grasp that held (a tie
    counts one half). None without such pairs."""
    views = defaultdict(list)
    for r in records:
        if is_main_correct_input(r) and r.get("grasp") and r.get("success") is not None:
            views[(r["task"], r["object_set"], r["model"], r.get("model_sha"), r["object"],
                   r["youngs_modulus_pa"])].append(r)      # one weights' grasps compared with each other only
    out = defaultdict(lambda: {"pairs": 0, "concordant": 0.0})
    for (task, object_set, model, _sha, _obj, _e), recs in views.items():
        for a, b in itertools.combinations(recs, 2):
            if bool(a["success"]) == bool(b["success"]):
                continue
            held, failed = (a, b) if a["success"] else (b, a)
            qh, qf = held["grasp"]["quality"], failed["grasp"]["quality"]
            cell = out[f"{task}|{object_set}|{model}"]
            cell["pairs"] += 1
            cell["concordant"] += 1.0 if qh > qf else 0.5 if qh == qf else 0.0
    return {k: {**v, "rate": v["concordant"] / v["pairs"]} for k, v in sorted(out.items())} or None


NEAR_GRASP_MM, NEAR_GRASP_DEG = 5.0, 15.0     # two grasps this close are "the same grasp" for the pairing


def model_grasp_pairs(records) -> dict | None:
    """Per "task|object set", over the graded main-experiment trials (correct input) that two models ran on
    one view and rank: how many were the identical simulation (the same grasp, so the same outcome by
    construction), how many near (centres <= NEAR_GRASP_MM, closing directions <= NEAR_GRASP_DEG apart) and
    how many apart, and in each how often the outcomes differ. Near pairs that differ measure how much of the
    paired comparison is the simulator's sensitivity to a small change of grasp, not a different choice.
    None without two models on a view."""
    by_view = defaultdict(dict)
    for r in records:
        if is_main_correct_input(r) and r.get("grasp") and r.get("success") is not None:
            by_view[(r["task"], r["object_set"], r["object"], r["youngs_modulus_pa"], r["rank"])][r["model"]] = r
    out = defaultdict(lambda: {"pairs": 0, "identical": 0, "near": 0, "near_differ": 0, "apart": 0,
                               "apart_differ": 0, "distances_mm": []})
    for (task, object_set, *_), models in by_view.items():
        if len(models) != 2:
            continue
        a, b = models.values()
        cell = out[f"{task}|{object_set}"]
        cell["pairs"] += 1
        if a.get("sim_key") and a.get("sim_key") == b.get("sim_key"):
            cell["identical"] += 1
            continue
        ga, gb = a["grasp"], b["grasp"]
        d_mm = 1000 * math.dist(ga["position_m"][:2], gb["position_m"][:2])
        cell["distances_mm"].append(d_mm)
        kind = "near" if d_mm <= NEAR_GRASP_MM and _grasp_turn_deg(ga["yaw_rad"], gb["yaw_rad"]) <= NEAR_GRASP_DEG \
            else "apart"
        cell[kind] += 1
        cell[f"{kind}_differ"] += int(bool(a["success"]) != bool(b["success"]))
    return {k: {**{n: v for n, v in c.items() if n != "distances_mm"},
                "median_distance_mm": float(np.median(c["distances_mm"])) if c["distances_mm"] else None}
            for k, c in sorted(out.items())} or None


def _model_pairs_markdown(pairs: dict | None) -> list:
    if not pairs:
        return []
    lines = ["**Do the two models choose different grasps?** (main experiment, correct input: the two models' "
             f"graded trials on one view and rank; near = centres <= {NEAR_GRASP_MM:.0f} mm and closing directions "
             f"<= {NEAR_GRASP_DEG:.0f} deg apart; an identical simulation has the same outcome by construction)", "",
             "| task | object set | pairs | identical simulation | near: outcomes differ | apart: outcomes differ | "
             "median distance (mm) |", "|---|---|---|---|---|---|---|"]

    def share(k, n):
        return f"{k} of {n} ({100 * k / n:.1f} %)" if n else "–"
    for key, v in pairs.items():
        task, object_set = key.split("|")
        median = "–" if v["median_distance_mm"] is None else f"{v['median_distance_mm']:.1f}"
        lines.append(f"| {task} | {object_set} | {v['pairs']} | {v['identical']} | "
                     f"{share(v['near_differ'], v['near'])} | {share(v['apart_differ'], v['apart'])} | {median} |")
    return lines + [""]


TWIST_AXIS_NAMES = ("x", "y", "z")    # sim.trial.TWIST_AXES in pairs: +x, -x, +y, -y, +z, -z


def twist_by_axis(records) -> dict | None:
    """{E label: {"trials", "lift_failed", "lifted", "axes": {axis: [held, tried]}}} over the main
    experiment's twist trials. The evaluation stops a trial at its first failing direction, so an axis
    counts as tried when one of its two directions failed or both were measured; None without trials."""
    held_at = TWIST_ACCEL_LIMIT_RADPS2 * (1 - LIMIT_TOLERANCE)
    per_e = defaultdict(lambda: {"trials": 0, "lift_failed": 0, "lifted": 0,
                                 "axes": {a: [0, 0] for a in TWIST_AXIS_NAMES}})
    for r in records:
        if r["task"] != "twist" or not is_main_correct_input(r) or r.get("status") not in (STATUS_OK,
                                                                                           STATUS_LIFT_FAILED):
            continue
        cell = per_e[f"{float(r['youngs_modulus_pa']):.0e}"]
        cell["trials"] += 1
        if r["status"] == STATUS_LIFT_FAILED:
            cell["lift_failed"] += 1
            continue
        cell["lifted"] += 1
        measured = r.get("measured") or [True] * len(r["accels"])
        for i, axis in enumerate(TWIST_AXIS_NAMES):
            both = [(r["accels"][j], measured[j]) for j in (2 * i, 2 * i + 1)]
            failed = any(m and a < held_at for a, m in both)
            if failed or all(m for _, m in both):
                cell["axes"][axis][0] += int(not failed)
                cell["axes"][axis][1] += 1
    return {e: per_e[e] for e in sorted(per_e, key=float)} or None


def _twist_axes_markdown(axes: dict | None) -> list:
    if not axes:
        return []
    lines = ["**Where the twist fails** (main experiment, both models' grasps pooled; of the lifted objects, "
             "held/tried per hand axis, both ways: x = the closing line, y = across it, z = the approach axis; "
             "a trial stops at its first failing axis, so later axes are tried on the survivors only)", "",
             "| E (Pa) | trials | lift failed | lifted | held about x | held about y | held about z |",
             "|---|---|---|---|---|---|---|"]
    for e, v in axes.items():
        counts = (v["axes"][a] for a in TWIST_AXIS_NAMES)
        held = " | ".join(f"{100 * h / n:.1f} % of {n}" if n else "–" for h, n in counts)
        lines.append(f"| {e} | {v['trials']} | {v['lift_failed']} | {v['lifted']} | {held} |")
    return lines + [""]


def diagnostics_markdown(labels: dict | None, shifts: dict | None, replicates: dict | None = None,
                         ranking: dict | None = None, twist_axes: dict | None = None,
                         model_pairs: dict | None = None) -> str:
    lines = []
    if labels:
        lines += [f"**Training labels by modulus** (`{labels.get('data_root', 'the dataset')}`)", "",
                  "| E (Pa) | trials | labelled | positive | positive rate | mean held shake accel. (m/s^2) |",
                  "|---|---|---|---|---|---|"]
        for e, v in labels["per_modulus"].items():
            rate = "–" if v["positive_rate"] is None else f"{100 * v['positive_rate']:.1f} %"
            acc = "–" if v["mean_shake_mps2"] is None else f"{v['mean_shake_mps2']:.1f}"
            lines.append(f"| {e} | {v['trials']} | {v['labelled']} | {v['positive']} | {rate} | {acc} |")
        lines += ["", f"{labels['objects']} objects with labels; {labels['candidates_with_several_moduli']} candidate "
                  "grasps were tried at more than one modulus. Same grasp, same label at two moduli:", "",
                  "| moduli | same label | compared | agreement |", "|---|---|---|---|"]
        for k, v in labels["label_agreement"].items():
            rate = "–" if v["rate"] is None else f"{100 * v['rate']:.1f} %"
            lines.append(f"| {k} | {v['same']} | {v['compared']} | {rate} |")
        lines.append("")
        lines += _locality_markdown(labels.get("locality"))
        lines += _height_offset_markdown(labels.get("positive_rate_by_height_offset_mm"))
        lines += _grasp_choice_markdown(labels.get("grasp_choice"))   # its signal report: under the targets
    if shifts:
        lines += ["**How far the best grasp moves with the modulus** (rank-0 grasp vs the one at the stiffest "
                  "modulus, same object)", "", "| model | E (Pa) | objects | mean shift (mm) | moved > 5 mm | "
                  "mean width change (mm) |", "|---|---|---|---|---|---|"]
        for m, per in shifts.items():
            for e, v in per.items():
                lines.append(f"| {m} | {e} | {v['objects']} | {v['mean_shift_mm']:.1f} | {v['moved_over_5mm']} | "
                             f"{v['mean_width_change_mm']:.1f} |")
        lines.append("")
    if replicates:
        lines += ["**How repeatable an outcome is** (sensitivity trials whose grasp is on the same pixel as the "
                  "correct-input trial of their view)", "",
                  f"{replicates['pairs']} pairs; width moved by a median {replicates['median_width_change_mm']:.2f} "
                  f"mm and angle by {replicates['median_angle_change_deg']:.2f} deg; the outcome differs in "
                  f"{replicates['outcome_differs']} ({100 * replicates['rate']:.1f} %).", ""]
    if ranking:
        lines += ["**Does the predicted quality order a view's grasps by outcome?** (pairs of one view's grasps, "
                  "correct stiffness input, that ended differently: share where the grasp that held had the higher "
                  "predicted quality; 50 % = no information, 100 % = a perfect order)", "",
                  "| task | object set | model | pairs | held grasp ranked higher |", "|---|---|---|---|---|"]
        for key, v in ranking.items():
            task, object_set, model = key.split("|")
            lines.append(f"| {task} | {object_set} | {model} | {v['pairs']} | {100 * v['rate']:.1f} % |")
        lines.append("")
    lines += _model_pairs_markdown(model_pairs)
    lines += _twist_axes_markdown(twist_axes)
    return "\n".join(lines)


def signal_lines(signal: dict | None, data_root: str | None) -> list:
    """The training labels' oracle gap and what it lets a ranking learn (data.signal's own statements)."""
    if not signal or not signal["oracle"].get("objects"):
        return []

    o = signal["oracle"]
    gaps = ", ".join(f"{label} {round(o[key]['gap_points'], 1) + 0.0:+.1f} points (aware "
                     f"{100 * o[key]['aware']:.1f} %, blind {100 * o[key]['blind']:.1f} %)"
                     for key, label in (("best", "best grasp"), (f"top{TOP_K}", f"best {TOP_K}")))
    return [f"**Could the training labels carry a stiffness-aware margin?** (`defgg-datagen signal {data_root}`, "
            f"{signal['labelled']} labelled trials, protocol {', '.join(signal['protocols'])}) A perfect "
            f"stiffness-aware choice among the labelled candidates vs a perfect stiffness-blind one: {gaps}.", "",
            *what_labels_carry(signal), ""]


def _locality_markdown(locality: dict | None) -> list:
    if not locality or not any(b["scenes"] for b in locality.values()):
        return []
    lines = [f"**Do nearby candidates share a label?** Pairs of one object and modulus (scenes with both labels "
             f"only); near = centres < {NEAR_PX:g} px and angles < {NEAR_DEG:g} deg apart, split by the "
             f"candidates' TCP heights (< {1000 * SAME_HEIGHT_M:g} mm or >= {1000 * APART_HEIGHT_M:g} mm apart); "
             f"far = centres >= {FAR_PX:g} px. The image-space grasp has no height: the evaluation derives it from "
             "the depth at the centre pixel, while the sampler's candidates span the object's height.", "",
             "| bodies | scenes | near: same label | near, same height | near, heights apart | far |",
             "|---|---|---|---|---|---|"]

    def cell(v):
        return "–" if not v or v["rate"] is None else f"{100 * v['rate']:.1f} % of {v['pairs']}"
    for name, b in locality.items():
        lines.append(f"| {name} | {b['scenes']} | " + " | ".join(cell(b.get(k)) for k in LOCALITY_KINDS) + " |")
    return lines + [""]


def _height_offset_markdown(by_height: dict | None) -> list:
    if not by_height:
        return []
    bins = list(next(iter(by_height.values())))
    lines = ["**Positive rate by the candidate's height above the evaluation's grasp** (TCP height of the "
             "trial minus the height the evaluation grasps at on the same pixel, mm)", "",
             "| bodies | " + " | ".join(bins) + " |", "|---|" + "---|" * len(bins)]
    for name, per_bin in by_height.items():
        cells = ["–" if not v["trials"] else f"{100 * v['positive'] / v['trials']:.1f} % of {v['trials']}"
                 for v in per_bin.values()]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines + [""]


def _grasp_choice_markdown(choice: dict | None) -> list:
    if not choice:
        return []
    lines = ["**How much does the choice of grasp decide?** Held shake acceleration (mean over the measured "
             "directions, 0 for a failed lift) of the training trials: the share of its variance within one "
             "object and modulus, i.e. the part a grasp ranking can act on; and the positive rate of a random "
             "candidate vs the best candidate of each scene (a perfect ranking of the sampler's candidates).", "",
             "| bodies | scenes | trials | variance within a scene | median SD within a scene (m/s^2) | "
             "scenes with both labels | random candidate positive | best candidate positive |",
             "|---|---|---|---|---|---|---|---|"]
    for name, c in choice.items():
        share = "–" if c["within_scene_share"] is None else f"{100 * c['within_scene_share']:.1f} %"
        lines.append(f"| {name} | {c['scenes']} | {c['trials']} | {share} | {c['median_within_scene_sd_mps2']:.1f} | "
                     f"{c['scenes_with_both_labels']} | {100 * c['random_candidate_positive']:.1f} % | "
                     f"{100 * c['best_candidate_positive']:.1f} % |")
    return lines + [""]

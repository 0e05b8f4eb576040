"""What any grasp choice could reach: the task run on the sampler's candidates instead of a model's.

For each object and modulus, the generator's antipodal sampler proposes
collision-free candidates (the same sampler and seeds as the training data,
object at the origin, yaw 0) and each runs under the evaluation's task
protocol, success judged by that protocol's rule (tasks.outcome_fields: under
defgraspsim the shake's mean, the every-direction result beside it). Two
figures per modulus bound a model's success:

- *random candidate*: the mean per-object fraction of candidates that
  succeed, i.e. what picking a candidate at random scores (no skill);
- *ceiling*: the fraction of objects where at least one candidate succeeds,
  i.e. the best a perfect ranking of these candidates could score.

A model below the random figure ranks worse than chance; a ceiling far below
a target says the simulator (grip force, friction, mass) and not the network
is what bounds the number.

The same candidates run at every modulus, which bounds what the stiffness
input can add: a depth-only model must pick one grasp per object whatever
its E (best case: the candidate that succeeds at the most moduli), a
stiffness-aware one may pick per modulus (best case: the ceiling). The gap
between the two is the largest advantage stiffness can give on these
candidates. Results are one fsync'd JSON line per trial
(resumable, like ``defgg-eval run``).
"""
from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

import pybullet

from defgg_ros.atomic import append_jsonl, read_jsonl, write_text_atomic
from defgg_ros.data.datagen import object_seed
from defgg_ros.evaluation.tasks import check_task, outcome_fields
from defgg_ros.sim import objects, world
from defgg_ros.sim.objects import simulation_shape
from defgg_ros.sim.sampler import sample_grasps
from defgg_ros.sim.trial import run_grasp_trial
from defgg_ros.sim.trial_settings import protocol_differences

RESULTS_FILE = "ceiling.jsonl"
TABLE_FILE = "ceiling.md"
COMMANDS_FILE = "ceiling_commands.txt"   # the commands that ran trials into the folder, for the report


def record_command(out_dir, command: str) -> None:
    path = Path(out_dir) / COMMANDS_FILE
    known = path.read_text(encoding="utf-8").splitlines() if path.is_file() else []
    if command not in known:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, "\n".join(known + [command]) + "\n")


def recorded_commands(out_dir) -> list:
    path = Path(out_dir) / COMMANDS_FILE
    return path.read_text(encoding="utf-8").splitlines() if path.is_file() else []


def trial_key(set_name: str, object_name: str, youngs_modulus_pa: float, candidate: int, task: str,
              max_tet_nodes: int, grasp_height: str = "contacts") -> str:
    key = f"{set_name}/{object_name}|E={youngs_modulus_pa:.3g}|c{candidate:03d}|{task}|nodes<={max_tet_nodes}"
    return key if grasp_height == "contacts" else f"{key}|height={grasp_height}"   # older keys unchanged


def plan_trials(shapes, moduli_pa, n_candidates: int, task: str, seed: int, max_tet_nodes: int | None = None,
                grasp_height: str = "contacts"):
    """[(key, shape, E, candidate index, WorldGrasp)] in candidate-major order (all objects' first one first).

    grasp_height: the sampler's rule (constants.GRASP_HEIGHT_RULES); "executor" puts the candidates at
    the height the evaluation executes a model's grasp at, so the bound is of comparable grasps."""
    check_task(task)
    if n_candidates < 1:
        raise ValueError(f"candidates per object must be >= 1, got {n_candidates}")
    per_shape = [(s, sample_grasps(s.surface(), object_seed(seed, s.name), keep=n_candidates,
                                   height_rule=grasp_height)) for s in shapes]
    trials = []
    for i in range(n_candidates):
        for shape, cands in per_shape:
            if i >= len(cands):
                continue
            for e in moduli_pa:
                sim_shape = simulation_shape(shape, e, max_tet_nodes)
                key = trial_key(shape.set_name, shape.name, e, i, task, sim_shape.max_tet_nodes, grasp_height)
                trials.append((key, sim_shape, e, i, cands[i].grasp))
    return trials


def run(out_dir, trials, task: str, settings, max_trials: int | None = None, progress=None,
        grasp_height: str = "contacts") -> int:
    """Simulate the trials not yet in OUT/ceiling.jsonl; returns how many ran."""
    path = Path(out_dir) / RESULTS_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    existing = read_jsonl(path)
    if protocol_differences(existing, settings.to_record(), task):
        raise ValueError(f"{path} holds trials of another protocol; run the ceiling into a new --out folder")
    heights = {r.get("grasp_height", "contacts") for r in existing}
    if heights - {grasp_height}:
        raise ValueError(f"{path} holds candidates at the {sorted(heights)[0]} height, not {grasp_height}; "
                         "run the ceiling into a new --out folder")
    done = {r["key"] for r in existing}
    pending = [t for t in trials if t[0] not in done][:max_trials]
    client = world.connect()
    try:
        for n, trial in enumerate(pending, 1):
            _run_one(path, client, trial, task, settings, grasp_height)
            if progress:
                progress(n, len(pending), trial[0])
    finally:
        pybullet.disconnect(client)
    return len(pending)


def _run_one(path, client, trial, task: str, settings, grasp_height: str) -> None:
    """One trial, appended to the results; a trial that raises is reported and left for the next run."""
    key, shape, e, i, grasp = trial
    try:
        out = run_grasp_trial(objects.ObjectSpec(shape, e), grasp, tests=(task,), settings=settings, client=client)
    except Exception as exc:  # noqa: BLE001 - not recorded, so a rerun retries it
        print(f"{key}: {type(exc).__name__}: {exc} (not recorded; a rerun retries it)", file=sys.stderr)
        return
    accels = out.shake_accels_mps2 if task == "shake" else out.twist_accels_radps2
    append_jsonl(path, {"key": key, "object": shape.name, "object_set": shape.set_name, "youngs_modulus_pa": e,
                        "candidate": i, "task": task, "status": out.status, "accels": accels,
                        **outcome_fields(task, out.status, accels, settings.protocol.name), "cpu_s": out.cpu_s,
                        "tet_nodes": [len(t.nodes_m) for t in shape.tet_parts],
                        "grasp_force_n": out.grasp_force_n, "trial_settings": settings.to_record(),
                        "grasp_height": grasp_height})


def summarize(records) -> list:
    """Rows per (task, E) and one "all" row per task: objects, trials, random-candidate and ceiling rates (%)."""
    by_view = defaultdict(list)
    for r in records:
        if r["success"] is not None:
            by_view[(r["task"], r["youngs_modulus_pa"], r["object"])].append(bool(r["success"]))
    rows = []
    for task in sorted({k[0] for k in by_view}):
        groups = defaultdict(list)
        for (t, e, _), outcomes in by_view.items():
            if t == task:
                groups[e].append(outcomes)
                groups["all"].append(outcomes)
        for e in sorted((k for k in groups if k != "all"), key=float) + ["all"]:
            views = groups[e]
            rows.append({"task": task, "youngs_modulus_pa": e, "objects": len(views),
                         "trials": sum(len(v) for v in views),
                         "random_pct": 100.0 * sum(sum(v) / len(v) for v in views) / len(views),
                         "ceiling_pct": 100.0 * sum(any(v) for v in views) / len(views)})
    return rows


def stiffness_advantage(records) -> list:
    """Per task: views and the best-case success (%) of one grasp for all moduli vs one grasp per modulus.

    Only candidates that ran at every modulus of their object count, so both
    choices pick from the same grasps.
    """
    outcome = defaultdict(dict)          # (task, object) -> {(candidate, E): success}
    for r in records:
        if r["success"] is not None:
            outcome[(r["task"], r["object"])][(r["candidate"], r["youngs_modulus_pa"])] = bool(r["success"])
    rows = defaultdict(lambda: {"views": 0, "one_for_all": 0, "per_modulus": 0})
    for (task, _), results in outcome.items():
        moduli = sorted({e for _, e in results})
        cands = [c for c in sorted({c for c, _ in results}) if all((c, e) in results for e in moduli)]
        if not cands:
            continue
        row = rows[task]
        row["views"] += len(moduli)
        row["one_for_all"] += max(sum(results[(c, e)] for e in moduli) for c in cands)
        row["per_modulus"] += sum(any(results[(c, e)] for c in cands) for e in moduli)
    return [{"task": t, "views": r["views"], "one_for_all_pct": 100.0 * r["one_for_all"] / r["views"],
             "per_modulus_pct": 100.0 * r["per_modulus"] / r["views"]} for t, r in sorted(rows.items()) if r["views"]]


def per_object_table(records) -> list:
    """Lines 'object | E | held/tried' for the Markdown file."""
    counts = defaultdict(lambda: [0, 0])
    for r in records:
        if r["success"] is not None:
            c = counts[(r["task"], r["object"], r["youngs_modulus_pa"])]
            c[0] += bool(r["success"])
            c[1] += 1
    return [f"| {t} | {o} | {e:.0e} | {h}/{n} |" for (t, o, e), (h, n) in sorted(counts.items())]


def write_table(out_dir, max_candidates: int | None = None) -> str:
    """OUT/ceiling.md over the first `max_candidates` candidates of each object (all if None)."""
    records = [r for r in read_jsonl(Path(out_dir) / RESULTS_FILE)
               if max_candidates is None or r["candidate"] < max_candidates]
    scope = "all candidates run" if max_candidates is None else f"candidates 0..{max_candidates - 1} of each object"
    lines = ["# Task success of the sampler's candidates (generated by defgg_ros.evaluation.ceiling)", "",
             f"Over {scope} (the sampler's seeded order, the same grasps at every modulus).", "",
             "| task | E (Pa) | objects | trials | random candidate (%) | ceiling: any candidate (%) |",
             "|---|---|---|---|---|---|"]
    for r in summarize(records):
        e = r["youngs_modulus_pa"]
        e_txt = "all stiffnesses" if e == "all" else f"{e:.0e}"
        lines.append(f"| {r['task']} | {e_txt} | {r['objects']} | {r['trials']} | {r['random_pct']:.1f} | "
                     f"{r['ceiling_pct']:.1f} |")
    lines += ["", "Largest advantage the stiffness input can give on these candidates (objects x moduli, only "
              "candidates run at every modulus): best case of one grasp per object for every E (all a depth-only "
              "model can do) vs one grasp per E.", "",
              "| task | views | one grasp for all E (%) | one grasp per E (%) | gap (points) |",
              "|---|---|---|---|---|"]
    for r in stiffness_advantage(records):
        lines.append(f"| {r['task']} | {r['views']} | {r['one_for_all_pct']:.1f} | {r['per_modulus_pct']:.1f} | "
                     f"{r['per_modulus_pct'] - r['one_for_all_pct']:.1f} |")
    lines += ["", "| task | object | E (Pa) | held / tried |", "|---|---|---|---|"] + per_object_table(records)
    text = "\n".join(lines) + "\n"
    write_text_atomic(Path(out_dir) / TABLE_FILE, text)
    return text

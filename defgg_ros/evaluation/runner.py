"""Run an evaluation: plan every view's grasps, simulate the trials, append the results.

The parent process renders the scenes and runs the networks (cheap), then
hands trials to worker processes (each with its own PyBullet DIRECT server)
and is the only writer of the results file: one fsync'd line per finished
trial, keys already present are skipped. A trial whose simulation is
identical to one already run (same object, materials, pose, world grasp,
task and settings; see jobs.sim_key) is not simulated again: its record
points at the original with ``reused_from``. A trial that raises is logged
to errors.jsonl instead of ending the run, and retried by the next run.
"""
from __future__ import annotations

import multiprocessing as mp
import time
from dataclasses import dataclass, field
from pathlib import Path

import pybullet as p
from tqdm import tqdm

from defgg_ros.atomic import append_jsonl, write_json_atomic
from defgg_ros.constants import SHAKE_ACCEL_LIMIT_MPS2, SHAKE_POSITIVE_THRESHOLD_MPS2, TWIST_ACCEL_LIMIT_RADPS2
from defgg_ros.data.format import TRIAL_ERRORS_FILE as ERRORS_FILE
from defgg_ros.evaluation import budget
from defgg_ros.evaluation import jobs as jobs_mod
from defgg_ros.evaluation import scene as scene_mod
from defgg_ros.evaluation.planning import plan_world_grasp
from defgg_ros.evaluation.sources import make_spec, shape_from_ref
from defgg_ros.evaluation.store import ResultStore
from defgg_ros.evaluation.tasks import STATUS_NO_GRASP, outcome_fields
from defgg_ros.sim import world
from defgg_ros.sim.protocol import DEFAULT_PROTOCOL, DEFGRASPSIM, TrialProtocol
from defgg_ros.sim.trial import WorldGrasp, run_grasp_trial
from defgg_ros.sim.trial_settings import TrialMotion, TrialSettings

# The twist's angular acceleration oscillates at this angular frequency (6.4 Hz) under an amplitude
# ramped to 500 rad/s^2 in 0.5 s, so the hand turns back and forth (at most ~0.3 rad) and spins at most
# ~500 / 40 = 12.5 rad/s. Accelerated one way (the generator's twist), the hand reaches 125 rad/s, and from
# ~25 rad/s the simulated hand came apart (palm up to 112 mm off its held pose, force-limited fingers
# forced open), so every grasp was "lost" at ~200 rad/s^2 whatever its grip (x15 force or torsional
# friction changed nothing). Oscillating, the palm stays on its pose (<= 0.1 mm) and rigid grasps hold
# or fail by their grip (bench/bench_twist_limit.py, bench/README.md). The real Panda's wrist turns at
# most 2.61 rad/s: the one-way spin tested nothing a cell could do.
EVAL_TWIST_OSCILLATION_RADPS = 40.0


def eval_trial_settings(protocol: TrialProtocol | str | dict | None = None) -> TrialSettings:
    """The tasks' settings: the generator's trial (same close, lift and ramp rates) with the shake ramped
    only to the task's 25 m/s^2 (0.25 s at the generator's 100 m/s^3), the twist oscillating
    (EVAL_TWIST_OSCILLATION_RADPS), and each task stopped at the first direction/axis that is not held (the
    grasp has failed; the rest is recorded as unmeasured). `protocol`: a TrialProtocol, a name or a stored
    protocol setting (None: the default)."""
    if protocol is None:
        protocol = DEFAULT_PROTOCOL
    elif not isinstance(protocol, TrialProtocol):
        protocol = TrialProtocol.from_setting({"protocol": protocol} if isinstance(protocol, str) else protocol)
    base = TrialSettings(protocol=protocol).with_fields(
        stop_direction_when_lost=True, stop_when_label_decided=False,
        twist_oscillation_radps=EVAL_TWIST_OSCILLATION_RADPS, twist_fail_below_radps2=TWIST_ACCEL_LIMIT_RADPS2)
    if protocol.name == DEFGRASPSIM:
        # the label's own criterion: every direction ramped to 50 m/s^2 until lost, until the mean and the
        # every-direction outcome are both certain (shake_stop_when_decided: exact for both), the twist as before
        return base.with_fields(shake_stop_when_decided=True)
    rate_mps3 = SHAKE_ACCEL_LIMIT_MPS2 / TrialMotion().shake_ramp_time_s
    return base.with_fields(shake_limit_mps2=SHAKE_POSITIVE_THRESHOLD_MPS2,
                            shake_ramp_time_s=SHAKE_POSITIVE_THRESHOLD_MPS2 / rate_mps3,
                            shake_fail_below_mps2=SHAKE_POSITIVE_THRESHOLD_MPS2)


def quick_trial_settings(protocol: TrialProtocol | str | dict | None = None) -> TrialSettings:
    """Smoke-test protocol: the same tasks with 5x faster ramps and a shorter lift. Never for reported numbers."""
    return eval_trial_settings(protocol).with_fields(lift_time_s=0.2, hold_time_s=0.05, shake_ramp_time_s=0.05,
                                                     twist_ramp_time_s=0.1)


@dataclass
class EvalPlan:
    """What to run: objects, models (name -> GraspPredictor), views, trials."""
    objects: list
    predictors: dict
    views: list
    grasps_per_view: int
    tasks: tuple
    seed: int = 0
    settings: TrialSettings = field(default_factory=eval_trial_settings)
    ranks: int | None = None       # run only grasp ranks < ranks now (budget); tables still expect grasps_per_view

    def model_shas(self) -> dict:
        return {name: pred.fingerprint for name, pred in self.predictors.items()}

    def jobs(self) -> list:
        jobs = jobs_mod.trial_jobs(self.views, self.model_shas(), self.grasps_per_view, self.tasks, self.seed)
        return jobs if self.ranks is None else [j for j in jobs if j.rank < self.ranks]


def plan_views(plan: EvalPlan, views, client: int, show_progress: bool = True) -> dict:
    """view -> list of PlannedGrasp (best first); each scene rendered once for all its views."""
    objects = {(o.set_name, o.name): o for o in plan.objects}
    by_scene = {}
    for v in views:
        by_scene.setdefault(v.scene_key, []).append(v)
    out = {}
    for scene_key, scene_views in tqdm(by_scene.items(), desc="planning", unit="scene", disable=not show_progress):
        obj = objects[scene_key[:2]]
        spec = obj.spec(scene_key[2], scene_key[3])
        images = scene_mod.render_scene(client, spec, scene_mod.object_yaw_rad(obj.name, plan.seed))
        for v in scene_views:
            moduli = scene_mod.input_moduli_image(images["youngs_modulus_pa"], images["object_mask"],
                                                  v.input_error_pct, v.input_override_pa)
            prediction = plan.predictors[v.model].predict(images["depth_m"], moduli, images["camera_k"],
                                                          images["object_mask"], top_k=plan.grasps_per_view)
            out[v] = [plan_world_grasp(c, i, images["base_T_camera"], images["camera_k"])
                      for i, c in enumerate(prediction.candidates)]
    return out


PLANS_FILE = "plans.json"


def write_plans(plan: EvalPlan, out_dir, show_progress: bool = True) -> tuple:
    """Render and plan every view (no simulation) into out_dir/plans.json; return its path and the budget of
    what a run would still simulate (budget.pending_budget)."""
    store = ResultStore(out_dir)
    client = world.connect()
    try:
        grasps = plan_views(plan, plan.views, client, show_progress)
        ready, to_run = pending_work(plan, store, client, show_progress, grasps)
    finally:
        p.disconnect(client)
    shas = plan.model_shas()
    entries = [{"view": v.to_json(), "model_sha": shas[v.model], "grasps": [g.to_json() for g in gs]}
               for v, gs in grasps.items()]
    path = Path(out_dir) / PLANS_FILE
    write_json_atomic(path, entries)
    return path, budget.pending_budget(ready, to_run, store.records())


def _base_record(job, plan: EvalPlan, obj, grasp) -> dict:
    v = job.view
    spec = obj.spec(v.youngs_modulus_pa, v.part0_youngs_modulus_pa)
    return {
        "key": job.key, "experiment": v.experiment, "model": v.model, "model_sha": plan.model_shas()[v.model],
        "uses_stiffness": bool(plan.predictors[v.model].uses_stiffness),
        "object": v.object_name, "object_set": v.object_set, "youngs_modulus_pa": v.youngs_modulus_pa,
        "part_moduli_pa": spec.part_moduli_pa(), "input": v.input_label, "input_error_pct": v.input_error_pct,
        "input_override_pa": v.input_override_pa, "rank": job.rank, "task": job.task, "seed": plan.seed,
        "object_yaw_rad": scene_mod.object_yaw_rad(v.object_name, plan.seed),
        "grasp": None if grasp is None else grasp.to_json(),
        "trial_settings": plan.settings.to_record(),
    }


def _trial_payload(obj, record: dict) -> dict:
    g = record["grasp"]
    return {"ref": obj.ref, "youngs_modulus_pa": record["youngs_modulus_pa"],
            "part0": record["part_moduli_pa"][0] if len(record["part_moduli_pa"]) > 1 else None,
            "yaw": record["object_yaw_rad"], "grasp": (g["position_m"], g["yaw_rad"], g["width_m"]),
            "task": record["task"], "settings": record["trial_settings"]}


_WORKER_CLIENT = None


def run_trial_payload(payload: dict) -> dict:
    """Worker side: one real PyBullet trial. Returns the outcome fields of a record."""
    global _WORKER_CLIENT
    if _WORKER_CLIENT is None:
        _WORKER_CLIENT = world.connect()
    spec = make_spec(shape_from_ref(payload["ref"]), payload["youngs_modulus_pa"], payload["part0"])
    grasp = WorldGrasp(tuple(payload["grasp"][0]), payload["grasp"][1], payload["grasp"][2])
    task = payload["task"]
    wall0 = time.monotonic()
    out = run_grasp_trial(spec, grasp, tests=(task,), settings=TrialSettings.from_record(payload["settings"]),
                          client=_WORKER_CLIENT, object_yaw_rad=payload["yaw"])
    accels = out.shake_accels_mps2 if task == "shake" else out.twist_accels_radps2
    return {"status": out.status, "accels": accels,
            "measured": out.shake_measured if task == "shake" else out.twist_measured,
            **outcome_fields(task, out.status, accels, payload["settings"].get("protocol", "legacy")),
            "grasp_force_n": out.grasp_force_n,
            "cpu_s": out.cpu_s, "wall_s": time.monotonic() - wall0, "sim_steps": out.sim_steps,
            "time_step_s": out.sim.get("time_step_s"), "soft": out.sim.get("soft"), "note": out.note}


def run_trial_payload_guarded(payload: dict) -> dict:
    """run_trial_payload, with an exception returned as {"error": ...}: one bad trial must not end the run."""
    global _WORKER_CLIENT
    try:
        return run_trial_payload(payload)
    except Exception as exc:  # noqa: BLE001 - recorded in ERRORS_FILE and retried by the next run
        if _WORKER_CLIENT is not None and p.isConnected(_WORKER_CLIENT):
            p.disconnect(_WORKER_CLIENT)
        _WORKER_CLIENT = None   # the next trial starts on a fresh PyBullet server
        return {"error": f"{type(exc).__name__}: {exc}"}


def pending_work(plan: EvalPlan, store: ResultStore, client: int, show_progress: bool = True,
                 grasps: dict | None = None):
    """(records ready to append now, {sim_key: [base records]} to simulate) for unfinished trials.
    grasps: the views' planned grasps when already known (plan_views), else they are planned here."""
    todo = [j for j in plan.jobs() if j.key not in store]
    views = list(dict.fromkeys(j.view for j in todo))
    if grasps is None:
        grasps = plan_views(plan, views, client, show_progress) if views else {}
    objects = {(o.set_name, o.name): o for o in plan.objects}
    ready, to_run, done_sims = [], {}, store.by_sim_key()
    settings = plan.settings.to_record()
    for job in todo:
        obj = objects[(job.view.object_set, job.view.object_name)]
        planned = grasps[job.view]
        grasp = planned[job.rank] if job.rank < len(planned) else None
        rec = _base_record(job, plan, obj, grasp)
        if grasp is None:
            protocol = settings.get("protocol", "legacy")
            ready.append({**rec, "status": STATUS_NO_GRASP, **outcome_fields(job.task, STATUS_NO_GRASP, None, protocol),
                          "accels": None, "sim_key": None,
                          "reused_from": None, "note": f"model proposed only {len(planned)} grasps"})
            continue
        key = jobs_mod.sim_key(obj.set_name, obj.name, rec["part_moduli_pa"], rec["object_yaw_rad"],
                               grasp.world_grasp(), job.task, settings)
        rec["sim_key"] = key
        if key in done_sims:
            ready.append(_reused(rec, done_sims[key]))
        else:
            to_run.setdefault(key, []).append((rec, obj))
    return ready, to_run


_OUTCOME_FIELDS = ("status", "accels", "measured", "success", "success_every_direction", "grasp_force_n", "cpu_s",
                   "wall_s", "sim_steps", "time_step_s", "soft", "note")


def _reused(rec: dict, original: dict) -> dict:
    return {**rec, **{k: original[k] for k in _OUTCOME_FIELDS if k in original}, "reused_from": original["key"]}


def run_evaluation(plan: EvalPlan, out_dir, workers: int = 1, show_progress: bool = True,
                   max_trials: int | None = None, on_progress=None) -> dict:
    """Run every unfinished trial of `plan` into out_dir/trials.jsonl. Returns counts.

    on_progress(n_simulated) is called after each stored trial (e.g. to rewrite the tables).
    """
    store = ResultStore(out_dir)
    client = world.connect()
    try:
        ready, to_run = pending_work(plan, store, client, show_progress)
    finally:
        p.disconnect(client)
    for rec in ready:
        store.append(rec)
    groups = list(to_run.values())
    if max_trials is not None:
        groups = groups[:max_trials]
    simulated = 0
    bar = tqdm(total=len(groups), desc="trials", unit="trial", disable=not show_progress, smoothing=0.05)
    payloads = [_trial_payload(g[0][1], g[0][0]) for g in groups]
    results = _map(payloads, workers)
    errors = 0
    for index, outcome in results:
        first, *rest = [rec for rec, _ in groups[index]]
        if "error" in outcome:   # not stored as a trial: the next run retries it
            errors += 1
            append_jsonl(Path(out_dir) / ERRORS_FILE, {"key": first["key"], "error": outcome["error"]})
            bar.write(f"trial {first['key']} raised {outcome['error']} (in {ERRORS_FILE})")
            bar.update(1)
            continue
        done = {**first, **outcome, "reused_from": None}
        store.append(done)
        for rec in rest:
            store.append(_reused(rec, done))
        simulated += 1
        bar.update(1)
        bar.set_postfix(ok=outcome["status"], cpu=f"{outcome['cpu_s']:.0f}s")
        if on_progress is not None:
            on_progress(simulated)
    bar.close()
    return {"reused_or_no_grasp": len(ready), "simulated": simulated, "errors": errors,
            "left": len(to_run) - simulated, "stored": len(store)}


def _map(payloads, workers: int):
    """Yield (index, outcome) as trials finish; in-process when workers <= 1 (easier to debug, no spawn)."""
    if workers <= 1:
        for i, payload in enumerate(payloads):
            yield i, run_trial_payload_guarded(payload)
        return
    ctx = mp.get_context("spawn")   # fresh interpreters: no PyBullet or torch state inherited
    with ctx.Pool(workers) as pool:
        yield from pool.imap_unordered(_indexed, list(enumerate(payloads)), chunksize=1)


def _indexed(item):
    index, payload = item
    return index, run_trial_payload_guarded(payload)

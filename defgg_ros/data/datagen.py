"""The dataset generator: plan (scenes, candidates, trials), run trials in parallel, write.

Only the main process writes (DatasetWriter appends one fsync'd JSON line per
finished trial), workers only simulate; so a killed run loses only the
trials in flight and a rerun skips every trial id already on disk.

Order: trials run in passes. Pass k runs candidates [k*pass_size,
(k+1)*pass_size) of EVERY scene (object x E) before pass k+1 starts, so a
partial dataset covers all objects and moduli evenly and can be trained on
at any time (use a small --pass-size for a slow soft run: pass size 1 is one
trial per scene per pass, 120 trials for the training set).
"""
from __future__ import annotations

import hashlib
import json
import math
import multiprocessing as mp
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pybullet as p
from tqdm import tqdm

from defgg_ros.atomic import append_jsonl, only_writer, write_json_atomic
from defgg_ros.constants import GRASP_CANDIDATES_PER_OBJECT, TRAINING_YOUNGS_MODULI_PA
from defgg_ros.data.card import write_card
from defgg_ros.data.format import TRIAL_ERRORS_FILE as ERRORS_FILE
from defgg_ros.data.format import (
    DatasetError,
    DatasetWriter,
    GraspRect,
    Scene,
    TrialRecord,
    check_header,
    scene_id_for,
)
from defgg_ros.data.header import effective_trial_settings, recorded_grasp_height, recorded_trial_settings
from defgg_ros.sim import camera, objects, world
from defgg_ros.sim.sampler import SAMPLER_VERSION, grasp_rect, sample_grasps
from defgg_ros.sim.trial import TrialSettings, WorldGrasp, run_grasp_trial
from defgg_ros.sim.trial_settings import comparable_protocol

LOCK_FILE = ".datagen.lock"     # held while a run writes: two runs into one folder would write each trial twice
CANDIDATE_FILE_VERSION = 1
# The coarse FEM mesh measured against the shipped one (up to 220 nodes):
# 6-12x cheaper soft trials, but 5 of 27 soft labels flipped (bench/README.md,
# "Dataset generation cost"); at most 80 nodes, 1.6x cheaper but 3 of 55 labels changed (94.5 %,
# 2026-11-25), so the generator's default stays the shipped mesh.
COARSE_SIM_MAX_TET_NODES = 50
# Trials that raised (not stored as trials, so the next run retries them), one JSON line each.


@dataclass
class DatagenConfig:
    out: Path
    object_set: str = "train"
    objects: tuple = ()                 # restrict to these names (empty = whole set)
    moduli_pa: tuple = TRAINING_YOUNGS_MODULI_PA
    grasps_per_scene: int = 40
    pass_size: int = 8
    n_candidates: int = GRASP_CANDIDATES_PER_OBJECT
    seed: int = 0
    workers: int = 1
    ray_address: str | None = None
    settings: dict = field(default_factory=dict)   # TrialSettings overrides
    sim_max_tet_nodes: int | None = None           # None: simulate on the shipped mesh
    # Tests each trial runs; the label reads the shake. ("shake", "twist") also records the twist
    # (the signal pilots' try of a twist-aware label, data/signal.py LABEL_RULES).
    tests: tuple = ("shake",)
    # constants.GRASP_HEIGHT_RULES; executor: each label is of the grasp the evaluation and the cell perform
    # (docs/archive/notes_height.md). A resumed dataset keeps its own (resolve_grasp_height).
    grasp_height: str = "executor"
    card_every: int = 20                           # regenerate the card every N finished trials

    def header(self) -> dict:
        d = asdict(self)
        if tuple(self.tests) == ("shake",):
            d.pop("tests")          # headers before the option exist without it: keep them comparable
        else:
            d["tests"] = list(self.tests)
        d.pop("out")
        d.pop("workers")
        d.pop("ray_address")
        d.pop("card_every")
        d.pop("pass_size")   # the order trials run in, not a property of the data
        d["moduli_pa"] = list(self.moduli_pa)
        d["objects"] = list(self.objects)
        d["trial_settings"] = effective_trial_settings(self.settings)
        return d


@dataclass(frozen=True)
class TrialJob:
    trial_id: str
    scene_id: str
    object_name: str
    youngs_modulus_pa: float
    candidate_index: int
    grasp: dict              # WorldGrasp fields
    rect: dict               # GraspRect fields
    seed: int
    settings: dict
    sim_max_tet_nodes: int | None = None
    tests: tuple = ("shake",)

    def to_dict(self) -> dict:
        return asdict(self)


def object_seed(seed: int, name: str) -> int:
    return int(hashlib.sha256(f"{seed}:{name}".encode()).hexdigest()[:8], 16)


def trial_id_for(scene_id: str, candidate_index: int) -> str:
    return f"{scene_id}__g{candidate_index:03d}"


def load_or_sample_candidates(root: Path, shape, cfg: DatagenConfig) -> list:
    """Collision-free antipodal candidates of one object, cached in <root>/candidates/<name>.json."""
    path = root / "candidates" / f"{shape.name}.json"
    seed = object_seed(cfg.seed, shape.name)
    key = {"version": CANDIDATE_FILE_VERSION, "sampler": SAMPLER_VERSION, "seed": seed,
           "n_candidates": cfg.n_candidates, "keep": cfg.grasps_per_scene,
           "mesh": [t.content_hash for t in shape.tet_parts]}
    if cfg.grasp_height != "contacts":      # the key of the datasets before the option stays as it was
        key["grasp_height"] = cfg.grasp_height
    if path.exists():
        cached = json.loads(path.read_text(encoding="utf-8"))
        if cached.get("key") == key:
            return cached["candidates"]
    found = sample_grasps(shape.surface(), seed, cfg.n_candidates, keep=cfg.grasps_per_scene,
                          height_rule=cfg.grasp_height, fill_short=True)
    cands = [{"grasp": grasp_fields(c.grasp), "rect": asdict(grasp_rect(c.grasp))} for c in found]
    write_json_atomic(path, {"key": key, "candidates": cands})
    return cands


def grasp_fields(grasp: WorldGrasp) -> dict:
    """A WorldGrasp as a candidate file and a TrialJob hold it; the opening only when the sampler set one
    (the files and jobs before sampler 4 have none)."""
    fields = {"position_m": list(grasp.position_m), "yaw_rad": grasp.yaw_rad, "width_m": grasp.width_m}
    if grasp.opening_m is not None:
        fields["opening_m"] = grasp.opening_m
    return fields


def world_grasp(fields: dict) -> WorldGrasp:
    return WorldGrasp(tuple(fields["position_m"]), fields["yaw_rad"], fields["width_m"], fields.get("opening_m"))


def render_scene(shape, youngs_modulus_pa: float, seed: int) -> Scene:
    """Render depth, stiffness and mask of the object resting at the origin (yaw 0)."""
    client = world.connect()
    try:
        spec = objects.ObjectSpec(shape, youngs_modulus_pa)
        world.create_world(client, spec.part_moduli_pa())
        loaded = objects.load_object(client, spec)
        images = camera.render_object_images(client, loaded)
    finally:
        p.disconnect(client)
    meta = {"object_name": shape.name, "object_set": shape.set_name, "youngs_modulus_pa": youngs_modulus_pa,
            "poisson_ratio": spec.poisson_ratio, "seed": seed, "soft": [pt.soft for pt in loaded.parts],
            "mass_kg": loaded.mass_kg, "tet_nodes": [len(t.nodes_m) for t in shape.tet_parts],
            "mesh_hash": [t.content_hash for t in shape.tet_parts], "object_pose": "origin, yaw 0"}
    return Scene(scene_id_for(shape.name, youngs_modulus_pa), meta=meta, **images)


def selected_shapes(cfg: DatagenConfig) -> list:
    """The object set's shapes the config names (all of them when it names none); DatasetError for a name
    the set does not have."""
    shapes = [s for s in objects.object_set(cfg.object_set) if not cfg.objects or s.name in cfg.objects]
    missing = set(cfg.objects) - {s.name for s in shapes}
    if missing:
        raise DatasetError(f"objects not in set {cfg.object_set!r}: {sorted(missing)}; its objects: "
                           f"{', '.join(s.name for s in objects.object_set(cfg.object_set))}")
    return shapes


def plan(cfg: DatagenConfig, writer: DatasetWriter, progress=None) -> list:
    """Render missing scenes, sample candidates, and return pending TrialJobs in pass order."""
    return pass_order(cfg, plan_scenes(cfg, writer, progress))


def plan_scenes(cfg: DatagenConfig, writer: DatasetWriter, progress=None) -> dict:
    """Render missing scenes and sample candidates: {(object, E): (scene id, candidates, finished trial ids)}."""
    per_scene = {}
    for shape in selected_shapes(cfg):
        cands = load_or_sample_candidates(writer.root, shape, cfg)
        for e in cfg.moduli_pa:
            sid = scene_id_for(shape.name, e)
            if not writer.has_scene(sid):
                writer.write_scene(render_scene(shape, e, cfg.seed))
            done = writer.finished_trial_ids(sid)
            per_scene[(shape.name, e)] = (sid, cands, done)
        if progress:
            progress(shape.name)
    return per_scene


def pass_order(cfg: DatagenConfig, per_scene: dict) -> list:
    """The scenes' pending TrialJobs in pass order (pass_size candidates of every scene per pass)."""
    jobs = []
    n_passes = math.ceil(cfg.grasps_per_scene / cfg.pass_size)
    for k in range(n_passes):
        for (name, e), (sid, cands, done) in per_scene.items():
            for i in range(k * cfg.pass_size, min((k + 1) * cfg.pass_size, len(cands), cfg.grasps_per_scene)):
                tid = trial_id_for(sid, i)
                if tid not in done:
                    jobs.append(TrialJob(tid, sid, name, e, i, cands[i]["grasp"], cands[i]["rect"],
                                         object_seed(cfg.seed, tid), cfg.settings, cfg.sim_max_tet_nodes,
                                         tuple(cfg.tests)))
    return jobs


def run_trial_job(job: dict) -> dict:
    """Simulate one trial (worker side); returns a TrialRecord as JSON."""
    job = TrialJob(**job)
    settings = TrialSettings.fast().with_fields(**job.settings)
    # Images and candidates come from the shipped mesh; only the FEM may run on a coarser one.
    shape = objects.simulation_shape(objects.get_shape(job.object_name), job.youngs_modulus_pa,
                                     job.sim_max_tet_nodes)
    spec = objects.ObjectSpec(shape, job.youngs_modulus_pa)
    grasp = world_grasp(job.grasp)
    outcome = run_grasp_trial(spec, grasp, tuple(job.tests), settings, client=_worker_client(world))
    sim = dict(outcome.sim, shake_measured=outcome.shake_measured, sim_steps=outcome.sim_steps,
               tet_nodes=[len(t.nodes_m) for t in shape.tet_parts])
    if grasp.opening_m is not None:     # records without it opened to width + OPENING_CLEARANCE_M
        sim["finger_opening_m"] = grasp.opening_m
    record = TrialRecord(
        trial_id=job.trial_id, scene_id=job.scene_id, object_name=job.object_name,
        youngs_modulus_pa=job.youngs_modulus_pa, candidate_index=job.candidate_index,
        rect=GraspRect(**job.rect), position_m=list(grasp.position_m), yaw_rad=grasp.yaw_rad,
        width_m=grasp.width_m, status=outcome.status, shake_accels_mps2=outcome.shake_accels_mps2,
        twist_accels_radps2=outcome.twist_accels_radps2,
        grasp_force_n=outcome.grasp_force_n, seed=job.seed, cpu_s=outcome.cpu_s, sim=sim, note=outcome.note)
    return record.to_json()


def job_from_record(record: TrialRecord, sim_max_tet_nodes: int | None = None) -> dict:
    """The job (run_trial_job's argument) that reruns a stored trial under its recorded settings (those it
    predates at the value they had then, TrialSettings.from_record) on the mesh the dataset simulated."""
    tests = ("shake", "twist") if record.twist_accels_radps2 is not None else ("shake",)
    grasp = {"position_m": record.position_m, "yaw_rad": record.yaw_rad, "width_m": record.width_m}
    if record.sim.get("finger_opening_m") is not None:
        grasp["opening_m"] = record.sim["finger_opening_m"]
    settings = TrialSettings.from_record(record.sim.get("settings") or {}).to_record()
    return TrialJob(record.trial_id, record.scene_id, record.object_name, record.youngs_modulus_pa,
                    record.candidate_index, grasp, asdict(record.rect), record.seed, settings, sim_max_tet_nodes,
                    tests).to_dict()


def run_trial_job_guarded(job: dict) -> dict:
    """run_trial_job, with an exception returned as {"trial_id", "error"}: one bad trial must not end the run."""
    try:
        return run_trial_job(job)
    except Exception as exc:  # noqa: BLE001 - recorded in ERRORS_FILE and retried by the next run
        return {"trial_id": job["trial_id"], "error": f"{type(exc).__name__}: {exc}"}


_CLIENT = None


def _worker_client(world):
    """One DIRECT physics server per worker process, reused by its trials."""
    global _CLIENT
    if _CLIENT is None:
        _CLIENT = world.connect()
    return _CLIENT


def _json_safe(x):
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_json_safe(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


def execute(jobs: list, cfg: DatagenConfig, on_result) -> None:
    """Run jobs locally (process pool) or on Ray; call on_result(record_json) in the main process."""
    payloads = [j.to_dict() for j in jobs]
    if cfg.ray_address:
        _execute_ray(payloads, cfg, on_result)
    elif cfg.workers <= 1:
        for job in payloads:
            on_result(run_trial_job_guarded(job))
    else:
        with mp.get_context("spawn").Pool(cfg.workers, maxtasksperchild=50) as pool:
            for result in pool.imap_unordered(run_trial_job_guarded, payloads, chunksize=1):
                on_result(result)


def _execute_ray(payloads, cfg, on_result) -> None:
    import ray  # an optional dependency: only a --ray run needs it

    started_here = not ray.is_initialized()
    if started_here:
        if cfg.ray_address == "local":
            ray.init(num_cpus=max(1, cfg.workers), include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=cfg.ray_address, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(run_trial_job_guarded)
    window = max(2, 2 * cfg.workers)
    pending, queue = [], list(payloads)
    try:
        while queue or pending:
            while queue and len(pending) < window:
                pending.append(remote.remote(queue.pop(0)))
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                on_result(ray.get(ref))
    finally:
        if started_here:
            ray.shutdown()


def recorded_generator(out) -> dict | None:
    """The generator section of the dataset at `out`, None when there is none yet."""
    return check_header(out).get("generator", {}) if (Path(out) / "dataset.json").exists() else None


def resolve_grasp_height(out, requested: str | None) -> str:
    """The candidates' height rule of a run: as requested; else the dataset's own when resuming one,
    else executor (DatagenConfig's default)."""
    if requested is not None:
        return requested
    stored = recorded_generator(out)
    return DatagenConfig.grasp_height if stored is None else recorded_grasp_height(stored)


def check_resumable(cfg: DatagenConfig) -> None:
    """A resumed dataset keeps its FEM mesh and trial protocol (labels depend on both)."""
    stored = check_header(cfg.out).get("generator", {})
    mesh = stored.get("sim_max_tet_nodes")
    if mesh != cfg.sim_max_tet_nodes:
        flag = f"--sim-max-tet-nodes {mesh or 0}"
        raise DatasetError(f"{cfg.out} was generated with {flag}; resume it with the same FEM mesh "
                           f"(got {cfg.sim_max_tet_nodes or 0}; 0 = the shipped mesh) or write a new dataset")
    height = recorded_grasp_height(stored)
    if height != cfg.grasp_height:
        raise DatasetError(f"{cfg.out} was generated with --grasp-height {height}; resume it with the same rule "
                           f"(got {cfg.grasp_height}) or write a new dataset")
    for key, flag in (("seed", "--seed"), ("n_candidates", "--candidates"), ("object_set", "--object-set")):
        if key in stored and stored[key] != getattr(cfg, key):   # the pending candidates would come from another
            raise DatasetError(f"{cfg.out} was generated with {flag} {stored[key]}; resume it with the same "
                               f"value (got {getattr(cfg, key)}) or write a new dataset")
    protocol = comparable_protocol(recorded_trial_settings(stored).to_record())
    current = comparable_protocol(effective_trial_settings(cfg.settings))
    if protocol != current:
        needed = {k: v for k, v in protocol.items() if current.get(k) != v}
        raise DatasetError(f"{cfg.out} was generated with another trial protocol; resume it with "
                           f"--settings '{json.dumps({**cfg.settings, **needed})}' or write a new dataset")


def generate(cfg: DatagenConfig, progress_bar=True) -> dict:
    """Plan + execute; returns counts. Safe to rerun: finished trials are skipped. One run per folder at a time."""
    selected_shapes(cfg)           # a bad object name is refused before anything is written
    Path(cfg.out).mkdir(parents=True, exist_ok=True)
    busy = DatasetError(f"another defgg-datagen run is writing {cfg.out}; let it finish or stop it")
    with only_writer(Path(cfg.out) / LOCK_FILE, busy):
        return _generate(cfg, progress_bar)


def _generate(cfg: DatagenConfig, progress_bar: bool) -> dict:
    writer = DatasetWriter(cfg.out, cfg.header())
    check_resumable(cfg)
    t_plan = tqdm(desc="planning (objects)", unit="obj", disable=not progress_bar)
    per_scene = plan_scenes(cfg, writer, progress=lambda name: t_plan.update(1))
    jobs = pass_order(cfg, per_scene)
    t_plan.close()
    counts = {"planned_pending": len(jobs), "done": 0, "labelled": 0, "failed": 0, "errors": 0}
    finished_before = sum(len(done) for _, _, done in per_scene.values())
    bar = tqdm(total=len(jobs), desc="trials", unit="trial", disable=not progress_bar, smoothing=0.05)
    t0 = time.monotonic()

    def on_result(record_json):
        if "error" in record_json:  # not written as a trial: the next run retries it
            append_jsonl(cfg.out / ERRORS_FILE, record_json)
            counts["errors"] += 1
            bar.write(f"trial {record_json['trial_id']} raised {record_json['error']} (in {ERRORS_FILE})")
            return
        record = TrialRecord.from_json(_json_safe(record_json))
        writer.append_trial(record)
        counts["done"] += 1
        counts["labelled" if record.label is not None else "failed"] += 1
        per_hour = counts["done"] / max(1e-9, time.monotonic() - t0) * 3600
        bar.set_postfix(trials_per_h=f"{per_hour:.0f}", labelled=counts["labelled"], failed=counts["failed"])
        bar.update(1)
        if counts["done"] % cfg.card_every == 0:
            write_card(cfg.out, cfg)
            if not progress_bar:   # a log (nohup, CI) still shows how far the run is, a line per card
                left_h = (len(jobs) - counts["done"]) / max(per_hour, 1e-9)
                in_dataset, planned = finished_before + counts["done"], finished_before + len(jobs)
                print(f"defgg-datagen: dataset {in_dataset} of {planned} trials ({100 * in_dataset / planned:.1f} %); "
                      f"this run {counts['done']} of {len(jobs)} pending trials done, {per_hour:.0f} trials/h, "
                      f"~{left_h:.1f} h left; card: {cfg.out / 'card.md'}", flush=True)

    try:
        execute(jobs, cfg, on_result)
    finally:
        bar.close()
        write_card(cfg.out, cfg)
    return counts

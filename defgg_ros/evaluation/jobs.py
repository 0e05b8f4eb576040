"""The trial list of an evaluation: which scenes each model sees and which trials follow.

Three experiments share one results file:

- ``main``: every model x object x table modulus, true stiffness input;
- ``sensitivity``: stiffness-aware models only, the true moduli scaled by
  (1 + error) in the paper's steps (0 % is the main run's cell);
- ``multimaterial``: each two-part object with a soft part 1, planned once
  with the correct per-part stiffness and once assuming it is rigid.

A *view* is what one model is shown (object, true moduli, stiffness input);
it yields the model's ranked grasps, and each (grasp rank, task) is one trial
with a stable key. Trials are ordered rank-major so a budgeted run that is
stopped early covers every cell evenly.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass

from defgg_ros.evaluation.tasks import check_task

EXPERIMENTS = ("main", "sensitivity", "multimaterial")
# Paper, Sec. "Sensitivity Analysis" (figure): error of the stiffness input in %.
SENSITIVITY_ERRORS_PCT = (-60, -45, -30, -15, -5, 0, 5, 15, 30, 45, 60)
# Multi-material experiment: the soft part's true modulus and the "rigid" assumption.
MULTIMATERIAL_SOFT_PART_PA = (2e4, 2e5)
RIGID_ASSUMPTION_PA = 2e9


@dataclass(frozen=True)
class View:
    """One model's look at one object: the true materials and the stiffness input it is given."""
    experiment: str
    model: str
    object_name: str
    object_set: str
    youngs_modulus_pa: float            # the table row: part 1's modulus for two-part objects
    part0_youngs_modulus_pa: float | None = None
    input_error_pct: float = 0.0
    input_override_pa: float | None = None

    @property
    def input_label(self) -> str:
        if self.input_override_pa is not None:
            return f"assume{self.input_override_pa:.0e}"
        return "true" if self.input_error_pct == 0 else f"err{self.input_error_pct:+g}%"

    @property
    def scene_key(self) -> tuple:
        """Views with the same scene key render the same images (truth, not input)."""
        return (self.object_set, self.object_name, self.youngs_modulus_pa, self.part0_youngs_modulus_pa)

    def trial_key(self, model_sha: str, rank: int, task: str, seed: int) -> str:
        part0 = "" if self.part0_youngs_modulus_pa is None else f"|part0={self.part0_youngs_modulus_pa:.3g}"
        return (f"{self.experiment}|{self.model}@{model_sha}|{self.object_set}/{self.object_name}"
                f"|E={self.youngs_modulus_pa:.3g}{part0}|in={self.input_label}|seed={seed}|r{rank}|{task}")

    def to_json(self) -> dict:
        return asdict(self)


def main_views(models, eval_objects) -> list:
    return [View("main", m, o.name, o.set_name, e) for o in eval_objects for e in o.moduli_pa for m in models]


def sensitivity_views(stiffness_models, eval_objects, errors_pct=SENSITIVITY_ERRORS_PCT) -> list:
    """Views with a wrong stiffness input; the 0 % error is the main experiment's view."""
    return [View("sensitivity", m, o.name, o.set_name, e, input_error_pct=float(err))
            for o in eval_objects for e in o.moduli_pa for m in stiffness_models for err in errors_pct if err != 0]


def multimaterial_views(models, eval_objects, soft_part_pa=MULTIMATERIAL_SOFT_PART_PA) -> list:
    """Two-part objects: correct per-part input vs every pixel assumed rigid."""
    views = []
    for o in eval_objects:
        if not o.multi_material:
            continue
        for e in soft_part_pa:
            for m in models:
                for override in (None, RIGID_ASSUMPTION_PA):
                    views.append(View("multimaterial", m, o.name, o.set_name, e,
                                      part0_youngs_modulus_pa=RIGID_ASSUMPTION_PA, input_override_pa=override))
    return views


@dataclass(frozen=True)
class TrialJob:
    """One simulator trial: a view's grasp of a given rank under one task."""
    key: str
    view: View
    rank: int
    task: str


def trial_jobs(views, model_shas: dict, grasps_per_view: int, tasks, seed: int) -> list:
    """Rank-major list of trials (all views' best grasp first, then the second best, ...)."""
    for t in tasks:
        check_task(t)
    if grasps_per_view < 1:
        raise ValueError(f"grasps per object must be >= 1, got {grasps_per_view}")
    jobs = []
    for experiment in EXPERIMENTS:
        exp_views = [v for v in views if v.experiment == experiment]
        # The paper's sensitivity analysis is on the shake task only.
        exp_tasks = [t for t in tasks if t == "shake"] if experiment == "sensitivity" else tasks
        for rank in range(grasps_per_view):
            for task in exp_tasks:
                for v in exp_views:
                    jobs.append(TrialJob(v.trial_key(model_shas[v.model], rank, task, seed), v, rank, task))
    return jobs


def sim_key(object_set: str, object_name: str, part_moduli_pa, object_yaw_rad: float, world_grasp, task: str,
            settings: dict) -> str:
    """Identity of a simulation: trials with the same key are the same deterministic run.

    Lets a sensitivity view whose grasp did not move reuse the main run's
    trial instead of simulating it again (recorded as ``reused_from``).
    """
    payload = {
        "object": f"{object_set}/{object_name}",
        "moduli": [float(f"{e:.6g}") for e in part_moduli_pa],
        "yaw": round(float(object_yaw_rad), 6),
        "grasp": [round(float(c), 5) for c in world_grasp.position_m] + [round(float(world_grasp.yaw_rad), 5),
                                                                          round(float(world_grasp.width_m), 5)],
        "task": task,
        "settings": settings,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:20]

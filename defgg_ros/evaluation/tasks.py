"""The two evaluation tasks and what counts as success (paper, Sec. "Grasping in Simulation").

A grasp is successful when the object stays in the gripper during the whole
procedure and withstands the task's acceleration limit:

- shake: linear acceleration along each of the 16 directions, success if
  the object is held at SHAKE_POSITIVE_THRESHOLD_MPS2 (25 m/s^2) in EVERY
  direction (the paper's "withstand the linear acceleration limit of 25
  m/s^2"; the training label used the mean instead, which is weaker);
- twist: angular acceleration about each of the six hand axes (oscillating,
  runner.EVAL_TWIST_OSCILLATION_RADPS), success if the object is held up to
  TWIST_ACCEL_LIMIT_RADPS2 (500 rad/s^2) amplitude about every axis.

The training label is weaker (mean held acceleration over the directions
>= 25 m/s^2 with a ramp to 50 m/s^2); the task needs every direction, so the
legacy evaluation ramps to 25 m/s^2 and stops at the first direction that fails
(runner.eval_trial_settings).

Under the defgraspsim protocol the shake's success is the label's own criterion
(SUCCESS_RULES "mean": held through the pickup, mean held acceleration over the
16 directions >= 25 m/s^2, each ramped to 50 m/s^2) and the every-direction rate
is the second column (record field "success_every_direction").

A lift failure is a failed grasp. Simulation failures (explosion, time-out)
are not grasp outcomes: ``success`` is None and tables count them apart.
"""
from __future__ import annotations

from defgg_ros.constants import HELD_LIMIT_TOLERANCE, SHAKE_POSITIVE_THRESHOLD_MPS2, TWIST_ACCEL_LIMIT_RADPS2
from defgg_ros.data.format import STATUS_LIFT_FAILED, STATUS_OK

TASKS = ("shake", "twist")
# "every": held at the limit in every direction/axis; "mean": the shake label's rule (mean held >= 25 m/s^2).
SUCCESS_RULES = ("every", "mean")
# The model proposed fewer grasps than asked: never simulated; the tables count it apart (tables.Cell: no grasp to
# try), the paired tests leave the rank out.
STATUS_NO_GRASP = "no_grasp"
LIMIT_TOLERANCE = HELD_LIMIT_TOLERANCE


class TaskError(ValueError):
    """An unknown task or a trial outcome that does not fit its task."""


def check_task(task: str) -> str:
    if task not in TASKS:
        raise TaskError(f"unknown task {task!r}; known: {', '.join(TASKS)}")
    return task


def task_success(task: str, status: str, accels: list | None, rule: str = "every") -> bool | None:
    """True/False for a grasp outcome, None when the simulation itself failed.

    accels: per-direction held accelerations (shake, m/s^2) or per-axis held
    angular accelerations (twist, rad/s^2) of an "ok" trial. rule: SUCCESS_RULES
    ("mean" applies to the shake only).
    """
    check_task(task)
    if rule not in SUCCESS_RULES or (rule == "mean" and task != "shake"):
        raise TaskError(f"success rule {rule!r} does not apply to the {task} task")
    if status in (STATUS_LIFT_FAILED, STATUS_NO_GRASP):
        return False
    if status != STATUS_OK:
        return None
    if not accels:
        raise TaskError(f"{task} trial with status ok but no accelerations recorded")
    limit = SHAKE_POSITIVE_THRESHOLD_MPS2 if task == "shake" else TWIST_ACCEL_LIMIT_RADPS2
    if rule == "mean":
        return bool(sum(accels) / len(accels) >= limit * (1 - LIMIT_TOLERANCE))
    return bool(min(accels) >= limit * (1 - LIMIT_TOLERANCE))


def shake_success_rule(protocol: str) -> str:
    """The shake's success rule of an evaluation under a trial protocol (legacy: every direction)."""
    return "mean" if protocol == "defgraspsim" else "every"


def outcome_fields(task: str, status: str, accels: list | None, protocol: str) -> dict:
    """A trial record's success fields under a protocol: "success" by the protocol's rule and, where that rule
    is not already every direction (the defgraspsim shake: the mean), "success_every_direction" beside it."""
    rule = shake_success_rule(protocol) if task == "shake" else "every"
    fields = {"success": task_success(task, status, accels, rule)}
    if rule != "every":
        fields["success_every_direction"] = task_success(task, status, accels)
    return fields

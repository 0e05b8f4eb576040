"""The paper's real-robot experiment in the simulated cell (issue 49 item 3): `defgg-cell-experiment`.

14 objects of the held-out evaluation sets (7 soft at 2e4-2e5 Pa, 7 stiff at 2e6-2e9 Pa; never a training
object), each picked through the node graph (defgg_ros/evaluation/cell_picks.py: PlanGrasp + PickAndPlace on
the fake driver) under each stiffness input given to the segmentation node with SetStiffness:

    correct   the object's own modulus
    rigid     every object assumed rigid (2e9 Pa, the stiffest training modulus)
    soft      every object assumed soft (2e4 Pa, the softest training modulus)
    measured  nothing told: the executor squeezes the object first (PickAndPlace measure_only) and sends its
              estimate to the segmentation node, then plan and pick (issue 49 item 4; --cases measured)
    rigid_grasp, soft_grasp
              the grasp channel alone: plan with the wrong input, close with the force and speed of the
              object's true modulus (the paper's robot closes the same gripper on every grasp; ours closes
              with the labels' FOS(E) force, so a plain wrong input changes the grasp and the force).
              Where the wrong input is the object's own modulus the plain case's picks stand in
              (--cases rigid_grasp,soft_grasp --records records_grasp_only.jsonl)

Each object is picked --picks times per case from a seeded pose (position and yaw on the table): pick i of an
object has the same pose in every case, so the cases compare paired. The order is pick-major (every object's
pick 0 in every case, then pick 1, ...), so a run stopped early still holds complete pairs for every object.

Records: one JSON line per pick in OUT/records.jsonl (fsynced; a torn last line is skipped). A restart skips
every pick that has an outcome; a pick whose cell failed (a node died, a call timed out) is recorded with
`cell_error` and tried again, at most --max-attempts times (default 2). The report (OUT/report.md,
OUT/per_object.png) is written by `report` (defgg_ros/evaluation/cell_report.py).

    defgg-cell-experiment run --out results/cell_experiment --picks 5
    defgg-cell-experiment report --out results/cell_experiment
"""
from __future__ import annotations

import argparse
import hashlib
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from defgg_ros.atomic import append_jsonl, read_jsonl
from defgg_ros.bringup.supervisor import BringupError
from defgg_ros.cli_help import HelpFormatter
from defgg_ros.constants import OBJECT_DENSITY_KG_M3, TRAINING_YOUNGS_MODULI_PA
from defgg_ros.evaluation.cell_picks import PickSetup, run_pick
from defgg_ros.evaluation.cell_report import (
    CASES,
    GRASP_ONLY_CASES,
    RECORDS_NAME,
    plain_case,
    read_records,
    rerun_lines,
    write_report,
)
from defgg_ros.provenance import file_sha256, git_commit
from defgg_ros.ros.cell_client import CellCallError
from defgg_ros.ros.domain import ISOLATION_ENV, apply_domain_choice, default_domain_choice
from defgg_ros.ros.share import share_path
from defgg_ros.sim import objects as sim_objects
from defgg_ros.sim.meshes import save_tet_mesh_file

RIGID_PA, SOFT_PA = max(TRAINING_YOUNGS_MODULI_PA), min(TRAINING_YOUNGS_MODULI_PA)
# The fourth case (issue 49 item 4, beyond the paper): the executor squeezes the object first and tells the
# segmentation node its estimate; then plan and pick. Run with --cases measured (a run of its own).
MEASURED = "measured"
# The grasp-only cases (cell_report.GRASP_ONLY_CASES): plan with the wrong input, close as for the true modulus.
# Run with --cases rigid_grasp,soft_grasp (a run of its own).
MAX_ATTEMPTS = 2
# The executor's words for "no joint states / an input silent" (wall clock): the simulator, not the grasp.
CELL_FAILURE_PREFIXES = ("driver silent", "no joint states", "no external wrench")
# Where the object stands: the camera's centre under the demo cell's camera, moved by up to this much, at any yaw.
CENTRE_XY_M = (0.5, 0.0)
MAX_OFFSET_M = 0.04


@dataclass(frozen=True)
class CellObject:
    """An evaluation object of the experiment: its library name and set, its true modulus, how the cell
    builds it ("box" for the sponge: the cell's regular FEM grid of the same box; else the library's mesh)."""
    name: str
    set_name: str
    youngs_modulus_pa: float
    cell_shape: str = "mesh"

    @property
    def soft(self) -> bool:
        return self.youngs_modulus_pa <= 2e5

    @property
    def mass_kg(self) -> float:
        """The cell's mass of it: its library surface's volume at the trials' density (what the labels used)."""
        return round(float(abs(_library_shape(self).surface().volume)) * OBJECT_DENSITY_KG_M3, 4)


# The paper's mix: boxes, toys, balls, fruit-like and irregular shapes. The common can (6.5 cm) is left out:
# wider than the gripper's opening minus the planner's clearance, it has no feasible grasp (measured: PlanGrasp
# refuses it on width), as the paper picked only objects its gripper could hold; mallet_mm is two-material.
OBJECTS = (
    CellObject("common_sponge", "common", 2e4, "box"),
    CellObject("common_toy_bone", "common", 2e4),
    CellObject("common_ball", "common", 2e5),
    CellObject("common_pear", "common", 2e5),
    CellObject("egad_test_02_c1", "adversarial", 2e4),
    CellObject("egad_test_05_c2", "adversarial", 2e5),
    CellObject("egad_test_11_c3", "adversarial", 2e4),
    CellObject("common_ring", "common", 2e9),
    CellObject("egad_test_00_c1", "adversarial", 2e9),
    CellObject("egad_test_04_c2", "adversarial", 2e9),
    CellObject("egad_test_10_c3", "adversarial", 2e9),
    CellObject("egad_test_16_c5", "adversarial", 2e9),
    CellObject("egad_test_17_c5", "adversarial", 2e6),
    CellObject("egad_test_20_c6", "adversarial", 2e6),
)


def input_modulus_pa(case: str, obj: CellObject) -> float:
    """The modulus the segmentation node is told for `obj` in `case`."""
    if case in GRASP_ONLY_CASES:
        return input_modulus_pa(plain_case(case), obj)
    if case == "correct":
        return obj.youngs_modulus_pa
    if case == "rigid":
        return RIGID_PA
    if case == "soft":
        return SOFT_PA
    if case == MEASURED:
        return 0.0       # nothing told: the segmentation node's default until the squeeze's estimate arrives
    raise ValueError(f"unknown case {case!r}; known: {', '.join((*CASES, MEASURED, *GRASP_ONLY_CASES))}")


def grip_modulus_pa(case: str, obj: CellObject) -> float | None:
    """The modulus the executor closes for (force and speed): the object's own in a grasp-only case, else
    None (the planned grasp's, i.e. the input's)."""
    return obj.youngs_modulus_pa if case in GRASP_ONLY_CASES else None


def same_as_plain_case(case: str, obj: CellObject) -> bool:
    """A grasp-only case whose input is the object's own modulus is its plain case (same plan, same grip):
    not run again; the report takes the plain case's picks."""
    return case in GRASP_ONLY_CASES and input_modulus_pa(case, obj) == obj.youngs_modulus_pa


def _uniform(seed: int, *key) -> float:
    """A reproducible number in [0, 1) per key: independent of the order the picks run in."""
    digest = hashlib.sha256("|".join(str(k) for k in (seed, *key)).encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2**64


def pick_pose(seed: int, object_name: str, pick: int) -> dict:
    """Pick `pick` of an object: its (x, y) on the table and its yaw; the same in every case."""
    x = CENTRE_XY_M[0] + MAX_OFFSET_M * (2 * _uniform(seed, object_name, pick, "x") - 1)
    y = CENTRE_XY_M[1] + MAX_OFFSET_M * (2 * _uniform(seed, object_name, pick, "y") - 1)
    return {"x_m": round(x, 4), "y_m": round(y, 4), "yaw_rad": round(math.pi * _uniform(seed, object_name, pick,
                                                                                           "yaw"), 4)}


def pick_key(object_name: str, case: str, pick: int) -> str:
    return f"{object_name}|{case}|{pick}"


def run_order(objects) -> list:
    """Soft and stiff objects alternating (a run stopped mid-round holds both kinds; soft picks cost more)."""
    soft, stiff = [o for o in objects if o.soft], [o for o in objects if not o.soft]
    out = []
    for i in range(max(len(soft), len(stiff))):
        out += soft[i:i + 1] + stiff[i:i + 1]
    return out


def planned_picks(objects, cases, picks: int) -> list:
    """(object, case, pick) in run order: pick-major, then object (soft and stiff alternating), then case."""
    return [(o, c, i) for i in range(picks) for o in run_order(objects) for c in cases
            if not same_as_plain_case(c, o)]


def finished_keys(records, max_attempts: int = MAX_ATTEMPTS) -> set:
    """Keys of picks that have an outcome, or whose cell failed max_attempts times."""
    done, errors = set(), {}
    for r in records:
        if r.get("cell_error"):
            errors[r["key"]] = errors.get(r["key"], 0) + 1
        else:
            done.add(r["key"])
    return done | {k for k, n in errors.items() if n >= max_attempts}


# ---- the cell's objects ---------------------------------------------------------------------------------------
def _library_shape(obj: CellObject):

    shape = sim_objects.get_shape(obj.name)
    if shape.set_name not in ("common", "adversarial"):
        raise ValueError(f"{obj.name} is a {shape.set_name} object: the experiment uses evaluation objects only")
    return shape


def mesh_file(obj: CellObject, folder: Path) -> Path:
    """The library object's shipped tet mesh (metres) as the .npz the scene names: the cell simulates it as it is,
    so every machine meets the discretization the labels were made with (an .obj surface was re-meshed by
    fTetWild, which is not deterministic: each machine simulated its own bodies until 2026-11-30)."""
    path = Path(folder) / f"{obj.name}.npz"
    if not path.exists():
        tet = _library_shape(obj).union_tet
        save_tet_mesh_file(path, tet.nodes_m, tet.tets)
    return path


def scene_object(obj: CellObject, pose: dict, mesh_folder: Path) -> dict:
    """The scene file's entry for `obj` at `pose` (mass from its volume at the trials' density)."""
    surface = _library_shape(obj).surface()
    entry = {"name": obj.name, "position_xy_m": [pose["x_m"], pose["y_m"]], "yaw_rad": pose["yaw_rad"],
             "youngs_modulus_pa": float(obj.youngs_modulus_pa), "mass_kg": obj.mass_kg}
    if obj.cell_shape == "box":
        lo, hi = surface.bounds
        # 3 cm cells: the demo's sponge grid (a coarser one let the fingers sink through the body).
        return {**entry, "shape": "box", "size_m": [round(float(v), 4) for v in hi - lo], "fem_cell_size_m": 0.03}
    return {**entry, "shape": "mesh", "mesh": str(mesh_file(obj, mesh_folder).resolve()), "size_m": [1.0, 1.0, 1.0]}


def identities(scene: dict, model: Path) -> dict:
    """What a pick ran on, so that pairs across runs can be checked to compare the same thing: the code's commit,
    the weights' and the object body's file hashes (a box on the FEM grid: its size and cell, in the record)."""
    body = scene.get("mesh")
    return {"commit": git_commit(), "model_sha256": file_sha256(model),
            "mesh_sha256": file_sha256(body) if body else None}


# ---- the run ----------------------------------------------------------------------------------------------------
def run(out: Path, work: Path, model: Path, picks: int, seed: int, objects, cases, pick_fn=None,
        progress=True, records_name: str = RECORDS_NAME, max_attempts: int = MAX_ATTEMPTS) -> int:
    """Run every planned pick that has no outcome yet in OUT/records_name; returns how many picks ran now."""
    pick_fn = pick_fn or run_pick
    records_path = Path(out) / records_name
    done = finished_keys(read_jsonl(records_path), max_attempts)
    plan = planned_picks(objects, cases, picks)
    todo = [(o, c, i) for o, c, i in plan if pick_key(o.name, c, i) not in done]
    ran = 0
    with tqdm(total=len(plan), initial=len(plan) - len(todo), unit="pick", desc="cell experiment",
              disable=not progress, mininterval=5.0) as bar:
        for obj, case, index in todo:
            key = pick_key(obj.name, case, index)
            bar.set_postfix_str(key)
            pose = pick_pose(seed, obj.name, index)
            record = {"key": key, "object": obj.name, "object_set": obj.set_name, "soft": obj.soft,
                      "youngs_modulus_pa": obj.youngs_modulus_pa, "case": case, "pick": index, "seed": seed,
                      "input_youngs_modulus_pa": input_modulus_pa(case, obj), "pose": pose,
                      "grip_youngs_modulus_pa": grip_modulus_pa(case, obj),
                      "model": str(model), "started_unix_s": round(time.time(), 1)}
            scene = scene_object(obj, pose, Path(work) / "meshes")
            record.update(identities(scene, model))   # pairs compare the same body, weights and code
            setup = PickSetup(scene, record["input_youngs_modulus_pa"], measure_first=case == MEASURED,
                              grip_youngs_modulus_pa=record["grip_youngs_modulus_pa"])
            record.update(_attempt(pick_fn, setup, Path(work), key, model))
            append_jsonl(records_path, record)
            ran += 1
            bar.update(1)
    return ran


def _attempt(pick_fn, setup, work: Path, key: str, model: Path) -> dict:

    stem = key.replace("|", "__")
    log_path = work / "logs" / f"{stem}.log"
    log_path.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with open(log_path, "w", encoding="utf-8") as log:
        try:
            record = pick_fn(setup, work / "scenes" / f"{stem}.yaml", model, log)
        except (BringupError, CellCallError, TimeoutError) as exc:
            return {"cell_error": f"{type(exc).__name__}: {exc}", "wall_s": round(time.monotonic() - started, 1)}
    reason = cell_failure_of(record)
    if reason:
        return {**record, "cell_error": f"the simulator, not the grasp: {reason}"}
    return record


def cell_failure_of(record: dict) -> str:
    """The reason a pick's record is the cell's failure, not the grasp's ('' when it is not): the pick's own, or
    its squeeze's in the measured case (a squeeze ended 'driver silent' left the object's modulus unmeasured, so
    the pick after it does not test the measured input)."""
    for reason in (record.get("failure_reason", ""), (record.get("squeeze") or {}).get("failure_reason", "")):
        if is_cell_failure(reason):
            return reason
    return ""


def is_cell_failure(failure_reason: str) -> bool:
    """A pick the executor ended because the simulator was too slow for its wall-clock guards (a loaded CPU),
    not because of the grasp: tried again like a cell that failed."""
    return failure_reason.startswith(CELL_FAILURE_PREFIXES)


# ---- CLI --------------------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:

    parser = argparse.ArgumentParser(prog="defgg-cell-experiment", formatter_class=HelpFormatter,
                                     description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="pick every object under every case (resumable)", formatter_class=HelpFormatter)
    p.add_argument("--out", required=True, help="records and report folder (e.g. results/cell_experiment)")
    p.add_argument("--work", default="runs/cell_experiment", help="scenes, meshes and every pick's node logs")
    p.add_argument("--model", default=str(share_path("models", "defgg_cnn.pt")), help="Def-GG-CNN checkpoint")
    p.add_argument("--picks", type=int, default=10, help="picks per object and case (the paper: 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the objects' poses")
    p.add_argument("--objects", help="comma-separated object names (default: all 14)")
    p.add_argument("--cases", default=",".join(CASES), help="comma-separated cases (default: %(default)s)")
    p.add_argument("--ros-domain", default=default_domain_choice(), metavar="private|inherit|ID",
                   help=f"ROS domain of the cells (default: private; from ${ISOLATION_ENV})")
    p.add_argument("--records", default=RECORDS_NAME, metavar="NAME",
                   help="records file in OUT (default: %(default)s; a second run beside a running one, e.g. the "
                        "measured case: records_measured.jsonl; the report reads every records*.jsonl)")
    p.add_argument("--max-attempts", type=int, default=MAX_ATTEMPTS,
                   help="tries of a pick whose cell failed (a node died, a call timed out, the simulator stalled) "
                        "before it is given up; raise it to give given-up picks another try (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p = sub.add_parser("report", help="write OUT/report.md and OUT/per_object.png from the records",
                       formatter_class=HelpFormatter)
    p.add_argument("--out", required=True, help="the run's folder")
    p.add_argument("--picks", type=int, default=None, help="picks planned per object and case (for the progress "
                                                             "line; default: the most recorded)")
    p.add_argument("--with", dest="with_dirs", nargs="+", default=[], metavar="DIR",
                   help="other runs' folders whose records join OUT's (other cases at the same seeded poses, e.g. "
                        "the three inputs beside a measured-case run), so the paired comparisons pair them; a pick "
                        "recorded in two folders is refused")
    p = sub.add_parser("compare", help="a rerun against an earlier run: the picks run in both, which ended the "
                                       "same way and chose the same grasp", formatter_class=HelpFormatter)
    p.add_argument("--out", required=True, help="the rerun's folder (its records*.jsonl)")
    p.add_argument("--earlier", required=True, help="the earlier run's folder (e.g. results/cell_experiment)")
    return parser


def _selected(args) -> tuple:
    names = args.objects.split(",") if args.objects else [o.name for o in OBJECTS]
    by_name = {o.name: o for o in OBJECTS}
    unknown = sorted(set(names) - set(by_name))
    if unknown:
        raise ValueError(f"--objects {unknown} are not objects of the experiment ({', '.join(by_name)})")
    if not args.records.startswith("records") or not args.records.endswith(".jsonl") or "/" in args.records:
        raise ValueError(f"--records must be a file name records*.jsonl (the report reads those), got {args.records}")
    cases = args.cases.split(",")
    for case in cases:
        input_modulus_pa(case, OBJECTS[0])   # ValueError on an unknown case
    return [by_name[n] for n in names], cases


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "report":
            print(write_report(Path(args.out), OBJECTS, args.picks, args.with_dirs))
            return 0
        if args.command == "compare":
            runs = [read_records(Path(d)) for d in (args.earlier, args.out)]
            for folder, records in zip((args.earlier, args.out), runs):
                if not records:
                    raise OSError(f"{folder} holds no records*.jsonl")
            print("\n".join(rerun_lines(*runs)))
            return 0
        if args.max_attempts < 1:
            raise ValueError(f"--max-attempts must be >= 1, got {args.max_attempts}")
        if args.picks < 1:
            raise ValueError(f"--picks must be >= 1, got {args.picks}")
        objects, cases = _selected(args)
        if not Path(args.model).is_file():
            raise ValueError(f"model file {args.model} does not exist")

        print(f"defgg-cell-experiment: {apply_domain_choice(args.ros_domain)}", flush=True)
        ran = run(Path(args.out), Path(args.work), Path(args.model), args.picks, args.seed, objects, cases,
                  progress=not args.no_progress, records_name=args.records, max_attempts=args.max_attempts)
        print(f"defgg-cell-experiment: {ran} picks run now; records in {Path(args.out) / args.records}")
        return 0
    except (ValueError, OSError) as exc:
        print(f"defgg-cell-experiment: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

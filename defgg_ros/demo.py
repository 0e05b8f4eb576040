"""defgg-demo (`make demo`): pick every object of the demo scene with Def-GG-CNN grasps in the simulated cell.

Brings up the simulated cell (fake Panda + camera, segmentation, grasp
inference, executor) headless, assigns each object its Young's modulus
(SetStiffness, from the scene's ground truth), then per object: a fresh
depth frame -> PlanGrasp restricted to that object -> PickAndPlace into the
bin. Prints a table (E, grasp width, quality, phase reached, held after
transfer, in the bin) and writes summary.json, grasps.png (depth, stiffness,
quality map and chosen grasp per object) and cell.log (every node's log) to
--out.

The cell runs in a private ROS domain with localhost-only discovery (the first
line printed names it), so it never reaches a real arm's controller on the
lab network; `--ros-domain inherit` (or DEFGG_ROS_DOMAIN=inherit) uses the
shell's ROS_DOMAIN_ID and discovery instead.

Exit codes: 0 the cell ran every pick (whether or not each object reached the
bin: the table says), 1 the cell failed (a node died, a call timed out), 2 bad
input (scene, model, --objects, flags), 3 with --strict: an object picked is
not in the bin.
"""
import argparse
import math
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.msg import ObjectStiffness
from defgg_interfaces.srv import PlanGrasp
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import RegionOfInterest
from tqdm import tqdm

from defgg_ros.bringup.demo_client import DemoClient
from defgg_ros.bringup.demo_geometry import (
    base_T_camera,
    bin_place_xy,
    in_bin,
    label_of_object,
    object_roi,
    part_roi,
    project_base_points,
    release_tcp_z,
)
from defgg_ros.bringup.demo_report import FramePanels, PickRow, format_table, save_figure, write_summary
from defgg_ros.bringup.node_set import NodeSetError, load_node_set
from defgg_ros.bringup.shared_parameters import effective_parameters
from defgg_ros.bringup.supervisor import Bringup, BringupError
from defgg_ros.cli_help import HelpFormatter
from defgg_ros.constants import PANDA_READY_Q_RAD
from defgg_ros.control.kinematics import KinematicsError, PandaKinematics
from defgg_ros.perception.grasp_planning import full_quality_image
from defgg_ros.ros.cell_client import CellCallError
from defgg_ros.ros.conversions import camera_info_to_k, depth_msg_to_metres, image_to_numpy
from defgg_ros.ros.domain import ISOLATION_ENV, apply_domain_choice, default_domain_choice
from defgg_ros.ros.parameters import defaults
from defgg_ros.ros.share import SOURCE_ROOT, demo_scene_file, share_path
from defgg_ros.sim.scene_spec import SceneError, load_scene

DEFAULT_SCENE = demo_scene_file()
DEFAULT_MODEL = share_path("models", "defgg_cnn.pt")
DRIVER, INFERENCE = "fake_panda_driver", "grasp_inference_node"
# Before each camera frame the arm goes to the ready pose, which is out of the
# camera's view: first straight up by this much, then in joint space.
OBSERVE_LIFT_M = 0.12
OBSERVE_MOVE_S = (2.0, 5.0)
# PlanGrasp returns each object's best grasp before any second one: asking for this many grasps gets the target's
# best one in a scene of up to this many objects (the demo's have at most eight).
TARGET_SEARCH_TOP_K = 10
EXIT_CELL_FAILED, EXIT_BAD_INPUT, EXIT_NOT_ALL_IN_BIN = 1, 2, 3


def parse_args(argv=None):
    parser = argparse.ArgumentParser(prog="defgg-demo", description=__doc__,
                                     formatter_class=HelpFormatter)
    parser.add_argument("--scene", default=str(DEFAULT_SCENE), help="scene YAML (default: the demo scene)")
    parser.add_argument("--model", default=str(DEFAULT_MODEL), help="Def-GG-CNN checkpoint for the inference node")
    parser.add_argument("--out", help="output folder (default: runs/demo/<UTC timestamp>)")
    parser.add_argument("--objects", help="comma-separated object names to pick (default: all, in scene order)")
    parser.add_argument("--gui", action="store_true", help="show PyBullet's GUI (default: headless)")
    parser.add_argument("--max-rtf", type=float, default=0.0,
                        help="cap on the simulation's real-time factor (default 0: as fast as the CPU allows)")
    parser.add_argument("--ready-timeout", type=float, default=180.0, help="seconds for the cell to come up")
    parser.add_argument("--pick-timeout", type=float, default=900.0, help="wall seconds allowed per pick")
    parser.add_argument("--ros-domain", default=default_domain_choice(), metavar="private|inherit|ID",
                        help="ROS domain of the cell: private (default: a random id, localhost-only discovery), "
                             "inherit (the shell's ROS_DOMAIN_ID and discovery) or an id; "
                             f"default from ${ISOLATION_ENV}")
    parser.add_argument("--strict", action="store_true",
                        help=f"exit {EXIT_NOT_ALL_IN_BIN} when the cell ran but an object picked did not end in the "
                             "bin (default: exit 0, the table says which)")
    return parser.parse_args(argv)


def exit_code(cell_ran: bool, rows, strict: bool) -> int:
    """0: every pick ran (and with strict, every object picked is in the bin); 1: the cell failed; 3: strict and
    an object picked is not in the bin (or nothing was picked)."""
    if not cell_ran:
        return EXIT_CELL_FAILED
    if strict and (not rows or not all(r.in_bin for r in rows)):
        return EXIT_NOT_ALL_IN_BIN
    return 0


def _out_dir(args) -> Path:
    if args.out:
        return Path(args.out)
    return SOURCE_ROOT / "runs" / "demo" / datetime.now(UTC).strftime("%Y%m%d-%H%M%S")


def _stiffness_msgs(scene, positions, k, image_wh, names):
    """ObjectStiffness entries (whole objects, ROI around each) for the named objects."""
    b_t_c = base_T_camera(scene)
    out = []
    for obj, pos in zip(scene["objects"], positions):
        if obj["name"] not in names:
            continue
        x, y, w, h = object_roi(obj, pos, b_t_c, k, image_wh)
        out.append(ObjectStiffness(name=obj["name"], youngs_modulus_pa=float(obj["youngs_modulus_pa"]),
                                   roi=RegionOfInterest(x_offset=x, y_offset=y, width=w, height=h)))
        part = part_roi(obj, pos, b_t_c, k, image_wh)
        if part is not None:  # multi-material: only the part's pixels take its modulus
            x, y, w, h = part
            out.append(ObjectStiffness(name=f"{obj['name']}_part", region_only=True,
                                       youngs_modulus_pa=float(obj["part"]["youngs_modulus_pa"]),
                                       roi=RegionOfInterest(x_offset=x, y_offset=y, width=w, height=h)))
    return out


def _describe_grasp(name, grasp, object_position_m) -> str:
    """One line: where the network's grasp is relative to the object (to tell a bad grasp from a bad pick)."""
    g = grasp.pose_base.pose.position
    offset_mm = (np.array([g.x, g.y]) - np.asarray(object_position_m)[:2]) * 1000
    angle_deg = np.degrees(grasp.angle_rad)
    return (f"defgg-demo: {name}: grasp at ({g.x:.3f}, {g.y:.3f}, {g.z:.3f}) m, "
            f"{offset_mm[0]:+.0f}/{offset_mm[1]:+.0f} mm (x/y) from the object's centre, "
            f"image angle {angle_deg:+.0f} deg, width {grasp.width_m * 1000:.1f} mm, "
            f"quality {grasp.quality:.2f}")


class DemoRun:
    """One demo: the client, the local predictor (for the quality pictures) and the results."""

    def __init__(self, client, model_path, bringup, pick_timeout_s=900.0, executor_params=None):
        from defgg_ros.model.inference import GraspPredictor  # torch: ~1.3 CPU-s, not for --help or bad input

        self.client = client
        self.executor_params = executor_params or {}  # without them, the executor's own place pose
        self.placed = 0
        self.bringup = bringup
        self.pick_timeout_s = pick_timeout_s
        self.predictor = GraspPredictor.from_checkpoint(model_path, num_threads=1)
        self.scene = client.scene()
        self.rows, self.panels = [], []

    def assign_stiffness(self, names):
        depth, info = self.client.fresh_frame(0.0)
        k = camera_info_to_k(info)
        entries = _stiffness_msgs(self.scene, self.client.object_positions(), k, (info.width, info.height), names)
        self.client.set_stiffness(entries)  # CellCallError when the segmentation node refuses the moduli

    def pick(self, index: int, remaining: set, progress) -> PickRow:
        obj = self.scene["objects"][index]
        row = PickRow(obj["name"], float(obj["youngs_modulus_pa"]), self.scene["objects_simulated_as"][index])
        started = time.monotonic()
        try:
            grasp = self._plan(index, remaining, row)
            if grasp is not None:
                progress.write(_describe_grasp(row.name, grasp, self.client.object_positions()[index]))
                self._execute(grasp, row, progress)
        finally:
            row.wall_duration_s = time.monotonic() - started
            position = self.client.object_positions()[index]
            row.in_bin = in_bin(position, self.scene.get("bin"))
            row.final_position_m = tuple(round(float(c), 4) for c in position)
        return row

    def final_check(self, rows, indices, settle_s=1.0, timeout_s=20.0):
        """Where every picked object ended once the cell is still: a later pick can knock an earlier
        object out of the bin, and one checked right after its own pick may still be rolling."""
        deadline = time.monotonic() + timeout_s
        previous = np.array(self.client.object_positions())
        still_since = time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - still_since < settle_s:
            now = np.array(self.client.object_positions())
            if np.abs(now - previous).max() > 0.002:
                still_since = time.monotonic()
            previous = now
        for row, index in zip(rows, indices):
            row.in_bin = in_bin(previous[index], self.scene.get("bin"))
            row.final_position_m = tuple(round(float(c), 4) for c in previous[index])

    def observe_pose(self):
        """Open the hand, lift the TCP straight up, go to the ready pose (clear of the camera's view).

        A failed pick leaves the arm where it stopped, over the objects; a frame
        taken from there would show the arm instead of the scene.
        """
        ready = np.array(PANDA_READY_Q_RAD)
        q_now = self.client.arm_positions()
        if np.abs(q_now - ready).max() < 0.02:
            return
        self.client.open_gripper()
        kinematics = PandaKinematics()
        base_m_tcp = kinematics.fk(q_now)
        base_m_tcp[2, 3] += OBSERVE_LIFT_M
        try:
            q_lift = kinematics.ik(base_m_tcp, q_seed_rad=q_now).q_rad
            waypoints = [(OBSERVE_MOVE_S[0], q_lift), (OBSERVE_MOVE_S[1], ready)]
        except KinematicsError:  # no straight lift from here: go in joint space
            waypoints = [(OBSERVE_MOVE_S[1], ready)]
        self.client.move_arm(waypoints)

    def _plan(self, index, remaining, row):
        self.observe_pose()
        depth_msg, info = self.client.fresh_frame(time.monotonic())
        depth_m, k = depth_msg_to_metres(depth_msg), camera_info_to_k(info)
        positions = self.client.object_positions()
        entries = _stiffness_msgs(self.scene, positions, k, (info.width, info.height), remaining)
        # The segmentation node perceives the frame (the cell's only perceiver); the target is the perceived
        # object under the scene object's position, and its grasps are chosen among the planner's.
        perceived = self.client.perceive(depth_msg, info, entries)
        if not perceived.success:
            row.failure_reason = f"Perceive: {perceived.message}"
            return None
        labels = image_to_numpy(perceived.perceived.labels)
        uv = project_base_points([positions[index]], base_T_camera(self.scene), k)[0]
        label = label_of_object(labels, uv)
        target = (labels == label) if label else np.zeros(labels.shape, dtype=bool)
        modulus = {o.label: o.stiffness.youngs_modulus_pa for o in perceived.perceived.objects}.get(label, 0.0)
        stiffness_pa = np.where(target, modulus, 0.0).astype(np.float32)
        panel = FramePanels(row.name, depth_m, stiffness_pa)
        self.panels.append(panel)
        if not label:
            x, y, z = positions[index]
            row.failure_reason = (f"object not seen where it is, ({x:.3f}, {y:.3f}, {z:.3f}) m: "
                                  "knocked away by an earlier pick, or hidden")
            return None
        prediction = self.predictor.predict(depth_m, stiffness_pa, k, object_mask=target.astype(np.uint8), top_k=1)
        panel.quality = full_quality_image(prediction.q, prediction.crop_offset_px, depth_m.shape)
        request = PlanGrasp.Request(depth=depth_msg, camera_info=info, perceived=perceived.perceived,
                                    top_k=TARGET_SEARCH_TOP_K)
        response = self.client.plan(request)
        grasp = next((g for g in response.grasps if g.object_id == label), None) if response.success else None
        if grasp is None:
            row.failure_reason = (f"PlanGrasp: {response.message}" if not response.success else
                                  f"PlanGrasp: none of its {len(response.grasps)} grasps is on the target")
            return None
        row.grasp_width_m, row.quality = grasp.width_m, grasp.quality
        row.estimated_mass_kg = grasp.estimated_mass_kg
        panel.grasp_uv_px = (grasp.center_u_px, grasp.center_v_px)
        panel.grasp_angle_rad, panel.grasp_width_px = grasp.angle_rad, grasp.width_px
        return grasp

    def _execute(self, grasp, row, progress):
        def on_feedback(feedback):
            if feedback.phase != row.phase_reached:  # one progress line per phase, not per message
                row.phase_reached = feedback.phase
                progress.set_postfix_str(f"{row.name}: {feedback.phase}")

        goal = PickAndPlace.Goal(plan_grasp=False, grasp=grasp,
                                 place_pose=self._place_pose(grasp.pose_base.pose))
        result = self.client.pick(goal, on_feedback, timeout_s=self.pick_timeout_s)
        self.placed += bool(result.held_after_transfer)
        row.success, row.held_after_transfer = result.success, result.held_after_transfer
        row.phase_reached = result.phase_reached or row.phase_reached
        row.failure_reason = result.failure_reason
        if not result.success and not result.phase_reached:
            row.failure_reason = "the executor returned an empty result (its error is in cell.log)"
        row.sim_duration_s = result.duration_s
        row.gripper_force_n = result.gripper_force_n or math.nan

    def _place_pose(self, grasp_pose):
        """Each object into its own quadrant of the bin, released just above the bin's floor
        (demo_geometry.release_tcp_z; at most the executor's configured release height), with the hand
        turned as it was at the grasp: a transfer that turns the hand about the vertical spun a soft block
        between the low-force fingers until its diagonal pried them open (bench/README.md).

        An empty frame (no bin in the scene, or no release height) leaves it to the executor.
        """
        pose = PoseStamped()
        p = self.executor_params
        if self.scene.get("bin") and "place_position_m" in p and "base_frame" in p:
            pose.header.frame_id = p["base_frame"]
            x, y = bin_place_xy(self.scene["bin"], self.placed)
            pose.pose.position.x, pose.pose.position.y = x, y
            pose.pose.position.z = release_tcp_z(grasp_pose.position.z, self.scene["bin"],
                                                 float(p["place_position_m"][2]))
            pose.pose.orientation = grasp_pose.orientation
        return pose


def executor_params(node_set) -> dict:
    """The executor's start-up parameters (place pose, base frame): as the bringup resolves them."""
    entry = next((e for e in node_set.nodes if e.name == "executor_node"), None)
    return effective_parameters(entry) if entry is not None else defaults("executor_node")


def run_demo(args, out_dir: Path, log) -> int:
    overrides = {DRIVER: {"scene_file": str(Path(args.scene).resolve()), "gui": bool(args.gui),
                          "max_real_time_factor": float(args.max_rtf)},
                 INFERENCE: {"model_path": str(Path(args.model).resolve())}}
    node_set = load_node_set("sim_cell")
    bringup = Bringup(node_set, overrides, out=log)
    client = None
    rows, panels = [], []
    started = time.monotonic()
    try:
        bringup.start()
        print(f"defgg-demo: starting the simulated cell ({Path(args.scene).name}); node logs in {log.name}")
        print(f"defgg-demo: cell ready in {bringup.wait_ready(args.ready_timeout):.1f} s")
        client = DemoClient(check_alive=lambda: _raise_if_dead(bringup))
        run = DemoRun(client, args.model, bringup, args.pick_timeout, executor_params(node_set))
        names = [o["name"] for o in run.scene["objects"]]
        wanted = args.objects.split(",") if args.objects else names
        unknown = set(wanted) - set(names)
        if unknown:
            raise CellCallError(f"--objects {sorted(unknown)} not in the scene (has {names})")
        run.assign_stiffness(set(names))
        remaining = set(names)
        with tqdm([names.index(n) for n in wanted], desc="picking", unit="object") as progress:
            for index in progress:
                _raise_if_dead(bringup)
                rows.append(run.pick(index, remaining, progress))
                if rows[-1].in_bin:
                    remaining.discard(names[index])
        run.final_check(rows, [names.index(n) for n in wanted])
        panels = run.panels
        cell_ran = True
    except (BringupError, CellCallError, NodeSetError) as exc:
        print(f"defgg-demo: {exc}", file=sys.stderr)
        _explain_dead_node(bringup)
        cell_ran = False
    finally:
        if client is not None:
            client.close()
        bringup.stop()
    _report(out_dir, rows, panels, args, time.monotonic() - started)
    code = exit_code(cell_ran, rows, args.strict)
    if code == EXIT_NOT_ALL_IN_BIN:
        print(f"defgg-demo: --strict: {sum(not r.in_bin for r in rows)} of {len(rows)} objects picked are not in "
              "the bin", file=sys.stderr)
    return code


def _check_inputs(args) -> str | None:
    """What is wrong with the scene, model or --objects, found before the cell starts (else None)."""
    if not args.max_rtf >= 0:
        return f"--max-rtf must be >= 0 (0: as fast as possible), got {args.max_rtf:g}"
    for flag, value in (("--ready-timeout", args.ready_timeout), ("--pick-timeout", args.pick_timeout)):
        if not value > 0:
            return f"{flag} must be > 0 s, got {value:g}"
    if not Path(args.model).is_file():
        return f"model file {args.model} does not exist"
    try:
        names = [o.name for o in load_scene(args.scene).objects]
    except SceneError as exc:
        return f"scene: {exc}"
    unknown = sorted(set(args.objects.split(",")) - set(names)) if args.objects else []
    if unknown:
        return f"--objects {unknown} not in the scene (it has {', '.join(names)})"
    return None


def _raise_if_dead(bringup) -> None:
    dead = bringup.failed_node()
    if dead is not None:
        raise BringupError(dead.describe())


def _explain_dead_node(bringup) -> None:
    """A call that timed out is often a node that died: name it and show its last lines (else every node's)."""
    dead = bringup.failed_node()
    if dead is not None:
        tail = "\n".join(bringup.processes[dead.name].tail)
        print(f"defgg-demo: {dead.describe()}; its last lines:\n{tail}", file=sys.stderr)
        return
    for name, process in bringup.processes.items():   # all alive: what each said last
        last = "\n  ".join(process.tail[-3:]) or "(nothing)"
        print(f"defgg-demo: {name} is running; its last lines:\n  {last}", file=sys.stderr)


def _report(out_dir, rows, panels, args, wall_s):
    if rows:
        print(format_table(rows))
    write_summary(out_dir / "summary.json", rows, {
        "scene": str(Path(args.scene).resolve()), "model": str(Path(args.model).resolve()),
        "wall_time_s": round(wall_s, 1), "finished_utc": datetime.now(UTC).isoformat()})
    if panels:
        save_figure(out_dir / "grasps.png", panels)
    held = sum(r.held_after_transfer for r in rows)
    binned = sum(r.in_bin for r in rows)
    print(f"defgg-demo: {binned}/{len(rows)} objects in the bin, {held} held after transfer, "
          f"{wall_s / 60:.1f} min; results in {out_dir}")


def main(argv=None) -> int:
    args = parse_args(argv)
    try:  # first: before any rclpy context or node process exists (they read the domain at start-up)
        domain_line = f"defgg-demo: {apply_domain_choice(args.ros_domain)}"
        print(domain_line, flush=True)
    except ValueError as exc:
        print(f"defgg-demo: --ros-domain: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    problem = _check_inputs(args)
    if problem:
        print(f"defgg-demo: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    out_dir = _out_dir(args)
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "cell.log", "w", encoding="utf-8") as log:
        print(domain_line, file=log, flush=True)
        return run_demo(args, out_dir, log)


if __name__ == "__main__":
    sys.exit(main())

"""defgg-record: record a session of the running cell into a rosbag2 (MCAP, zstd) bag.

Records the camera (depth + camera_info + colour, decimated to one frame per
--depth-period-s plus every frame a grasp was planned on), /joint_states
(decimated), the stiffness assignments, the best grasps, the fake driver's
scene, and metadata (scene file, model fingerprint, node parameters,
software version). Two ways to use it:

  passive (e.g. `defgg-bringup --record PATH`): record until Ctrl-C / --duration-s;
  driving: --plan N calls PlanGrasp N times on fresh frames (and --pick I,J
  sends PickAndPlace goals with those calls' best grasps), recording every
  request/response and goal/feedback/result: this is how the sessions in
  sim_bringup/sessions/ were made.

Replay with `defgg-replay PATH`.
"""
import argparse
import signal
import sys
import threading
import time
from pathlib import Path

import rclpy
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.msg import ObjectStiffness
from defgg_interfaces.srv import PlanGrasp
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo
from tqdm import tqdm

from defgg_ros.cli_help import HelpFormatter
from defgg_ros.ros import qos
from defgg_ros.ros.cell_client import CellCallError, CellClient
from defgg_ros.ros.conversions import camera_info_to_k
from defgg_ros.ros.executor import SpinThread, ThreadedExecutor
from defgg_ros.ros.launcher import watch_supervisor
from defgg_ros.ros.transport import use_large_message_transport
from defgg_ros.sessions import metadata as md
from defgg_ros.sessions.bag import SessionBagError, SessionWriter
from defgg_ros.sessions.compare import GraspSummary, PickOutcome, Tolerances
from defgg_ros.sessions.params import CELL_NODES, PERCEPTION_NODES, fetch_all
from defgg_ros.sessions.recorder_node import SessionRecorder
from defgg_ros.sessions.scene_stiffness import scene_stiffness_entries
from defgg_ros.sessions.selector import DEFAULT_DEPTH_PERIOD_S, DEFAULT_JOINT_STATE_PERIOD_S, FrameSelector
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)
from defgg_ros.sim.scene_spec import SceneError, load_scene

FRESH_FRAME_TIMEOUT_S = 60.0
PASSIVE_PERIODIC_S = 5.0


def _model_path(args, parameters: dict) -> tuple[Path, bool]:
    inference = parameters.get("grasp_inference_node") or {}
    use_stiffness = bool(inference.get("use_stiffness", True))
    if args.model:
        return Path(args.model), use_stiffness
    if inference.get("model_path"):
        return Path(inference["model_path"]), use_stiffness
    from defgg_ros.nodes.grasp_inference_node import default_model_path  # loads torch (~1.5 CPU-s): only here
    return default_model_path(use_stiffness), use_stiffness


def _pick_indices(text: str | None, n_plans: int) -> set:
    """ValueError unless `text` names PlanGrasp calls of this run (check_args: before anything connects)."""
    if not text:
        return set()
    if n_plans < 1:
        raise ValueError("--pick needs --plan N (it picks with the grasps of those PlanGrasp calls)")
    try:
        indices = {int(v) for v in text.split(",")}
    except ValueError:
        raise ValueError(f"--pick needs plan indices like 0,2; got {text!r}") from None
    if any(not 0 <= i < n_plans for i in indices):
        raise ValueError(f"--pick indices must be in 0..{n_plans - 1} (see --plan)")
    return indices


def wait_camera_info(node, timeout_s: float) -> CameraInfo:
    got = []
    event = threading.Event()
    sub = node.create_subscription(CameraInfo, topics.DEPTH_CAMERA_INFO,
                                   lambda m: (got.append(m), event.set()), qos.SENSOR_DATA)
    try:
        if not event.wait(timeout_s):
            raise CellCallError(f"no camera_info on {topics.DEPTH_CAMERA_INFO} within {timeout_s:g} s")
        return got[0]
    finally:
        node.destroy_subscription(sub)


def assign_scene_stiffness(recorder, client, scene_path, log=print) -> None:
    """--stiffness-from-scene: enter every scene object's modulus (and parts) through SetStiffness."""
    info = wait_camera_info(recorder, FRESH_FRAME_TIMEOUT_S)
    entries = scene_stiffness_entries(load_scene(scene_path), camera_info_to_k(info), (info.width, info.height))
    objects = []
    for e in entries:
        o = ObjectStiffness(name=e["name"], youngs_modulus_pa=e["youngs_modulus_pa"], region_only=e["region_only"])
        o.roi.x_offset, o.roi.y_offset, o.roi.width, o.roi.height = e["roi"]
        objects.append(o)
    response = client.set_stiffness(objects, 0.0)
    log(f"stiffness from the scene: {response.message}")


def drive(recorder, client, args, log=tqdm.write) -> None:
    """--plan/--pick: call the cell like a user would, on fresh frames, and record it."""
    picks = _pick_indices(args.pick, args.plan)
    flush = 0
    if args.stiffness_from_scene:
        assign_scene_stiffness(recorder, client, args.scene, log)
        # The frame in flight when SetStiffness returned was segmented with the old moduli and its
        # grasp still counts as fresh: let one more frame through so plan 0 sees the new ones.
        flush = 1
    for i in tqdm(range(args.plan), desc="plan calls", unit="call", disable=args.plan < 2):
        if not recorder.wait_for_grasps(args.frames_between + (flush if i == 0 else 0), FRESH_FRAME_TIMEOUT_S):
            raise CellCallError(f"no new grasp on {topics.BEST_GRASP} within {FRESH_FRAME_TIMEOUT_S:g} s "
                                "(is the camera publishing and the inference node running?)")
        response = client.plan(PlanGrasp.Request(top_k=args.top_k))
        best = GraspSummary.of(response.grasps[0]).brief() if response.grasps else "none"
        log(f"  plan {i}: {'ok' if response.success else 'FAILED'} {best} {response.message}")
        if i in picks and response.success:
            result = client.pick(PickAndPlace.Goal(plan_grasp=False, grasp=response.grasps[0]))
            log(f"  pick {i}: {PickOutcome.of(result).brief()}")


def _cell_parameters(probe, args, log) -> dict:
    """The running cell nodes' parameters. Driving a cell, its perception nodes are known to be up: a
    slow answer (a loaded machine) is waited for up to --wait-s, because a session without their
    parameters replays against the shipped YAML, which may not be what the cell ran."""
    parameters = fetch_all(probe, CELL_NODES, args.param_timeout_s)
    missing = [name for name in PERCEPTION_NODES if name not in parameters]
    if args.plan and missing:
        parameters.update(fetch_all(probe, missing, max(args.wait_s, args.param_timeout_s)))
    log(f"parameters recorded from: {', '.join(parameters) or 'no running cell node'}")
    missing = [name for name in PERCEPTION_NODES if name not in parameters]
    if missing:
        log(f"WARNING: no parameters from {', '.join(missing)}: a replay runs them with the shipped YAML "
            "(sim_bringup/config), which may differ from what this cell ran")
    return parameters


def record(args, log=print) -> Path:
    context = Context()
    rclpy.init(context=context)
    executor = ThreadedExecutor(num_threads=4, context=context)
    spin_thread = SpinThread(executor)
    writer = None
    try:
        probe = Node("defgg_session_probe", context=context)
        executor.add_node(probe)
        # Driving: the cell must be up before its parameters can be read. These clients, once they have
        # seen the servers, make the calls: fresh clients on the recorder node, created while the camera's
        # frames stream in, were twice not discovered within --wait-s on a loaded CI machine (30 s, then 60 s).
        cell = CellClient(probe) if args.plan else None
        if cell is not None:
            cell.wait_for_servers(args.wait_s, pick=bool(args.pick))
        parameters = _cell_parameters(probe, args, log)
        model_path, use_stiffness = _model_path(args, parameters)
        tolerances = Tolerances(args.position_tol_mm, args.angle_tol_deg, args.width_tol_mm)
        meta = md.make_metadata(Path(args.out).name, source=args.source or ("sim" if args.scene else "real"),
                                scene_path=args.scene, model_path=model_path, use_stiffness=use_stiffness,
                                parameters=parameters, pick=bool(args.pick), tolerances=tolerances, note=args.note)
        writer = SessionWriter(args.out, meta, time.time_ns())
        recorder = SessionRecorder(writer, FrameSelector(topics.DEPTH_IMAGE, args.depth_period_s,
                                                         args.joint_state_period_s,
                                                         frame_topics=(topics.DEPTH_CAMERA_INFO,),
                                                         paired_topics=(topics.COLOR_IMAGE,)),
                                   record_color=not args.no_color, context=context)
        executor.add_node(recorder)
        try:
            if args.plan:
                cell.recorder = recorder  # every call goes into the bag from here on
                drive(recorder, cell, args)
            else:
                log(f"recording into {args.out} " + (f"for {args.duration_s:g} s" if args.duration_s
                                                     else "until Ctrl-C"))
                wait_passive(context, args.duration_s, lambda: _late_parameters(probe, recorder, meta))
        except KeyboardInterrupt:
            log("stopping (Ctrl-C)")
        path = recorder.finish()
        writer = None
        log(f"wrote {path}: " + ", ".join(f"{t} x{n}" for t, n in sorted(recorder.counts.items())))
        check_complete(path, recorder.errors + [f"a callback raised {e!r}" for e in spin_thread.errors])
        return path
    finally:
        if writer is not None:
            writer.abort()
        executor.shutdown()
        spin_thread.join(10.0)  # before the context goes, or rcl aborts at exit
        context.try_shutdown()


class IncompleteRecording(ValueError):
    """The bag was written, but something the cell used did not reach it (the session cannot replay it)."""


def check_complete(path, errors: list) -> None:
    """IncompleteRecording naming what is missing (a frame the cell used: its replay would compare the cell's
    answer against another frame's), so defgg-record exits 2 instead of 0."""
    if errors:
        shown = "; ".join(errors[:3]) + (f"; ... ({len(errors)} in all)" if len(errors) > 3 else "")
        raise IncompleteRecording(f"{path} is incomplete: {shown}; record it again")


def _late_parameters(probe, recorder, meta) -> None:
    """Nodes started with the recorder (defgg-bringup --record) answer later: add their parameters."""
    missing = [n for n in CELL_NODES if n not in meta["parameters"]]
    late = fetch_all(probe, missing, 1.0) if missing else {}
    if late:
        meta["parameters"] = {**meta["parameters"], **late}
        recorder.update_metadata(meta)


def wait_passive(context, duration_s: float, periodic=lambda: None) -> None:
    """Until duration_s passed (0: forever), Ctrl-C/SIGTERM, or rclpy's own SIGINT handling ends the context.

    Calls `periodic()` every PASSIVE_PERIODIC_S meanwhile.
    """
    end = time.monotonic() + duration_s if duration_s else float("inf")
    next_call = time.monotonic() + PASSIVE_PERIODIC_S
    tick = threading.Event()
    while context.ok() and time.monotonic() < end:
        tick.wait(min(0.5, max(0.0, end - time.monotonic())))
        if time.monotonic() >= next_call and context.ok():
            periodic()
            next_call = time.monotonic() + PASSIVE_PERIODIC_S


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="defgg-record", description=__doc__,
                                     formatter_class=HelpFormatter)
    parser.add_argument("out", help="bag folder to create (must not exist)")
    parser.add_argument("--scene", help="scene YAML the cell runs (sim): embedded so picks can be replayed")
    parser.add_argument("--source", choices=("sim", "real"), help="where it was recorded (default: sim with --scene)")
    parser.add_argument("--model", help="checkpoint the inference node runs (default: asked from the node)")
    parser.add_argument("--note", default="", help="free text stored in the metadata")
    parser.add_argument("--duration-s", type=float, default=0.0, help="passive mode: stop after this long (0: Ctrl-C)")
    parser.add_argument("--plan", type=int, default=0,
                        help="driving mode: PlanGrasp calls to make, one per fresh frame")
    parser.add_argument("--pick", help="driving mode: comma-separated plan indices to pick with "
                                       "(PickAndPlace; 0 = the first PlanGrasp call's grasp)")
    parser.add_argument("--stiffness-from-scene", action="store_true",
                        help="driving mode: first enter the --scene objects' moduli (and parts) via SetStiffness")
    parser.add_argument("--top-k", type=int, default=3, help="grasps per PlanGrasp call")
    parser.add_argument("--frames-between", type=int, default=1,
                        help="fresh grasps to wait for before each PlanGrasp call (lets the scene settle)")
    parser.add_argument("--depth-period-s", type=float, default=DEFAULT_DEPTH_PERIOD_S,
                        help="keep one depth frame per this period (planned-on frames are always kept)")
    parser.add_argument("--joint-state-period-s", type=float, default=DEFAULT_JOINT_STATE_PERIOD_S,
                        help="keep one /joint_states message per this period")
    parser.add_argument("--no-color", action="store_true", help="do not record the colour image")
    parser.add_argument("--position-tol-mm", type=float, default=Tolerances.position_mm,
                        help="replay tolerance stored in the session: grasp position (mm)")
    parser.add_argument("--angle-tol-deg", type=float, default=Tolerances.angle_deg,
                        help="replay tolerance: grasp angle (deg)")
    parser.add_argument("--width-tol-mm", type=float, default=Tolerances.width_mm,
                        help="replay tolerance: grasp width (mm)")
    parser.add_argument("--wait-s", type=float, default=60.0, help="driving mode: wait this long for the servers")
    parser.add_argument("--param-timeout-s", type=float, default=2.0,
                        help="how long to wait for each node's parameter service")
    return parser


def check_args(args) -> None:
    """ValueError naming the first option out of range (before anything connects or writes)."""
    import math

    least = {"--duration-s": (args.duration_s, 0.0), "--plan": (args.plan, 0), "--top-k": (args.top_k, 1),
             "--frames-between": (args.frames_between, 0), "--depth-period-s": (args.depth_period_s, 0.0),
             "--joint-state-period-s": (args.joint_state_period_s, 0.0)}
    positive = {"--position-tol-mm": args.position_tol_mm, "--angle-tol-deg": args.angle_tol_deg,
                "--width-tol-mm": args.width_tol_mm, "--wait-s": args.wait_s, "--param-timeout-s":
                args.param_timeout_s}
    for flag, (value, bound) in least.items():
        if not (math.isfinite(value) and value >= bound):
            raise ValueError(f"{flag} must be >= {bound:g}, got {value:g}")
    for flag, value in positive.items():
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{flag} must be > 0, got {value:g}")
    if args.stiffness_from_scene and not args.scene:
        raise ValueError("--stiffness-from-scene needs --scene")
    _pick_indices(args.pick, args.plan)


def _interrupt(*_):
    raise KeyboardInterrupt


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        check_args(args)
    except ValueError as exc:
        print(f"defgg-record: error: {exc}", file=sys.stderr)
        return 2
    use_large_message_transport()
    # SIGTERM (e.g. from the bringup) ends the recording cleanly, like Ctrl-C; and SIGINT does even when the
    # recorder was started as a shell's background job (which starts with SIGINT ignored).
    previous = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    # Started by a bringup that is then killed: end the bag cleanly instead of recording on, orphaned.
    watch_supervisor("defgg-record")
    try:
        record(args)
    except (SessionBagError, md.MetadataError, CellCallError, SceneError, ValueError) as exc:
        print(f"defgg-record: error: {exc}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0


if __name__ == "__main__":
    sys.exit(main())

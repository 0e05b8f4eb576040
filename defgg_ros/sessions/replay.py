"""defgg-replay: play recorded sessions into a fresh simulated cell and compare with the recording.

For each session: start segmentation + grasp inference (and, when the
session has picks, the fake Panda driver on the recorded scene + the
executor), feed the recorded depth frames and stiffness assignments, replay
the PlanGrasp calls and PickAndPlace goals, and compare grasps (position mm,
angle deg, width mm) and pick outcomes with the recording. Prints a diff
table per session. Exit codes: 0 all matched, 1 regression (a recorded frame
that gets no grasp within --timeout-s is one), 2 a session or the cell could
not be replayed (bad bag, node died, a service or action call timed out).
"""
import argparse
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from tqdm import tqdm

from defgg_ros.cli_help import HelpFormatter
from defgg_ros.ros.cell_client import CellCallError, CellClient
from defgg_ros.ros.domain import PRIVATE_DOMAIN_RANGE, SAFE_DOMAIN_RANGE, pick_private_domain
from defgg_ros.ros.executor import SpinThread, ThreadedExecutor
from defgg_ros.ros.transport import use_large_message_transport
from defgg_ros.sessions import metadata as md
from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.bag import SessionBagError, SessionWriter
from defgg_ros.sessions.compare import Tolerances
from defgg_ros.sessions.params import PERCEPTION_NODES
from defgg_ros.sessions.player import Replay, ReplayOptions, SessionPlayer
from defgg_ros.sessions.recorder_node import SessionRecorder
from defgg_ros.sessions.replay_graph import graph_specs, resolve_model
from defgg_ros.sessions.replay_nodes import GraphError, NodeGraph
from defgg_ros.sessions.report import format_table, regression_message
from defgg_ros.sessions.selector import FrameSelector
from defgg_ros.sessions.session import load_session
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

EXIT_OK, EXIT_REGRESSION, EXIT_ERROR, EXIT_INTERRUPTED = 0, 1, 2, 130
STARTUP_TIMEOUT_S = 90.0
PICK_NODES = ("fake_panda_driver", "executor_node")
# How long a replay listens to a candidate ROS domain for other nodes (discovery on localhost
# takes well under a second, but a loaded machine once needed more than 1.5 s, and at a load of 8 on 2 cores
# more than 3 s: the full test suite, 2026-12-02).
DOMAIN_LISTEN_S = 5.0
# Recorded from the driver; a replay without picks carries them over into an --update.
DRIVER_TOPICS = (topics.JOINT_STATES, st.DRIVER_SCENE)


def find_sessions(paths) -> list[Path]:
    """Bag folders given directly, or every bag folder inside a given folder (sorted)."""
    found = []
    for raw in paths:
        path = Path(raw)
        if (path / "metadata.yaml").is_file() or not path.is_dir():
            found.append(path)  # a bag, or a missing path that load_session reports
        else:
            bags = sorted(p for p in path.iterdir() if (p / "metadata.yaml").is_file())
            if not bags:
                raise SessionBagError(f"{path} holds no session bags (folders with metadata.yaml)")
            found += bags
    return found


def nodes_in_domain(domain_id: int, listen_s: float = DOMAIN_LISTEN_S) -> list:
    """Names of the ROS nodes seen in `domain_id` within listen_s (a probe node of our own)."""
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        probe = rclpy.create_node("defgg_replay_domain_probe", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(probe)
        deadline = time.monotonic() + listen_s
        others = []
        while not others and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
            others = [name for name, _ in probe.get_node_names_and_namespaces() if name != probe.get_name()]
        return others
    finally:
        context.try_shutdown()


def pick_empty_domain(log=print, attempts: int = 5, listen_s: float = DOMAIN_LISTEN_S) -> int:
    """A private domain where no other node answers discovery within listen_s. CI once saw a replay's services
    'appear' 0.0 s after its nodes were launched and then never answer: another graph was there."""
    tried = []
    for _ in range(attempts):
        domain_id = pick_private_domain(exclude=tried)
        others = nodes_in_domain(domain_id, listen_s)
        if not others:
            return domain_id
        log(f"  ROS domain {domain_id} is in use ({', '.join(sorted(others)[:4])}); trying another")
        tried.append(domain_id)
    raise GraphError(f"no free ROS domain among {len(tried)} tried ({tried}); pass --domain-id")


class ReplayRun:
    """One private ROS domain and one player for all the sessions of a command.

    The segmentation + inference nodes are reused from one session to the next while their
    parameters are the same (each session starts by setting its own stiffness assignments); the
    driver and executor of a session with picks are started for it and stopped after (fresh scene).
    """

    def __init__(self, args, log=print):
        self.args, self.log = args, log
        # A ROS domain of its own keeps other graphs on this machine (a running cell, tests, other
        # replays) from feeding it frames.
        self.domain_id = args.domain_id if args.domain_id is not None else pick_empty_domain(log)
        self.run_dir = Path(args.run_dir or tempfile.mkdtemp(prefix="defgg_replay_"))
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain_id)
        self.executor = ThreadedExecutor(num_threads=4, context=self.context)
        self.player = SessionPlayer(context=self.context)
        self.executor.add_node(self.player)
        self.client = CellClient(self.player)
        self.graph = NodeGraph(self.run_dir, self.domain_id)
        self._perception = None   # parameters of the running segmentation + inference nodes
        self._spin_thread = SpinThread(self.executor)

    def _check_alive(self) -> None:
        """Called while waiting: a node of the graph died, or a callback of ours raised (RuntimeError)."""
        self.graph.check_alive()
        self._spin_thread.raise_if_failed()

    def close(self) -> None:
        self.graph.stop_all()
        # Stop spinning and wait for the thread before the context goes (else rcl aborts at exit).
        self.executor.shutdown()
        self._spin_thread.join(10.0)
        self.context.try_shutdown()

    def _start_cell(self, specs: list, pick: bool) -> None:
        perception = [(s.name, s.parameters) for s in specs if s.name in PERCEPTION_NODES]
        if perception != self._perception:
            self.graph.stop(PERCEPTION_NODES)
            for spec in specs:
                if spec.name in PERCEPTION_NODES:
                    self.graph.start(spec)
            self._perception = perception
        for spec in specs:
            if spec.name not in PERCEPTION_NODES:
                self.graph.start(spec)
        started = time.monotonic()
        self.client.wait_for_servers(STARTUP_TIMEOUT_S, pick, self._check_alive)
        self.log(f"  cell ready after {time.monotonic() - started:.1f} s (node logs in {self.run_dir})")

    def replay(self, path: Path) -> tuple[int, str]:
        """Replay one session; (exit code, message)."""
        args, log = self.args, self.log
        session = load_session(path)
        meta = session.metadata
        tolerances = _tolerances(args, md.tolerances_of(meta))
        pick = md.pick_enabled(meta) and not args.no_pick and bool(session.picks)
        model = resolve_model(meta, args.model, args.use_stiffness)
        log(f"session {path.name}: {len(session.frames)} frame(s), {len(session.of_kind('plan'))} plan call(s), "
            f"{len(session.picks)} pick(s){'' if pick else ' (picks skipped)'}; {model.describe(meta)}")
        unrecorded = [name for name in PERCEPTION_NODES if name not in (meta.get("parameters") or {})]
        if unrecorded:
            log(f"  no recorded parameters for {', '.join(unrecorded)}: running the shipped YAML "
                "(sim_bringup/config); a difference may be the cell's parameters, not a regression")
        writer = recorder = None
        try:
            # Latched before the cell starts: the perception nodes hold the recorded camera pose before a frame.
            transforms = self.player.publish_static_transforms(session.static_transforms)
            if transforms:
                log(f"  {transforms} recorded static transform(s) on {topics.TF_STATIC} (the camera's pose)")
            self._start_cell(graph_specs(meta, model, pick, self.run_dir), pick)
            if args.update:
                new_meta = md.updated_metadata(meta, model.path, model.use_stiffness, tolerances)
                writer = SessionWriter(path, new_meta, time.time_ns(), overwrite=True)
                selector = FrameSelector(topics.DEPTH_IMAGE, paired_topics=(topics.COLOR_IMAGE,))
                recorder = SessionRecorder(writer, selector, live=False, context=self.context)
                self.executor.add_node(recorder)
                recorder.copy_messages(session.static_transforms)
                if not pick:  # no driver runs: keep the recorded robot state and scene as they were
                    recorder.copy_messages([m for m in session.messages if m.topic in DRIVER_TOPICS])
            options = ReplayOptions(tolerances, pick=pick, grasp_timeout_s=args.timeout_s,
                                    pick_timeout_s=args.pick_timeout_s)
            replay = Replay(session, self.player, self.client, options, self._check_alive, log, recorder)
            rows = replay.run()
            if recorder is not None:
                recorder.finish()
                writer = None
        finally:
            if writer is not None:
                writer.abort()
            if recorder is not None:
                self.executor.remove_node(recorder)
                recorder.destroy_node()
            self.graph.stop(PICK_NODES)
        if replay.uncompared_frames:
            log(f"({replay.uncompared_frames} frame(s) had no recorded grasp — the live cell skipped them — "
                "and were not compared)")
        log(format_table(f"\n{path.name} (tolerances: {tolerances.position_mm:g} mm, "
                         f"{tolerances.angle_deg:g} deg, {tolerances.width_mm:g} mm)", rows))
        if args.update:
            return EXIT_OK, f"{path.name}: expectations re-recorded into {path}"
        if not rows:   # nothing recorded to compare with: a pass here would check nothing
            return EXIT_ERROR, (f"{path.name}: nothing to compare (no frame with a recorded grasp, no plan or pick "
                                "call): record the session again with the cell running")
        message = regression_message(path.name, rows, model.change_from(meta), str(path))
        return (EXIT_REGRESSION, message) if message else (EXIT_OK, f"{path.name}: all {len(rows)} item(s) match")


def _tolerances(args, recorded: Tolerances) -> Tolerances:
    changes = {k: v for k, v in (("position_mm", args.position_tol_mm), ("angle_deg", args.angle_tol_deg),
                                 ("width_mm", args.width_tol_mm)) if v is not None}
    return replace(recorded, **changes)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="defgg-replay", description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument("sessions", nargs="+", help="session bag folders, or folders of them "
                                                    "(e.g. sim_bringup/sessions)")
    parser.add_argument("--update", action="store_true",
                        help="re-record the expectations on purpose: replace each session with this replay's "
                             "grasps and pick outcomes (inputs unchanged)")
    parser.add_argument("--no-pick", action="store_true", help="skip the picks (no simulator); compare grasps only")
    parser.add_argument("--model", help="checkpoint to replay with instead of the shipped model the session names")
    parser.add_argument("--use-stiffness", choices=("true", "false"),
                        help="stiffness input on/off (default: from --model's checkpoint, else as recorded)")
    parser.add_argument("--position-tol-mm", type=float, help="grasp position tolerance (default: as recorded)")
    parser.add_argument("--angle-tol-deg", type=float, help="grasp angle tolerance (default: as recorded)")
    parser.add_argument("--width-tol-mm", type=float, help="grasp width tolerance (default: as recorded)")
    parser.add_argument("--timeout-s", type=float, default=30.0,
                        help="how long to wait for a frame's grasp (s); none by then: a regression")
    parser.add_argument("--pick-timeout-s", type=float, default=300.0, help="how long a pick may take (s)")
    parser.add_argument("--domain-id", type=int,
                        help="ROS_DOMAIN_ID of the replay's private graph (default: a random one in "
                             f"{PRIVATE_DOMAIN_RANGE[0]}..{PRIVATE_DOMAIN_RANGE[1]}, not the caller's, where no "
                             f"other node answers discovery within {DOMAIN_LISTEN_S:g} s)")
    parser.add_argument("--run-dir", help="folder for the nodes' logs (default: a new temporary folder)")
    return parser


def check_args(args) -> None:
    """ValueError naming the first option out of range (before any node starts)."""
    for flag, value in (("--position-tol-mm", args.position_tol_mm), ("--angle-tol-deg", args.angle_tol_deg),
                        ("--width-tol-mm", args.width_tol_mm)):
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{flag} must be >= 0 (0: exact), got {value:g}")
    for flag, value in (("--timeout-s", args.timeout_s), ("--pick-timeout-s", args.pick_timeout_s)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{flag} must be > 0, got {value:g}")
    low, high = SAFE_DOMAIN_RANGE
    if args.domain_id is not None and not low <= args.domain_id <= high:
        raise ValueError(f"--domain-id must be in {low}..{high} (higher ids map to ports in Linux's ephemeral "
                         f"range), got {args.domain_id}")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        check_args(args)
    except ValueError as exc:
        print(f"defgg-replay: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    use_large_message_transport()
    try:
        paths = find_sessions(args.sessions)
    except SessionBagError as exc:
        print(f"defgg-replay: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    results = []
    try:
        run = ReplayRun(args, log=tqdm.write)
    except GraphError as exc:
        print(f"defgg-replay: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    try:
        for path in tqdm(paths, desc="sessions", unit="session", disable=len(paths) < 2):
            try:
                results.append(run.replay(path))
            except (SessionBagError, md.MetadataError, GraphError, CellCallError, ValueError) as exc:
                results.append((EXIT_ERROR, f"{path.name}: cannot replay: {exc}"))
    except KeyboardInterrupt:
        print("defgg-replay: interrupted; stopping the nodes", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        run.close()
    print()
    for code, message in results:  # the verdicts last, where CI logs end
        print(message, file=sys.stderr if code else sys.stdout)
    worst = max(code for code, _ in results)
    print(f"defgg-replay: {len(results)} session(s): "
          + {EXIT_OK: "all match", EXIT_REGRESSION: "REGRESSION", EXIT_ERROR: "ERROR"}[worst],
          file=sys.stderr if worst else sys.stdout)
    return worst


if __name__ == "__main__":
    sys.exit(main())

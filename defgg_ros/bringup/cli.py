"""defgg-bringup: start the cell's nodes as separate processes and supervise them.

    defgg-bringup                       # simulated cell: driver, segmentation, inference, executor
    defgg-bringup --set real_cell       # the three non-simulated nodes (real robot + camera drivers run apart)
    defgg-bringup --scene sim_bringup/scenes/soft_box.yaml --gui
    defgg-bringup --ros-domain 42       # the sim cell in domain 42 (localhost-only discovery)

ROS domain: the simulated cell runs in a private, random domain with
localhost-only discovery (the first log line names it), so it never reaches a
real arm's controller; `--ros-domain inherit` (or DEFGG_ROS_DOMAIN=inherit)
uses the shell's ROS_DOMAIN_ID and discovery. The real cell inherits them and
warns when it finds a simulated driver on that domain.

Waits until every node is ready (its service/action/topic is in the ROS
graph), forwards their logs as '[node] ...', and stops them all on Ctrl-C /
SIGTERM or as soon as one dies (naming it; exit code 1).
"""
import argparse
import os
import signal
import sys
import threading
import time

from defgg_ros.bringup.node_set import NodeSetError, load_node_set
from defgg_ros.bringup.shared_parameters import disagreements, effective_parameters
from defgg_ros.bringup.supervisor import DEFAULT_READY_TIMEOUT_S, Bringup, BringupError
from defgg_ros.cli_help import HelpFormatter
from defgg_ros.ros.domain import ISOLATION_ENV, apply_domain_choice, parse_domain_choice
from defgg_ros.ros.launcher import watch_supervisor
from defgg_ros.ros.parameters import check_value, coerce_value, load_schema, schema_path
from defgg_ros.ros.share import demo_scene_file
from defgg_ros.sim.scene_spec import SceneError, load_scene

DRIVER = "fake_panda_driver"
EXECUTOR = "executor_node"


def parse_args(argv=None):
    parser = argparse.ArgumentParser(prog="defgg-bringup", description=__doc__,
                                     formatter_class=HelpFormatter)
    parser.add_argument("--set", default="sim_cell",
                        help="node set: a name in sim_bringup/config (sim_cell; real_cell: FR3; "
                             "real_cell_fer: Panda, franka_ros2 robot_type fer) or a YAML path")
    parser.add_argument("--scene", help="scene YAML for the simulated driver (default: its parameter file's)")
    parser.add_argument("--gui", action="store_true", help="open PyBullet's GUI (the driver is headless by default)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NODE:NAME:=VALUE",
                        help="override one node parameter, e.g. -p fake_panda_driver:max_real_time_factor:=0")
    parser.add_argument("--ready-timeout", type=float, default=DEFAULT_READY_TIMEOUT_S,
                        help="seconds to wait for every node to become ready")
    parser.add_argument("--ros-domain", default=None, metavar="private|inherit|ID",
                        help="ROS domain of the cell's graph: private (sim sets' default: random id, localhost-only "
                             "discovery), inherit (the shell's; real_cell's default) or an id (localhost-only); "
                             f"default also from ${ISOLATION_ENV}")
    parser.add_argument("--record", metavar="PATH",
                        help="also record the session to this bag folder (runs defgg-record alongside)")
    return parser.parse_args(argv)


def parse_overrides(args) -> dict:
    overrides = {}
    for item in args.param:
        node, sep, rest = item.partition(":")
        name, sep2, value = rest.partition(":=")
        if not (sep and sep2 and node and name):
            raise NodeSetError(f"--param {item!r}: expected NODE:NAME:=VALUE")
        overrides.setdefault(node, {})[name] = _yaml_scalar(value)
    if args.scene:
        overrides.setdefault(DRIVER, {})["scene_file"] = args.scene
    if args.gui:
        overrides.setdefault(DRIVER, {})["gui"] = True
    return overrides


def checked_overrides(node_set, overrides: dict) -> dict:
    """The overrides with values in their schema's type (`:=0` for a double is 0.0: rclpy refuses an integer
    for a double parameter). NodeSetError for an override of a node the set does not start, of a parameter its
    schema does not declare, or with a value its schema refuses; and for a scene file that is not a valid scene.
    Checked before any process starts: a typo would otherwise leave the parameter at its default (or kill a node
    mid start-up)."""
    names = [entry.name for entry in node_set.nodes]
    out = {}
    for node, params in overrides.items():
        if node not in names:
            raise NodeSetError(f"--param/--scene/--gui: node {node!r} is not in node set {node_set.name!r} "
                               f"(it starts {', '.join(names)})")
        if not schema_path(node).is_file():
            out[node] = dict(params)
            continue
        specs = load_schema(node)
        out[node] = {}
        for name, value in params.items():
            if name not in specs:
                raise NodeSetError(f"--param {node}:{name}: {node} has no parameter {name!r} "
                                   f"(see defgg_ros/ros/params/{node}.yaml)")
            out[node][name] = coerce_value(specs[name], value)
            problem = check_value(specs[name], out[node][name])
            if problem:
                raise NodeSetError(f"--param {node}:{problem}")
    scene = out.get(DRIVER, {}).get("scene_file")
    if scene:
        try:
            load_scene(scene)
        except SceneError as exc:
            raise NodeSetError(f"--scene: {exc}") from None
    return out


def check_cell_parameters_agree(node_set, overrides: dict) -> None:
    """NodeSetError when the nodes would start with different values for one cell's geometry or arm
    (bringup/shared_parameters.py): each would act on its own idea of the table, frame or camera."""
    lines = disagreements(node_set, overrides)
    if lines:
        raise NodeSetError("the nodes disagree on the cell (set one value for every node, e.g. in "
                           "sim_bringup/config/real_cell/<robot>.yaml, or -p for each):\n  " + "\n  ".join(lines))


def _yaml_scalar(text):
    import yaml

    return yaml.safe_load(text) if text else ""


def record_hook(path: str, node_set, overrides: dict) -> dict:
    """The recorder as one more supervised process (its CLI: defgg_ros/sessions/record.py), its exit code
    the recorder's own. On a set with the simulated driver the session records the scene that driver runs
    (--scene, or its parameter files' scene_file): a simulated session, replayable with its picks."""
    argv = [sys.executable, "-c", "import sys; from defgg_ros.sessions.record import main; sys.exit(main())", path]
    driver = next((entry for entry in node_set.nodes if entry.name == DRIVER), None)
    if driver is not None:
        scene = effective_parameters(driver, overrides.get(DRIVER)).get("scene_file") or demo_scene_file()
        argv += ["--scene", str(scene)]
    return {"recorder": argv}


# How often the real cell looks again for a simulated driver on its domain (s).
INTRUDER_CHECK_PERIOD_S = 30.0


def domain_choice(args, node_set, env=None) -> str | int:
    """--ros-domain, else $DEFGG_ROS_DOMAIN, else the node set's own default (sim: private, real: inherit)."""
    env = os.environ if env is None else env
    text = args.ros_domain or env.get(ISOLATION_ENV) or node_set.ros_domain
    return parse_domain_choice(text)


def warn_about_intruders(bringup: Bringup) -> list:
    """Print a warning for every node of the set's warn_if_present list found on its domain; returns them."""
    wanted = bringup.node_set.warn_if_present
    found = bringup.nodes_present(wanted)
    print(f"defgg-bringup: looked for {', '.join(wanted)} on this domain: "
          f"{'found ' + ', '.join(found) if found else 'none'}", flush=True)
    for name in found:
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        print(f"defgg-bringup: WARNING: node '{name}' (a simulated driver) is running on this ROS domain "
              f"(ROS_DOMAIN_ID={domain}): it may answer in the real robot's place; stop it or move it to "
              "another domain", file=sys.stderr, flush=True)
    return found


def supervise(bringup: Bringup, stop_requested: threading.Event) -> int:
    """Until Ctrl-C/SIGTERM (exit 0) or a node dies (exit 1)."""
    next_check = time.monotonic() + INTRUDER_CHECK_PERIOD_S
    while not stop_requested.wait(0.2):
        dead = bringup.failed_node()
        if dead is not None:
            print(f"defgg-bringup: {dead.describe()}; stopping the others", file=sys.stderr, flush=True)
            return 1
        if bringup.node_set.warn_if_present and time.monotonic() >= next_check:
            next_check = time.monotonic() + INTRUDER_CHECK_PERIOD_S
            warn_about_intruders(bringup)
    print("defgg-bringup: stop requested; stopping the nodes", flush=True)
    return 0


def main(argv=None) -> int:
    args = parse_args(argv)
    stop_requested = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop_requested.set())
    watch_supervisor("defgg-bringup")   # started by a process that was then killed: stop the nodes in order
    try:
        node_set = load_node_set(args.set)
        # First, before any rclpy context or child process exists: they read the domain at start-up.
        print(f"defgg-bringup: {apply_domain_choice(domain_choice(args, node_set))}", flush=True)
        overrides = checked_overrides(node_set, parse_overrides(args))
        check_cell_parameters_agree(node_set, overrides)
        extra = record_hook(args.record, node_set, overrides) if args.record else {}
        bringup = Bringup(node_set, overrides, extra)
    except (NodeSetError, BringupError, ValueError) as exc:
        print(f"defgg-bringup: {exc}", file=sys.stderr)
        return 2
    code = 1
    try:
        bringup.start()
        started = ", ".join(f"{name} (pid {proc.pid})" for name, proc in bringup.processes.items())
        print(f"defgg-bringup: started {started}; waiting until ready", flush=True)
        took = bringup.wait_ready(args.ready_timeout, stop_requested)
        print(f"defgg-bringup: cell ready in {took:.1f} s ({node_set.name})", flush=True)
        if node_set.warn_if_present:
            warn_about_intruders(bringup)
        code = supervise(bringup, stop_requested)
    except BringupError as exc:
        print(f"defgg-bringup: {exc}", file=sys.stderr, flush=True)
        code = 0 if stop_requested.is_set() else 1
    finally:
        codes = bringup.stop()   # reverse start order: the executor (which stops the arm) before the driver
        print("defgg-bringup: stopped " + ", ".join(f"{n} ({c})" for n, c in codes.items()), flush=True)
    if codes.get(EXECUTOR, 0) != 0:
        # The executor exits non-zero when it could not confirm the arm at rest (or failed): say so, and so do we.
        print(f"defgg-bringup: WARNING: {EXECUTOR} exited {codes[EXECUTOR]}: it may not have stopped the arm "
              "(its last lines above); check the arm", file=sys.stderr, flush=True)
        code = code or 1
    if codes.get("recorder", 0) != 0:   # --record: the session is missing or incomplete (its lines above)
        print(f"defgg-bringup: WARNING: the recorder exited {codes['recorder']}: the session is not complete "
              "(its last lines above)", file=sys.stderr, flush=True)
        code = code or 1
    return code


if __name__ == "__main__":
    sys.exit(main())

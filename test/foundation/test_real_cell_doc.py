"""Every command in docs/real_cell.md's ```bash blocks is one this test checks against what it names.

Commands of this package are checked for real: launch files are evaluated with the doc's arguments (the
launch_recorder stand-in), `defgg-bringup` command lines go through the CLI's own parser and its checks of node
sets, parameters and cell agreement, `ros2 param set` against the schema's bounds and read_only flags, service and
action calls against the interface files. Commands of franka_ros2, realsense2_camera, ros2_control and tf2_ros are
checked against the facts read from their sources (docs/real_cell.md, section 8), held here as lists. A command
no checker knows fails the test: a new command in the doc needs a check here.
"""
import re
import sys
from pathlib import Path

import pytest
import yaml
from support.doc_commands import SHARE_TOKEN, DocCommand, commands, option_value
from support.setup_capture import console_scripts, installed_files
from test_franka_controllers import CONTROLLERS, JTC, controller_manager_entries, load_ros_parameter_file

from defgg_ros.bringup import cli
from defgg_ros.bringup.node_set import load_node_set
from defgg_ros.ros import topics
from defgg_ros.ros.parameters import check_value, coerce_value, defaults, load_schema

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "real_cell.md"
RECORDER_DIR = REPO / "test" / "support" / "launch_recorder"
PLACEHOLDER = re.compile(r"^<[a-z0-9-]+>$")          # a value the reader fills in, e.g. <robot-ip>
CLONE_DIR = "src/defgg_ros"                          # where the doc clones this repository

# --- facts read from the sources (docs/real_cell.md, section 8) ---
FRANKA_REPO, FRANKA_RELEASE = "https://github.com/frankarobotics/franka_ros2.git", "v3.4.0"
FRANKA_LAUNCH_ARGUMENTS = {"robot_type", "arm_prefix", "namespace", "robot_ip", "load_gripper", "use_fake_hardware",
                           "fake_sensor_commands", "joint_state_rate", "load_franka_robot_state_broadcaster",
                           "controllers_yaml"}                          # franka_bringup/launch/franka.launch.py
MOVEIT_LAUNCH_ARGUMENTS = {"robot_ip", "namespace", "load_gripper", "ee_id", "use_fake_hardware",
                           "fake_sensor_commands", "db"}          # franka_fr3_moveit_config/launch/moveit.launch.py
RS_LAUNCH_ARGUMENTS = {"camera_name", "camera_namespace", "depth_module.depth_profile", "pointcloud.enable",
                       "align_depth.enable", "enable_color", "enable_depth", "publish_tf",
                       "tf_publish_rate"}                       # realsense2_camera rs_launch.py (part)
SPAWNER_VALUE_OPTIONS = {"-c", "--controller-manager", "--controller-manager-timeout", "-p", "--param-file",
                         "--switch-timeout", "--service-call-timeout"}       # controller_manager/spawner.py
SPAWNER_FLAGS = {"--inactive", "--load-only", "-u", "--unload-on-kill", "--activate-as-group"}
STATIC_TF_OPTIONS = {"--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw", "--roll", "--pitch", "--yaw",
                     "--frame-id", "--child-frame-id"}          # tf2_ros static_transform_publisher (Jazzy)
REALSENSE_ROOT_FRAME = "camera_link"                  # realsense2_camera: camera_link -> ... -> optical frame
APT_PACKAGES = {"ros-jazzy-realsense2-camera", "python3-pip"}    # both in Jazzy / Ubuntu 24.04
ROS_SETUP_FILES = {"/opt/ros/jazzy/setup.bash", "install/setup.bash"}
ROS2_READ_ONLY = {("control", "list_controllers"), ("action", "list")}


def base_frames() -> set[str]:
    return {topics.robot_names(robot_type)["base_frame"] for robot_type in topics.ROBOT_TYPES}


def default_topic_names() -> set[str]:
    """Every topic a node of this package reads or writes by default (the schemas' *_topic parameters)."""
    names = set()
    for node in ("executor_node", "grasp_inference_node", "segmentation_node", "fake_panda_driver"):
        names |= {value for name, value in defaults(node).items() if name.endswith("_topic") and value}
    return names


def strip_environment(argv: tuple) -> tuple:
    index = 0
    while index < len(argv) and re.match(r"^[A-Z_][A-Z0-9_]*=", argv[index]):
        index += 1
    return argv[index:]


def launch_arguments(argv) -> dict:
    pairs = {}
    for token in argv:
        name, sep, value = token.partition(":=")
        assert sep, f"launch argument {token!r} is not NAME:=VALUE"
        pairs[name] = value
    return pairs


def resolve_share(value: str) -> Path:
    """`$(ros2 pkg prefix --share defgg_ros)/x` -> the repository file installed as share/defgg_ros/x."""
    prefix = SHARE_TOKEN.format("defgg_ros")
    assert value.startswith(prefix + "/"), f"{value}: not a path in defgg_ros's share folder"
    destination = "share/defgg_ros/" + value[len(prefix) + 1:]
    source = installed_files().get(destination)
    assert source, f"{destination} is not installed by setup.py"
    return REPO / source


def arm_controllers() -> dict:
    raw = load_ros_parameter_file(CONTROLLERS)
    return {name: raw["/**"][name]["ros__parameters"] for name, entry in controller_manager_entries(raw).items()
            if isinstance(entry, dict) and entry.get("type") == JTC}


# --- one checker per command ---

def check_shell(argv):
    if argv[0] == "source":
        assert argv[1] in ROS_SETUP_FILES, argv
    elif argv[0] == "sudo":
        assert argv[1:3] == ("apt", "install") and set(argv[3:]) <= APT_PACKAGES, argv
    # mkdir, cd: nothing to check


def check_git(argv):
    assert argv[1] == "clone", argv
    if FRANKA_REPO in argv:
        assert option_value(argv, "--branch") == FRANKA_RELEASE and argv[-1] == "src/franka_ros2", argv
    else:
        assert PLACEHOLDER.match(argv[2]) and argv[3] == CLONE_DIR, argv


def check_vcs(argv):
    # franka's README: vcs import src < <its checkout>/dependency.repos --recursive --skip-existing
    assert argv[1:4] == ("import", "src", "<") and argv[4] == "src/franka_ros2/dependency.repos", argv


def check_ln(argv):
    assert argv[1] == "-s", argv
    target, link = argv[2], argv[3]
    assert Path(CLONE_DIR).name == target.split("/")[0], f"{target}: not inside {CLONE_DIR}"
    package = REPO / Path(*target.split("/")[1:]) / "package.xml"
    name = re.search(r"<name>(.+?)</name>", package.read_text(encoding="utf-8")).group(1)
    assert link == f"src/{name}", f"the link must be named after the package it holds ({name})"


def check_rosdep(argv):
    if argv[1] == "update":
        return
    assert argv[1] == "install" and option_value(argv, "--from-paths") == "src", argv
    assert option_value(argv, "--rosdistro") == "jazzy" and "--ignore-src" in argv and "-y" in argv, argv
    # its --skip-keys: test_real_cell_install.py


def check_pip(argv):
    assert argv[1] == "install", argv
    path = option_value(argv, "-r")
    assert path and path.startswith(CLONE_DIR + "/"), argv
    assert (REPO / path[len(CLONE_DIR) + 1:]).is_file(), path


def check_colcon(argv):
    assert argv[1] == "build" and "--symlink-install" not in argv, "plain colcon build (docs/real_cell.md, 1.)"
    assert "-DBUILD_TESTING=OFF" in argv   # as test_colcon.py's build, which runs this build


def check_franka_launch(argv):
    arguments = launch_arguments(argv[4:])
    assert set(arguments) <= FRANKA_LAUNCH_ARGUMENTS, set(arguments) - FRANKA_LAUNCH_ARGUMENTS
    assert arguments.get("robot_type") in topics.ROBOT_TYPES, "franka.launch.py's robot_type has no default"
    assert arguments.get("load_gripper") == "true", "the executor needs the gripper (default false)"
    assert PLACEHOLDER.match(arguments["robot_ip"]), arguments
    controllers = resolve_share(arguments["controllers_yaml"])
    assert controllers == CONTROLLERS
    assert topics.robot_names(arguments["robot_type"])["arm_controller"] in arm_controllers()


def check_moveit_launch(argv):
    arguments = launch_arguments(argv[4:])
    assert set(arguments) <= MOVEIT_LAUNCH_ARGUMENTS and "robot_ip" in arguments, arguments   # robot_ip: required


def check_realsense_launch(argv):
    arguments = launch_arguments(argv[4:])
    assert set(arguments) <= RS_LAUNCH_ARGUMENTS, set(arguments) - RS_LAUNCH_ARGUMENTS
    if "depth_module.depth_profile" in arguments:
        width, height, fps = arguments["depth_module.depth_profile"].split("x")
        assert int(width) * int(height) <= 1280 * 800 and int(fps) > 0   # within the nodes' max_image_size_px


def check_own_launch(argv):
    sys.path.insert(0, str(RECORDER_DIR))
    try:
        import recorder
        from test_launch_files import load_launch_file

        path = REPO / "sim_bringup" / "launch" / argv[3]
        assert path.is_file() and (f"share/defgg_ros/launch/{argv[3]}" in installed_files()), argv[3]
        recorder.evaluate(load_launch_file(path), launch_arguments(argv[4:]), {"defgg_ros": REPO})
    finally:
        sys.path.remove(str(RECORDER_DIR))
        for name in [n for n in sys.modules if n.split(".")[0] in ("launch", "launch_ros", "recorder")]:
            del sys.modules[name]


def check_bringup(argv):
    args = cli.parse_args(list(argv))
    node_set = load_node_set(args.set)
    overrides = cli.checked_overrides(node_set, cli.parse_overrides(args))
    cli.check_cell_parameters_agree(node_set, overrides)
    if args.ros_domain is not None:
        cli.domain_choice(args, node_set, env={})


def check_spawner(argv):
    name, index = argv[4], 5
    assert name in arm_controllers(), f"{name} is not a JointTrajectoryController of {CONTROLLERS.name}"
    while index < len(argv):
        if argv[index] in SPAWNER_VALUE_OPTIONS:
            index += 2
        else:
            assert argv[index] in SPAWNER_FLAGS, f"spawner has no option {argv[index]}"
            index += 1


def check_static_transform(argv):
    options = dict(zip(argv[4::2], argv[5::2]))
    assert set(options) <= STATIC_TF_OPTIONS, set(options) - STATIC_TF_OPTIONS
    assert options["--frame-id"] in base_frames() and options["--child-frame-id"] == REALSENSE_ROOT_FRAME
    norm = sum(float(options[k]) ** 2 for k in ("--qx", "--qy", "--qz", "--qw")) ** 0.5
    assert abs(norm - 1.0) < 0.01, f"quaternion norm {norm:.4f}"


def check_tf2_echo(argv):
    assert argv[4] in base_frames() and argv[5] == topics.CAMERA_OPTICAL_FRAME, argv


def check_ros2_run(argv):
    package, executable = argv[2], argv[3]
    if package == "defgg_ros":
        assert executable in console_scripts(), f"{executable} is not a console script of setup.py"
        assert executable == "defgg-bringup", f"no checker for {executable}"
        check_bringup(argv[4:])
    elif (package, executable) == ("controller_manager", "spawner"):
        check_spawner(argv)
    elif (package, executable) == ("tf2_ros", "static_transform_publisher"):
        check_static_transform(argv)
    elif (package, executable) == ("tf2_ros", "tf2_echo"):
        check_tf2_echo(argv)
    else:
        raise AssertionError(f"no checker for ros2 run {package} {executable}")


def check_ros2_launch(argv):
    launchers = {("franka_bringup", "franka.launch.py"): check_franka_launch,
                 ("franka_fr3_moveit_config", "moveit.launch.py"): check_moveit_launch,
                 ("realsense2_camera", "rs_launch.py"): check_realsense_launch}
    if argv[2] == "defgg_ros":
        check_own_launch(argv)
    else:
        launchers[(argv[2], argv[3])](argv)


def check_ros2_topic(argv):
    name = argv[-1]
    assert name.startswith("/") and name[1:] in default_topic_names(), f"{name}: no node's default topic"


def check_ros2_param(argv):
    assert argv[2] == "set", argv
    node, name, value = argv[3].lstrip("/"), argv[4], yaml.safe_load(argv[5])
    spec = load_schema(node)[name]
    assert not spec.read_only, f"{node}:{name} is read-only: it cannot be set at run time"
    assert check_value(spec, coerce_value(spec, value)) is None, check_value(spec, value)


def interface_file(type_name: str) -> Path:
    package, kind, name = type_name.split("/")
    roots = {"defgg_interfaces": REPO / "msg_defs", "franka_msgs": REPO / "vendor_interfaces" / "franka_msgs"}
    return roots[package] / kind / f"{name}.{kind}"


def check_ros2_action_goal(argv):
    assert argv[2] == "send_goal", argv
    name, type_name, goal = argv[3], argv[4], yaml.safe_load(argv[5])
    assert name[1:] in {topics.GRIPPER_HOMING_ACTION, topics.GRIPPER_MOVE_ACTION, topics.GRIPPER_GRASP_ACTION,
                        topics.ERROR_RECOVERY_ACTION}
    assert interface_file(type_name).is_file() and isinstance(goal, dict), argv


def check_ros2_service(argv):
    assert argv[2] == "call", argv
    name, type_name, request = argv[3], argv[4], yaml.safe_load(argv[5])
    assert name[1:] == defaults("grasp_inference_node")["plan_grasp_service"], name
    definition = interface_file(type_name).read_text(encoding="utf-8").split("---")[0]
    fields = {line.split()[1] for line in definition.splitlines() if line.strip() and not line.startswith("#")}
    assert set(request) <= fields, set(request) - fields


def check_ros2_control(argv):
    """A robot error's recovery: the hardware component by its franka_ros2 name, then every controller the error
    deactivated (both broadcasters and one robot type's arm controller)."""
    if argv[2] == "set_hardware_component_state":
        assert list(argv[3:]) == [topics.FRANKA_HARDWARE_COMPONENT, "active"], argv
        return
    assert argv[2] == "switch_controllers" and argv[3] == "--activate", argv
    arm_controllers = {topics.robot_names(t)["arm_controller"] for t in topics.ROBOT_TYPES}
    names = set(argv[4:])
    assert {topics.JOINT_STATE_BROADCASTER, topics.ROBOT_STATE_BROADCASTER} <= names, argv
    assert len(names & arm_controllers) == 1 and len(names) == 3, argv


def check_ros2(argv):
    verb = argv[1]
    if (verb, argv[2]) in ROS2_READ_ONLY:
        return
    handlers = {"run": check_ros2_run, "launch": check_ros2_launch, "topic": check_ros2_topic,
                "param": check_ros2_param, "service": check_ros2_service, "control": check_ros2_control}
    if verb == "action":
        check_ros2_action_goal(argv)
    else:
        handlers[verb](argv)


CHECKERS = {"source": check_shell, "mkdir": check_shell, "cd": check_shell, "sudo": check_shell,
            "git": check_git, "vcs": check_vcs, "ln": check_ln, "rosdep": check_rosdep, "pip": check_pip,
            "colcon": check_colcon, "ros2": check_ros2, "defgg-bringup": lambda argv: check_bringup(argv[1:])}


def doc_commands() -> list[DocCommand]:
    return commands(DOC)


def readme_commands() -> list[DocCommand]:
    """The README's short version of the same steps (its section "The real cell")."""
    return commands(REPO / "README.md", section="The real cell")


@pytest.mark.parametrize("command", [pytest.param(c, id=f"real_cell.md-line{c.line}") for c in doc_commands()]
                         + [pytest.param(c, id=f"README.md-line{c.line}") for c in readme_commands()])
def test_the_command_names_existing_files_executables_arguments_and_parameters(command):
    argv = strip_environment(command.argv)
    assert argv[0] in CHECKERS, f"{command}: no checker for {argv[0]!r} (add one, or drop the command)"
    try:
        CHECKERS[argv[0]](argv)
    except (AssertionError, KeyError, ValueError, cli.NodeSetError) as exc:
        raise AssertionError(f"{command}: {exc!r}") from exc


def test_the_readme_shows_the_start_commands():
    assert len(readme_commands()) == 4, [str(c) for c in readme_commands()]


def test_the_doc_walks_through_install_start_checks_and_rehearsal():
    firsts = [strip_environment(c.argv)[:4] for c in doc_commands()]
    order = [("git", "clone", "--branch", FRANKA_RELEASE), ("rosdep", "install", "--from-paths", "src"),
             ("ros2", "launch", "franka_bringup", "franka.launch.py"),
             ("ros2", "run", "controller_manager", "spawner"), ("ros2", "launch", "realsense2_camera", "rs_launch.py"),
             ("ros2", "launch", "defgg_ros", "real_cell.launch.py"), ("ros2", "run", "defgg_ros", "defgg-bringup")]
    positions = [firsts.index(step) for step in order]
    assert positions == sorted(positions), "the commands are out of order"


def test_the_checkers_refuse_what_is_wrong():
    with pytest.raises(AssertionError):
        check_spawner(("ros2", "run", "controller_manager", "spawner", "panda_arm_controller"))
    with pytest.raises(ValueError):
        check_own_launch(("ros2", "launch", "defgg_ros", "real_cell.launch.py", "robot_type:=panda"))
    with pytest.raises(cli.NodeSetError):
        check_bringup(("--set", "real_cell", "-p", "executor_node:arm_id:=fr3"))
    with pytest.raises(AssertionError):
        check_ros2_param(("ros2", "param", "set", "/executor_node", "robot_type", "fr3"))   # read-only
    with pytest.raises(AssertionError):   # the broadcasters stay inactive after a robot error
        check_ros2_control(("ros2", "control", "switch_controllers", "--activate", "fr3_arm_controller"))
    with pytest.raises(AssertionError):
        check_ros2_control(("ros2", "control", "set_hardware_component_state", "fr3_hardware", "active"))
    with pytest.raises(AssertionError):
        check_franka_launch(("ros2", "launch", "franka_bringup", "franka.launch.py", "arm_id:=fr3",
                             "robot_ip:=<robot-ip>"))

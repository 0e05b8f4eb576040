"""Shared test set-up: markers, a per-test timeout, ROS isolation per test process, rclpy fixtures, waits.

Each pytest process gets its own ROS_DOMAIN_ID and localhost-only discovery
so parallel runs (and a cell running on the same machine) never cross-talk.

Markers (every test gets exactly one kind; `make check` runs `-m "not e2e and not slow"`, the slow list below):
  unit  pure Python/numpy/torch, no DDS, no PyBullet
  ros   real rclpy nodes over real DDS in this process or a few child processes
  sim   PyBullet (FEM trials, the simulated cell's physics)
  e2e   whole cell or whole offline pipeline: several processes, tens of seconds to minutes
A module sets `pytestmark = pytest.mark.<kind>` or is listed in this file's kind table (UNIT_MODULES ...);
a test's own kind marker wins. A test of a module in neither place fails, naming the table. Helpers shared
between test modules live in test/support/ (a package; pytest puts test/ on sys.path because this conftest sits
there, so no sys.path edits are needed).

Timeout: every test phase (set-up, call, tear-down) is stopped after DEFGG_TEST_TIMEOUT_S seconds
(default 300; e2e tests 900) or `@pytest.mark.timeout(seconds)`. pytest-timeout is not on the lock,
so this is a SIGALRM timer; it is skipped when the pytest-timeout plugin is present.
"""
import os
import random
import signal
import time
from pathlib import Path

import pytest

from defgg_ros.ros.domain import TEST_DOMAIN_RANGE, pick_private_domain

# Must happen before rclpy initialises its context. A domain of the tests' own range (disjoint from the demo's and
# the bringup's) that no other process on this host holds, held by this process until it exits.
os.environ["ROS_DOMAIN_ID"] = str(pick_private_domain(rng=random.Random(os.getpid()), domain_range=TEST_DOMAIN_RANGE))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

TEST_ROOT = Path(__file__).resolve().parent
REPO_ROOT = TEST_ROOT.parent
KINDS = ("unit", "ros", "sim", "e2e")
DEFAULT_TIMEOUT_S = float(os.environ.get("DEFGG_TEST_TIMEOUT_S", "300"))
E2E_TIMEOUT_S = max(DEFAULT_TIMEOUT_S, 900.0)
# The kind of every test module that sets no `pytestmark` of its own (a test's own kind marker wins over both).
# A module in neither place fails its tests with a message naming this table (test/foundation/test_test_kinds.py).
UNIT_MODULES = {
    "bringup/test_shared_parameters.py", "control/test_control_fingers_not_closed.py",
    "control/test_control_fr3_limits.py", "control/test_control_pick_place.py",
    "control/test_control_trajectories.py", "control/test_velocity_estimate.py", "data/test_augment.py",
    "data/test_datagen.py", "data/test_dataset.py", "data/test_dataset_card_notes.py", "data/test_groundtruth.py",
    "data/test_labels.py", "evaluation/test_diagnose.py", "evaluation/test_mini_eval.py",
    "evaluation/test_ship_and_card.py", "evaluation/test_sources.py", "evaluation/test_tables.py",
    "evaluation/test_tasks_and_store.py", "foundation/test_bench_help.py", "foundation/test_format_and_atomic.py",
    "foundation/test_package.py", "grasping/test_contact_angle.py", "grasping/test_finger_clearance.py",
    "grasping/test_grasping_geometry.py", "grasping/test_grasping_postprocess.py", "model/test_model_benches.py",
    "model/test_model_checkpoint.py", "model/test_model_inference.py", "model/test_model_network.py",
    "model/test_model_preprocess.py", "perception/test_depth_noise_low_objects.py", "perception/test_frame_worker.py",
    "perception/test_grip_estimate.py", "perception/test_perception_grasp_planning.py",
    "perception/test_perception_segmentation.py", "perception/test_perception_sync.py",
    "perception/test_tabletop_kernels.py", "perception/test_tabletop_ranking.py",
    "perception/test_tabletop_scenes.py", "perception/test_tabletop_shapes.py", "reliability/test_eval_kill.py",
    "reliability/test_motion_safety_property.py", "reliability/test_trust_boundaries.py",
    "sessions/test_replay_graph.py", "sessions/test_selector_frames.py", "sessions/test_sessions_bag.py",
    "sessions/test_sessions_compare_report.py", "test_lint.py", "test_stiffness.py", "train/test_label_grip_rule.py",
    "train/test_train_config.py", "train/test_train_ddp.py", "train/test_train_learning.py",
    "train/test_train_resume.py", "train/test_retrain_pair.py",
}
ROS_MODULES = {
    "bringup/test_bringup_supervision.py", "bringup/test_demo_helpers.py", "bringup/test_demo_place.py",
    "bringup/test_node_set.py", "foundation/test_interfaces_roundtrip.py", "foundation/test_ros_executor.py",
    "foundation/test_ros_service.py", "nodes/test_conversions.py", "nodes/test_executor_finish.py",
    "nodes/test_executor_franka_inputs.py", "nodes/test_executor_messages.py", "nodes/test_executor_node.py",
    "nodes/test_grasp_inference_cell.py", "nodes/test_grasp_inference_fuzz.py", "nodes/test_grasp_inference_node.py",
    "nodes/test_grasp_inference_on_arrival.py", "nodes/test_segmentation_node.py", "nodes/test_table_frame.py",
    "perception/test_plausibility_entries.py", "perception/test_self_filter.py", "reliability/test_pick_faults.py",
    "reliability/test_plan_grasp_faults.py", "reliability/test_segmentation_faults.py",
    "sessions/test_live_message.py", "sessions/test_replay_domain.py", "sessions/test_sessions_record.py",
    "sessions/test_sessions_selector.py", "sim_cell/test_driver_node.py", "sim_cell/test_franka_contract.py",
}
SIM_MODULES = {
    "control/test_control_gripper_rule.py", "control/test_control_kinematics.py",
    "control/test_control_pick_in_cell.py", "control/test_tcp_closing_axis.py", "evaluation/test_ceiling.py",
    "evaluation/test_eval_protocol.py", "evaluation/test_paired.py", "evaluation/test_planning_and_jobs.py",
    "perception/test_perception_cell_render.py", "reliability/test_eval_trial_error.py",
    "reliability/test_offline_faults.py", "sessions/test_sessions_scene_stiffness.py", "sim/test_camera.py",
    "sim/test_objects.py", "sim/test_sampler.py", "sim/test_trial.py", "sim/test_trial_energy.py",
    "sim_cell/test_cell.py", "sim_cell/test_grid_mesh.py", "sim_cell/test_gripper.py", "sim_cell/test_scene_spec.py",
    "sim_cell/test_trajectory.py",
}
# Whole cell / whole pipeline: several processes, minutes on a 2-core machine.
E2E_MODULES = {
    "test_demo.py",
    "nodes/test_executor_e2e.py",
    "sessions/test_sessions_replay.py",   # replays recorded sessions through the whole node graph
    "sessions/test_record_all.py",        # records a session with the committed recipe, then replays it
}
MODULE_KINDS = {module: kind for kind, modules in (("unit", UNIT_MODULES), ("ros", ROS_MODULES),
                                                   ("sim", SIM_MODULES), ("e2e", E2E_MODULES))
                for module in modules}
# Not e2e, but too slow for `make check` (a test of several seconds each here); `make test` runs them.
SLOW_MODULES = {
    "train/test_train_learning.py", "train/test_train_ddp.py", "train/test_train_resume.py",
    "model/test_model_benches.py", "evaluation/test_mini_eval.py", "reliability/test_eval_kill.py",
    "bringup/test_isolation.py", "bringup/test_bringup_supervision.py", "nodes/test_transport_default_publisher.py",
    "sessions/test_sessions_record.py", "reliability/test_pick_faults.py",
    "sim/test_trial.py", "sim/test_trial_protocols.py", "data/test_datagen.py", "reliability/test_eval_trial_error.py",
    "reliability/test_offline_faults.py", "reliability/test_motion_safety_property.py", "nodes/test_executor_node.py",
    "nodes/test_grasp_inference_cell.py", "control/test_control_pick_in_cell.py", "evaluation/test_ship_and_card.py",
    "evaluation/test_eval_protocol.py", "perception/test_tabletop_scenes.py", "sessions/test_replay_domain.py",
    "perception/test_depth_noise_low_objects.py", "perception/test_tabletop_shapes.py",
    "train/test_label_grip_rule.py", "foundation/test_bench_help.py", "bringup/test_demo_place.py",
    "test_examples.py",                  # each example in a process of its own
    # a module's single slow test: "path::test name"
    "reliability/test_plan_grasp_faults.py::test_a_node_with_bad_start_up_files_or_parameters_exits_2_with_one_clear_line",
    # FEM squeezes and the sampler's full first stage: 18-91 s each (make check at 4:46 on a slow machine, 2026-12-02)
    "sim_cell/test_cell.py::test_a_pressed_finger_settles_on_an_fem_ball_and_the_squeeze_steps_are_even",
    "sim_cell/test_cell.py::test_a_grasp_presses_an_fem_body_with_its_force_not_with_its_closing_speed",
    "sim/test_sampler.py::test_the_first_stage_still_gives_fem_v5s_candidates",
    "sim/test_trial_hand_press.py::test_the_pressing_hand_squeezes_harder_with_more_force_and_the_speed_drive_does_not",
    # two presses of the hand on a block, one per arm drive: ~15 s
    "sim_cell/test_cell.py::test_the_franka_jtc_drive_presses_a_contact_with_frankas_joint_springs_and_the_motor_ten_times_harder",
}


def pytest_configure(config):
    for kind, what in (("unit", "pure Python, no DDS, no PyBullet"),
                       ("ros", "real rclpy nodes over real DDS"),
                       ("sim", "PyBullet physics"),
                       ("e2e", "whole cell or whole offline pipeline (minutes)"),
                       ("slow", "not e2e but too slow for make check"),
                       ("timeout(seconds)", "per-phase time limit for this test")):
        config.addinivalue_line("markers", f"{kind}: {what}")


def _relative(path) -> str:
    try:
        return Path(path).resolve().relative_to(TEST_ROOT).as_posix()
    except ValueError:
        return Path(path).name


def pytest_collection_modifyitems(config, items):
    for item in items:
        relative = _relative(item.path)
        if not any(item.get_closest_marker(kind) for kind in KINDS) and relative in MODULE_KINDS:
            item.add_marker(getattr(pytest.mark, MODULE_KINDS[relative]))
        if relative in SLOW_MODULES or f"{relative}::{item.originalname}" in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
    items[:] = heaviest_files_first(items)


def heaviest_files_first(items) -> list:
    """Files with an e2e test first, then those with a slow one, then the rest; collection order within each.

    The workers (make test: --dist loadfile --no-loadscope-reorder) take files in this order, one at a time, so the
    minutes-long cells start early and the seconds-long files fill in at the end. xdist's own reorder (most tests
    first) put the one-test cells last: the bin-fill test (500 s on CI) could run alone at the end of the suite."""
    def rank(item) -> int:
        return 0 if item.get_closest_marker("e2e") else 1 if item.get_closest_marker("slow") else 2

    file_rank = {}
    for item in items:
        file_rank[item.path] = min(file_rank.get(item.path, 2), rank(item))
    return sorted(items, key=lambda item: file_rank[item.path])   # stable: a file's tests keep their order


@pytest.fixture(autouse=True)
def _explicit_kind(request):
    """Fails a test whose module has no kind: no `pytestmark`, not in the kind table, no marker of its own."""
    if not any(request.node.get_closest_marker(kind) for kind in KINDS):
        pytest.fail(f"{_relative(request.node.path)} has no test kind: set `pytestmark = pytest.mark.<kind>` "
                    f"(one of {', '.join(KINDS)}) or list it in test/conftest.py's UNIT_MODULES ... E2E_MODULES")


def _timeout_of(item) -> float:
    marker = item.get_closest_marker("timeout")
    if marker is not None and marker.args:
        return float(marker.args[0])
    return E2E_TIMEOUT_S if item.get_closest_marker("e2e") else DEFAULT_TIMEOUT_S


class PhaseTimeout(Exception):
    """Raised in the test's main thread when a phase outlives its time limit."""


def _run_with_alarm(item, phase: str):
    """Arm SIGALRM for one phase; the handler fails the test with the phase and the limit."""
    if item.config.pluginmanager.hasplugin("timeout") or not hasattr(signal, "setitimer"):
        yield
        return
    limit_s = _timeout_of(item)

    def on_alarm(signum, frame):
        raise PhaseTimeout(f"{item.nodeid}: {phase} exceeded {limit_s:.0f} s (DEFGG_TEST_TIMEOUT_S / "
                               "@pytest.mark.timeout)")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, limit_s)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    yield from _run_with_alarm(item, "set-up")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    yield from _run_with_alarm(item, "call")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item):
    yield from _run_with_alarm(item, "tear-down")


@pytest.fixture
def rclpy_context():
    """An initialised rclpy context, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        context.try_shutdown()


@pytest.fixture
def executor(rclpy_context):
    """A ThreadedExecutor (defgg_ros.ros.executor) on the test's context; nodes added to it are destroyed after."""
    from defgg_ros.ros.executor import ThreadedExecutor

    ex = ThreadedExecutor(num_threads=4, context=rclpy_context)
    yield ex
    from defgg_ros.ros.action import destroy_actions

    for node in list(ex.get_nodes()):
        ex.remove_node(node)
        destroy_actions(node)  # plain client nodes too: rclpy's destroy_node leaves actions alive
        node.destroy_node()
    ex.shutdown(timeout_sec=2.0)


@pytest.fixture(scope="session")
def random_checkpoint(tmp_path_factory):
    """Factory: random_checkpoint(seed=0, uses_stiffness=True) -> path of a randomly initialised
    Def-GG-CNN checkpoint in the real format, written once per test session and arguments."""
    from defgg_ros.model.checkpoint import make_random_checkpoint

    made = {}

    def make(seed: int = 0, uses_stiffness: bool = True) -> Path:
        key = (seed, uses_stiffness)
        if key not in made:
            folder = tmp_path_factory.mktemp(f"checkpoint_seed{seed}")
            made[key] = make_random_checkpoint(folder / "random.pt", seed=seed, uses_stiffness=uses_stiffness)
        return made[key]

    return make


@pytest.fixture
def executor_cell(rclpy_context):
    """An ExecutorNode with quick motion parameters, a PickAndPlace client and a factory for the in-test
    driver (test/support/executor_cell.py): (executor, executor node, action client, start_driver)."""
    from support.executor_cell import run_cell

    yield from run_cell(rclpy_context)


@pytest.fixture
def inference_service(executor):
    """Factory: start a GraspInferenceNode and the SegmentationNode it plans on (the cell's only perceiver) on
    `executor`, each with those of these parameters its schema declares, plus a client node whose PlanGrasp
    client is ready. Returns (inference node, client node, client); the inference node's `segmentation_node`
    attribute is the segmentation node."""
    from defgg_interfaces.srv import PlanGrasp
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
    from defgg_ros.nodes.segmentation_node import SegmentationNode
    from defgg_ros.ros import topics
    from defgg_ros.ros.parameters import defaults

    def start(client_name: str, **parameters):
        declared = {name: set(defaults(name)) for name in ("grasp_inference_node", "segmentation_node")}
        unknown = set(parameters) - declared["grasp_inference_node"] - declared["segmentation_node"]
        assert not unknown, f"no node declares {sorted(unknown)}"

        def overrides(node_name):
            return [Parameter(n, value=v) for n, v in parameters.items() if n in declared[node_name]]

        segmentation = SegmentationNode(context=executor.context, parameter_overrides=overrides("segmentation_node"))
        executor.add_node(segmentation)
        node = GraspInferenceNode(context=executor.context, parameter_overrides=overrides("grasp_inference_node"))
        node.segmentation_node = segmentation
        executor.add_node(node)
        client_node = Node(client_name, context=executor.context)
        executor.add_node(client_node)
        service = parameters.get("plan_grasp_service", topics.PLAN_GRASP_SERVICE)
        client = client_node.create_client(PlanGrasp, service)
        assert client.wait_for_service(timeout_sec=10.0), f"{service} did not appear"
        return node, client_node, client

    return start


def spin_until(executor, done, timeout_s: float, what: str):
    """Spin `executor` until `done` (a Future or a callable -> bool) is true.

    Fails the test with `what` after `timeout_s` seconds; never sleeps.
    Returns the future's result when `done` is a Future.
    """
    is_future = hasattr(done, "done") and hasattr(done, "result")
    if not _spin_while_not(executor, done.done if is_future else done, timeout_s):
        pytest.fail(f"timed out after {timeout_s:.1f} s waiting for {what}")
    return done.result() if is_future else True


def _spin_while_not(executor, check, timeout_s: float) -> bool:
    """Spin `executor` in short slices until check() holds (True) or `timeout_s` passes (False)."""
    deadline = time.monotonic() + timeout_s
    while not check():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        executor.spin_once(timeout_sec=min(0.05, remaining))
    return True


@pytest.fixture
def spin():
    """The spin_until helper as a fixture: spin(executor, done, timeout_s, what)."""
    return spin_until


def call_service(executor, client, request, timeout_s: float, what: str):
    """Call `client` with an idempotent `request`, spinning `executor` here and re-sending it while
    unanswered (defgg_ros.ros.service: Fast DDS can drop a response to a just-started client).
    Fails the test with `what` after `timeout_s`; returns the response."""
    from defgg_ros.ros.service import ServiceTimeout, call_idempotent

    def wait_until(predicate, wait_s):
        return _spin_while_not(executor, predicate, wait_s)

    try:
        return call_idempotent(client, request, timeout_s, what, wait_until=wait_until)
    except ServiceTimeout as error:
        pytest.fail(str(error))


@pytest.fixture
def call():
    """The call_service helper as a fixture: call(executor, client, request, timeout_s, what)."""
    return call_service

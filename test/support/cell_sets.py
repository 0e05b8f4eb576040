"""Node sets for tests that run the simulated driver and the executor as processes (as the bringup does)."""
import yaml

from defgg_ros.bringup.node_set import config_dir, load_node_set

# The executor's watchdog in cell tests that do not test it (test_pick_faults.py does): on a starved 2-core machine
# (the full suite at a load of 8, or two workers beside each other) the simulated driver has gone 2 s without a
# joint state mid-pick (exit-stop, squeeze-cell, and on 2026-12-02 bin-fill tests), ending the pick "driver silent".
STARVED_WATCHDOG_S = 10.0


def driver_and_executor_set(tmp_path, scene_file, executor_overrides=None, driver_overrides=None):
    """fake_panda_driver (sim time, the scene_file) and executor_node with the cell's parameter files plus these
    overrides; the goals take given grasps (no perception)."""
    config = config_dir()
    driver = {"scene_file": str(scene_file), "depth_rate_hz": 0.5, **(driver_overrides or {})}
    text = {"name": "driver_and_executor", "use_sim_time": True, "nodes": [
        {"name": "fake_panda_driver", "module": "defgg_ros.nodes.fake_panda_driver_node",
         "params": [str(config / "fake_panda_driver.yaml")], "ready": {"action": "/franka_gripper/grasp"},
         "overrides": driver},
        {"name": "executor_node", "module": "defgg_ros.nodes.executor_node",
         "params": [str(config / "executor_node.yaml")], "ready": {"action": "/defgg/pick_and_place"},
         "overrides": dict(executor_overrides or {})}]}
    path = tmp_path / "driver_and_executor.yaml"
    path.write_text(yaml.safe_dump(text))
    return load_node_set(str(path))

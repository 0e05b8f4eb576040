"""PlanGrasp with scene-level faults, and node start-up with bad files.

- an empty scene (nothing above the table) is refused with a reason, for
  both request forms (objects -> segmented here; a stiffness image);
- an object cut by the image border still gets a grasp ON the object (the
  network's 300 px window is clamped inside the image, not centred off it);
- a missing, truncated or tampered model file, a missing background or scene
  file or invalid parameters stop the node's process at start-up with one
  line naming the problem and exit code 2 (real processes, no traceback).
"""
import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from defgg_interfaces.msg import ObjectStiffness
from defgg_interfaces.srv import PlanGrasp
from rclpy.parameter import Parameter

from defgg_ros.model.checkpoint import CheckpointError
from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info

SERVICE = "/reliability/plan_grasp"
K = default_camera_k()
INFO = make_camera_info(K, 640, 480)
EMPTY_M, _ = render(SyntheticScene(objects=()))
# A 6 x 5 cm box whose right part lies outside the image (the image spans +-0.33 m at the table).
BORDER_M, BORDER_TRUTH = render(SyntheticScene(objects=(SceneObject((0.30, 0.05), 0.05, (0.06, 0.05)),), walls=True))


@pytest.fixture
def checkpoint(random_checkpoint):
    return random_checkpoint(seed=11)


@pytest.fixture
def client(executor, call, checkpoint, inference_service):
    _, _, cli = inference_service("plan_fault_client", model_path=str(checkpoint), plan_grasp_service=SERVICE)
    return lambda request: call(executor, cli, request, 20.0, "plan_grasp response")


def _objects_request(depth_m):
    return PlanGrasp.Request(depth=depth_metres_to_msg(depth_m, "16UC1"), camera_info=INFO,
                             objects=[ObjectStiffness(name="part", youngs_modulus_pa=2e5)])


def _depth_request(depth_m):
    return PlanGrasp.Request(depth=depth_metres_to_msg(depth_m, "16UC1"), camera_info=INFO, top_k=3)


def test_empty_scene_is_refused_and_an_object_at_the_border_is_grasped_on_the_object(client):
    for request, reason in ((_objects_request(EMPTY_M), "no object found above the table"),
                            (_depth_request(EMPTY_M), "no object found above the table")):
        response = client(request)
        assert not response.success and reason in response.message, response.message
        assert not response.grasps
    assert BORDER_TRUTH[:, -1].any(), "the test object must touch the image border"
    for request in (_objects_request(BORDER_M), _depth_request(BORDER_M)):
        response = client(request)
        assert response.success, response.message
        for grasp in response.grasps:
            u, v = int(round(grasp.center_u_px)), int(round(grasp.center_v_px))
            assert 0 <= u < 640 and 0 <= v < 480
            assert BORDER_TRUTH[v, u] > 0, f"grasp at ({u}, {v}) is not on the object"
            assert np.isfinite(grasp.pose_base.pose.position.z) and grasp.width_m > 0


def test_bad_model_files_are_refused_at_construction(executor, checkpoint, tmp_path):
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(checkpoint.read_bytes()[:5000])
    tampered = tmp_path / "tampered.pt"
    payload = torch.load(checkpoint, weights_only=True)
    name = next(iter(payload["state_dict"]))
    payload["state_dict"][name] = payload["state_dict"][name] + 0.01
    torch.save(payload, tampered)
    cases = {tmp_path / "missing.pt": "not found", truncated: "cannot read", tampered: "sha256",
             tmp_path: "not found"}  # a folder is not a checkpoint
    for path, reason in cases.items():
        with pytest.raises(CheckpointError, match=reason):
            GraspInferenceNode(context=executor.context,
                               parameter_overrides=[Parameter("model_path", value=str(path))])


def _run_node(module, *params, timeout_s=60):
    cmd = [sys.executable, "-m", module, "--ros-args"]
    for param in params:
        cmd += ["-p", param]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, env=dict(os.environ))


@pytest.mark.parametrize("module,param,words", [
    ("defgg_ros.nodes.grasp_inference_node", "model_path:=/nonexistent/defgg.pt", "checkpoint file not found"),
    ("defgg_ros.nodes.segmentation_node", "background_depth_file:=/nonexistent/bg.npy", "No such file"),
    ("defgg_ros.nodes.segmentation_node", "default_youngs_modulus_pa:=-1.0", "modulus_pa = -1.0 must be > 0"),
    ("defgg_ros.nodes.executor_node", "limits_scale:=0.0", "limits_scale"),
    ("defgg_ros.nodes.fake_panda_driver_node", "scene_file:=/nonexistent/scene.yaml", "does not exist"),
])
def test_a_node_with_bad_start_up_files_or_parameters_exits_2_with_one_clear_line(module, param, words):
    done = _run_node(module, param)
    output = done.stdout + done.stderr
    assert done.returncode == 2, output[-2000:]
    assert words in output and "Traceback" not in output, output[-2000:]
    # one line, named after the node (PyBullet prints its build banner on import: not the node's)
    lines = [line for line in output.splitlines() if line.strip() and not line.startswith("pybullet build time")]
    node = module.rsplit(".", 1)[1].removesuffix("_node")     # fake_panda_driver_node runs fake_panda_driver
    assert len(lines) == 1 and lines[0].startswith(node) and words in lines[0], output[-2000:]

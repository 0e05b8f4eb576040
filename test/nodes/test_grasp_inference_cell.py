"""The perception chain in the simulated cell over DDS: fake driver -> segmentation -> grasp inference."""
from pathlib import Path

import numpy as np
import pytest
from defgg_interfaces.msg import Grasp
from defgg_interfaces.srv import PlanGrasp
from geometry_msgs.msg import PoseArray
from rclpy.node import Node
from rclpy.parameter import Parameter

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M, OBJECT_DENSITY_KG_M3
from defgg_ros.grip_force import LabelGripRule
from defgg_ros.model.checkpoint import make_random_checkpoint
from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
from defgg_ros.nodes.segmentation_node import SegmentationNode
from defgg_ros.ros import qos, topics

SCENE = Path(__file__).resolve().parents[2] / "sim_bringup" / "scenes" / "rigid_box.yaml"
BOX_HALF_SIZE_M = 0.025  # rigid_box.yaml: a 5 cm cube
TIMEOUT_S = 60.0


DEFGRASPSIM_RULE = {"protocol": "defgraspsim", "friction": 0.7}


@pytest.fixture(params=[None, DEFGRASPSIM_RULE], ids=["legacy_weights", "defgraspsim_weights"])
def chain(executor, tmp_path, request):
    """The chain; its network records no label grip rule (legacy) or the defgraspsim one."""
    from defgg_ros.nodes.fake_panda_driver_node import FakePandaDriver

    driver = FakePandaDriver(context=executor.context, parameter_overrides=[
        Parameter("scene_file", value=str(SCENE)), Parameter("max_real_time_factor", value=0.0),
        Parameter("depth_rate_hz", value=5.0), Parameter("depth_noise_coeff_per_m", value=0.004)])
    segmentation = SegmentationNode(context=executor.context, parameter_overrides=[
        Parameter("default_youngs_modulus_pa", value=2e9)])
    inference = GraspInferenceNode(context=executor.context, parameter_overrides=[
        Parameter("model_path", value=str(make_random_checkpoint(
            tmp_path / "random.pt", meta={"label_grip_rule": request.param} if request.param else None)))])
    probe = Node("cell_probe", context=executor.context)
    for node in (driver, segmentation, inference, probe):
        executor.add_node(node)
    probe.label_grip_rule = LabelGripRule.from_meta({"label_grip_rule": request.param})
    yield probe
    driver.shutdown()


def test_best_grasp_lands_on_the_box_and_plan_grasp_serves_the_latest_frame(chain, executor, spin, call):
    grasps, poses = [], []
    chain.create_subscription(Grasp, topics.BEST_GRASP, grasps.append, qos.STATE)
    chain.create_subscription(PoseArray, "/fake_panda/object_poses", poses.append, qos.STATE)
    spin(executor, lambda: grasps and poses, TIMEOUT_S, "a best grasp from the live camera stream")
    grasp, box = grasps[-1], poses[-1].poses[0].position
    p = grasp.pose_base.pose.position
    # On the cube (table top at z = 0 in panda_link0, cube 5 cm tall): within its footprint, above the
    # table. An untrained network may pick a pixel of the side wall the camera sees in perspective, so
    # the height is anywhere on the cube, not necessarily its top face.
    assert np.hypot(p.x - box.x, p.y - box.y) < BOX_HALF_SIZE_M * np.sqrt(2) + 0.003
    assert 0.004 < p.z < 2 * BOX_HALF_SIZE_M + 0.005
    assert grasp.youngs_modulus_pa == pytest.approx(2e9) and grasp.object_id == 1
    assert 0.0 <= grasp.width_m <= GRIPPER_MAX_WIDTH_M
    # The cube's mass from the height map (125 g at the trials' density) and, for weights whose labels
    # squeezed with FOS*m*g/mu, that force for the executor (legacy weights: 0, the executor's own rule).
    assert grasp.estimated_mass_kg == pytest.approx((2 * BOX_HALF_SIZE_M) ** 3 * OBJECT_DENSITY_KG_M3, rel=0.2)
    rule = chain.label_grip_rule
    expected = rule.finger_force_n(2e9, grasp.estimated_mass_kg) if rule.needs_mass else 0.0
    assert grasp.finger_force_n == pytest.approx(expected) and (grasp.finger_force_n > 1.0) == rule.needs_mass
    client = chain.create_client(PlanGrasp, topics.PLAN_GRASP_SERVICE)
    assert client.wait_for_service(timeout_sec=10.0)
    response = call(executor, client, PlanGrasp.Request(top_k=2), TIMEOUT_S, "plan_grasp response")
    assert response.success, response.message
    assert response.grasps[0].header.frame_id == grasp.header.frame_id

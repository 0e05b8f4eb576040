"""grasp_inference_node over real DDS with a random-init checkpoint (structure, not quality)."""
import math

import numpy as np
import pytest
from defgg_interfaces.msg import Grasp, ObjectStiffness
from defgg_interfaces.srv import PlanGrasp
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.grasping.finger_clearance import fingers_clear
from defgg_ros.nodes import qos
from defgg_ros.nodes.conversions import (
    depth_metres_to_msg,
    image_to_numpy,
    make_camera_info,
    numpy_to_image,
    stamp_to_ns,
)
from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
from defgg_ros.perception.geometry import quaternion_xyzw_to_matrix
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render
from defgg_ros.ros import topics

K = default_camera_k()
SCENE = SyntheticScene(objects=(
    SceneObject(center_xy_m=(-0.04, 0.02), height_m=0.05, size_xy_m=(0.05, 0.04), yaw_rad=0.3),
    SceneObject(center_xy_m=(0.06, -0.03), height_m=0.04, radius_m=0.025),
))
DEPTH_M, TRUTH = render(SCENE)
STIFFNESS_PA = np.where(TRUTH == 1, 2e4, np.where(TRUTH == 2, 2e9, 0.0)).astype(np.float32)
BASE_T_CAMERA = [0.5, 0.0, 0.40, 1.0, 0.0, 0.0, 0.0]


@pytest.fixture
def checkpoint(random_checkpoint):
    return random_checkpoint(seed=3)


@pytest.fixture
def cell(checkpoint, inference_service):
    # These tests pin the camera_crop planner's contract (quality order, 300 px minimum); the tabletop
    # planner's is tested in test/perception/test_tabletop_node.py.
    return inference_service("grasp_test_client", model_path=str(checkpoint), base_T_camera=BASE_T_CAMERA,
                             planner="camera_crop")


def plan(executor, call, client, request, timeout_s=20.0):
    return call(executor, client, request, timeout_s, "plan_grasp response")


def header(stamp_sec=1):
    h = Header(frame_id="camera_depth_optical_frame")
    h.stamp.sec = stamp_sec
    return h


def image_request(depth_encoding="16UC1", top_k=1, **overrides) -> PlanGrasp.Request:
    request = PlanGrasp.Request(
        depth=depth_metres_to_msg(DEPTH_M, depth_encoding, header()),
        camera_info=make_camera_info(K, 640, 480, header()),
        stiffness=numpy_to_image(STIFFNESS_PA, "32FC1", header()), top_k=top_k)
    for name, value in overrides.items():
        setattr(request, name, value)
    return request


def objects_request(objects) -> PlanGrasp.Request:
    return PlanGrasp.Request(depth=depth_metres_to_msg(DEPTH_M, "16UC1", header()),
                             camera_info=make_camera_info(K, 640, 480, header()), objects=objects)


def entry(value, roi=(0, 0, 0, 0), region_only=False):
    e = ObjectStiffness(name="thing", youngs_modulus_pa=value, region_only=region_only)
    e.roi.x_offset, e.roi.y_offset, e.roi.width, e.roi.height = roi
    return e


def assert_valid_grasp(grasp: Grasp):
    u, v = int(round(grasp.center_u_px)), int(round(grasp.center_v_px))
    assert TRUTH[v, u] > 0, f"grasp at ({u}, {v}) is not on an object"
    assert grasp.object_id >= 1
    assert 0.0 <= grasp.width_m <= GRIPPER_MAX_WIDTH_M
    assert 0.0 <= grasp.quality <= 1.0
    assert -math.pi / 2 <= grasp.angle_rad <= math.pi / 2
    p, o = grasp.pose_base.pose.position, grasp.pose_base.pose.orientation
    assert grasp.pose_base.header.frame_id == topics.BASE_FRAME
    # The camera is 0.40 m above the table (z = 0): the grasp point is on an object top.
    assert p.z == pytest.approx(0.40 - DEPTH_M[v, u], abs=2e-3) and 0.035 < p.z < 0.055
    rotation = quaternion_xyzw_to_matrix([o.x, o.y, o.z, o.w])
    np.testing.assert_allclose(rotation[:, 2], [0, 0, -1], atol=1e-6)


def clearance(grasp: Grasp, opening_m: float) -> bool:
    depth = float(DEPTH_M[int(round(grasp.center_v_px)), int(round(grasp.center_u_px))])
    return fingers_clear(DEPTH_M, TRUTH, grasp.center_u_px, grasp.center_v_px, grasp.angle_rad, depth, opening_m,
                         K[0, 0])


def assert_ranked_clear_first(grasps, opening_m: float):
    """Grasps whose fingers land beside the objects first, each group best quality first."""
    clear = [clearance(g, opening_m) for g in grasps]
    assert clear == sorted(clear, reverse=True), clear
    for group in (True, False):
        qualities = [g.quality for g, c in zip(grasps, clear) if c is group]
        assert qualities == sorted(qualities, reverse=True)


@pytest.mark.parametrize("depth_encoding", ["16UC1", "32FC1"])
def test_plan_grasp_with_stiffness_image(cell, executor, spin, depth_encoding, call):
    _, _, client = cell
    response = plan(executor, call, client, image_request(depth_encoding, top_k=3))
    assert response.success, response.message
    assert 1 <= len(response.grasps) <= 3 and response.inference_time_s > 0
    assert_ranked_clear_first(response.grasps, GRIPPER_MAX_WIDTH_M)
    for grasp in response.grasps:
        assert_valid_grasp(grasp)
        u, v = int(round(grasp.center_u_px)), int(round(grasp.center_v_px))
        assert grasp.youngs_modulus_pa == pytest.approx(STIFFNESS_PA[v, u])
        assert grasp.header.stamp.sec == 1


def test_plan_grasp_with_objects_segments_the_request(cell, executor, spin, call):
    _, _, client = cell
    response = plan(executor, call, client, objects_request([entry(2e5)]))
    assert response.success, response.message
    assert_valid_grasp(response.grasps[0])
    assert response.grasps[0].youngs_modulus_pa == pytest.approx(2e5)


def test_synchronised_streams_publish_and_serve_empty_requests(cell, executor, spin, call):
    node, client_node, client = cell
    pubs = {name: client_node.create_publisher(kind, topic, qos.SENSOR_DATA) for name, kind, topic in (
        ("depth", Image, topics.DEPTH_IMAGE), ("stiffness", Image, topics.STIFFNESS_IMAGE),
        ("info", CameraInfo, topics.DEPTH_CAMERA_INFO))}
    got = {"grasp": [], "quality": [], "markers": []}
    client_node.create_subscription(Grasp, topics.BEST_GRASP, got["grasp"].append, qos.STATE)
    client_node.create_subscription(Image, topics.QUALITY_IMAGE, got["quality"].append, qos.SENSOR_DATA)
    client_node.create_subscription(MarkerArray, topics.GRASP_MARKERS, got["markers"].append, qos.STATE)
    h = header(stamp_sec=42)
    messages = {"depth": depth_metres_to_msg(DEPTH_M, "16UC1", h), "info": make_camera_info(K, 640, 480, h),
                "stiffness": numpy_to_image(STIFFNESS_PA, "32FC1", h)}
    ticks = [0]

    def outputs_arrived():
        ticks[0] += 1
        if ticks[0] % 10 == 1:  # best effort + discovery: resend (same stamp) until synchronised
            for name in ("stiffness", "info", "depth"):
                pubs[name].publish(messages[name])
        return all(got.values())

    spin(executor, outputs_arrived, 30.0, "best grasp, quality image and markers")
    assert node.synced_frames >= 1
    assert stamp_to_ns(got["grasp"][0].header.stamp) == 42 * 10**9
    assert_valid_grasp(got["grasp"][0])
    quality = image_to_numpy(got["quality"][0])
    assert quality.shape == (480, 640) and 0 <= quality.min() and quality.max() <= 1
    fingers = got["markers"][0].markers
    assert len(fingers) == 2
    gap = math.dist(*[(m.pose.position.x, m.pose.position.y, m.pose.position.z) for m in fingers])
    assert gap == pytest.approx(got["grasp"][0].width_m + fingers[0].scale.x, abs=1e-6)
    response = plan(executor, call, client, PlanGrasp.Request())
    assert response.success, response.message
    assert response.grasps[0].header.stamp.sec == 42


def _wrong(request_fn, **changes):
    def build():
        request = request_fn()
        for path, value in changes.items():
            target = request
            *parents, leaf = path.split("__")
            for parent in parents:
                target = getattr(target, parent)
            setattr(target, leaf, value)
        return request
    return build


NAN_DEPTH = numpy_to_image(np.full((480, 640), np.nan, np.float32), "32FC1", header())
BAD_REQUESTS = {
    "empty request, nothing synchronised yet": (PlanGrasp.Request, "no synchronised"),
    "rgb8 depth": (_wrong(image_request, depth=numpy_to_image(np.zeros((480, 640, 3), np.uint8), "rgb8")),
                   "16UC1"),
    "unknown encoding": (_wrong(image_request, depth__encoding="bayer_grbg8"), "16UC1"),
    "depth with zero width": (_wrong(image_request, depth=Image(height=480, encoding="16UC1")), "0x480"),
    "stiffness with no size": (_wrong(image_request, stiffness=Image(encoding="32FC1", data=bytes(8))), "0x0"),
    "truncated data": (_wrong(image_request, depth__data=bytes(100)), "B, expected"),
    "stiffness size mismatch": (_wrong(image_request, stiffness=numpy_to_image(
        STIFFNESS_PA[:240, :320], "32FC1")), "stiffness is 320x240"),
    "camera_info size mismatch": (_wrong(image_request, camera_info=make_camera_info(K, 320, 240)), "camera_info"),
    "no camera_info": (_wrong(image_request, camera_info=CameraInfo()), "no camera_info"),
    "zero focal length": (_wrong(image_request, camera_info__k=[0.0] * 9), "focal"),
    "all-NaN depth": (_wrong(image_request, depth=NAN_DEPTH), "no valid pixel"),
    "metres in 16UC1": (_wrong(image_request, depth=numpy_to_image(np.ones((480, 640), np.uint16), "16UC1")),
                        "look like metres"),
    "negative stiffness": (_wrong(image_request, stiffness=numpy_to_image(-STIFFNESS_PA, "32FC1")), "negative"),
    "NaN stiffness": (_wrong(image_request, stiffness=numpy_to_image(STIFFNESS_PA * np.nan, "32FC1")), "NaN"),
    "no object in stiffness": (_wrong(image_request, stiffness=numpy_to_image(STIFFNESS_PA * 0, "32FC1")),
                               "no object"),
    "stiffness and objects": (_wrong(image_request, objects=[entry(2e5)]), "either"),
    "E = 0": (lambda: objects_request([entry(0.0)]), "> 0"),
    "E < 0": (lambda: objects_request([entry(-2e5)]), "> 0"),
    "E NaN": (lambda: objects_request([entry(float("nan"))]), "> 0"),
    "E absurd": (lambda: objects_request([entry(1e30)]), "plausible"),
    "roi off image": (lambda: objects_request([entry(2e5, (5000, 0, 10, 10))]), "outside"),
    "top_k too big": (lambda: image_request(top_k=1000), "top_k"),
    "small image": (lambda: PlanGrasp.Request(depth=depth_metres_to_msg(DEPTH_M[140:340, 220:420], "16UC1"),
                                              camera_info=make_camera_info(K, 200, 200),
                                              stiffness=numpy_to_image(STIFFNESS_PA[140:340, 220:420], "32FC1")),
                    "smaller than"),
}


def test_bad_requests_fail_cleanly_and_node_keeps_serving(cell, executor, spin, call):
    _, _, client = cell
    for name, (build, reason) in BAD_REQUESTS.items():
        response = plan(executor, call, client, build())
        assert not response.success, f"{name}: unexpectedly succeeded"
        assert reason in response.message, f"{name}: message {response.message!r} lacks {reason!r}"
        assert not response.grasps
    response = plan(executor, call, client, image_request())
    assert response.success, response.message


def test_depth_only_model_via_use_stiffness_false(executor, spin, random_checkpoint, inference_service, call):
    checkpoint = random_checkpoint(uses_stiffness=False)
    node, _, client = inference_service("depth_only_client", model_path=str(checkpoint), use_stiffness=False,
                                        plan_grasp_service="/test/depth_only_plan")
    assert not node.predictor.uses_stiffness
    response = plan(executor, call, client, image_request())
    assert response.success, response.message
    assert_valid_grasp(response.grasps[0])


def test_finger_clearance_ranking_can_be_switched_off(executor, spin, checkpoint, inference_service, call):
    _, _, client = inference_service("clearance_off_client", model_path=str(checkpoint), planner="camera_crop",
                                     base_T_camera=BASE_T_CAMERA, finger_clearance_opening_m=0.0,
                                     plan_grasp_service="/test/clearance_off_plan")
    response = plan(executor, call, client, image_request(top_k=5))
    assert response.success, response.message
    qualities = [g.quality for g in response.grasps]
    assert qualities == sorted(qualities, reverse=True)   # the network's own ranking


def test_square_contacts_turn_the_grasps_to_the_box_faces(executor, spin, checkpoint, inference_service, call):
    import cv2
    _, _, client = inference_service("contact_client", model_path=str(checkpoint), base_T_camera=BASE_T_CAMERA,
                                     planner="camera_crop",
                                     contact_angle=True, plan_grasp_service="/test/contact_plan")
    box_only = numpy_to_image(np.where(TRUTH == 1, 2e4, 0.0).astype(np.float32), "32FC1", header())
    response = plan(executor, call, client, image_request(top_k=3, stiffness=box_only))
    assert response.success, response.message
    assert len(response.grasps) == 3
    # the 50 x 40 mm box's faces in the image, from its pixels
    _, _, face_deg = cv2.minAreaRect(np.argwhere(TRUTH == 1)[:, ::-1].astype(np.float32))
    for grasp in response.grasps:
        assert_valid_grasp(grasp)
        off_face_deg = min(abs(math.degrees((grasp.angle_rad - math.radians(face_deg + f) + math.pi / 2) % math.pi
                                            - math.pi / 2)) for f in (0.0, 90.0))
        assert off_face_deg <= 5.0 + 1e-6, (grasp.angle_rad, face_deg)


def test_bad_finger_clearance_opening_is_refused(executor, checkpoint):
    for bad in (-0.01, 0.2):
        with pytest.raises(ValueError, match="finger_clearance_opening_m"):
            GraspInferenceNode(context=executor.context, parameter_overrides=[
                Parameter("model_path", value=str(checkpoint)), Parameter("finger_clearance_opening_m", value=bad)])


def test_clearance_opening_is_the_executors_pre_grasp_opening():
    from defgg_ros.control.gripper_rule import pre_grasp_opening_m
    from defgg_ros.nodes.grasp_inference_node import PARAMETERS

    assert PARAMETERS["finger_clearance_opening_m"].default == pre_grasp_opening_m()


def test_model_that_does_not_match_use_stiffness_is_refused(executor, checkpoint):
    with pytest.raises(ValueError, match="use_stiffness"):
        GraspInferenceNode(context=executor.context, parameter_overrides=[
            Parameter("model_path", value=str(checkpoint)), Parameter("use_stiffness", value=False)])


def test_shipped_yaml_config_loads(executor, checkpoint):
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "sim_bringup" / "config" / "grasp_inference_node.yaml"
    node = GraspInferenceNode(context=executor.context, cli_args=["--ros-args", "--params-file", str(path)],
                              parameter_overrides=[Parameter("model_path", value=str(checkpoint))])
    executor.add_node(node)
    assert list(node.get_parameter("base_T_camera").value) == BASE_T_CAMERA
    assert node.get_parameter("default_youngs_modulus_pa").value == 2e6


def test_default_model_paths_are_the_shipped_checkpoints():
    from defgg_ros.model.inference import GraspPredictor
    from defgg_ros.nodes.grasp_inference_node import default_model_path

    for use_stiffness, name in ((True, "defgg_cnn.pt"), (False, "ggcnn_depth_only.pt")):
        path = default_model_path(use_stiffness)
        assert path.name == name and path.is_file()
        assert GraspPredictor.from_checkpoint(path).uses_stiffness == use_stiffness

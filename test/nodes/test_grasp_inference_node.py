"""grasp_inference_node over real DDS with the shipped model: it plans on the segmentation node's perception
(PerceivedObjects on the stream, the Perceive service for a request's own depth) and never perceives itself."""
import math

import numpy as np
import pytest
from defgg_interfaces.msg import Grasp, ObjectStiffness, PerceivedObjects
from defgg_interfaces.srv import Perceive, PlanGrasp
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from defgg_ros.constants import GRIPPER_MAX_WIDTH_M
from defgg_ros.nodes.grasp_inference_node import GraspInferenceNode
from defgg_ros.perception.geometry import quaternion_xyzw_to_matrix
from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render
from defgg_ros.ros import qos, topics
from defgg_ros.ros.conversions import (
    depth_metres_to_msg,
    image_to_numpy,
    make_camera_info,
    numpy_to_image,
    stamp_to_ns,
)
from defgg_ros.ros.parameters import defaults

K = default_camera_k()
SCENE = SyntheticScene(objects=(
    SceneObject(center_xy_m=(-0.04, 0.02), height_m=0.05, size_xy_m=(0.05, 0.04), yaw_rad=0.3),
    SceneObject(center_xy_m=(0.06, -0.03), height_m=0.04, radius_m=0.025),
))
DEPTH_M, TRUTH = render(SCENE)
BASE_T_CAMERA = [0.5, 0.0, 0.40, 1.0, 0.0, 0.0, 0.0]
BASE_FRAME = defaults("segmentation_node")["base_frame"]


@pytest.fixture
def checkpoint(random_checkpoint):
    return random_checkpoint(seed=3)


@pytest.fixture
def cell(inference_service):
    return inference_service("grasp_test_client", base_T_camera=BASE_T_CAMERA)


def plan(executor, call, client, request, timeout_s=60.0):
    return call(executor, client, request, timeout_s, "plan_grasp response")


def header(stamp_sec=1, stamp_nanosec=0):
    h = Header(frame_id="camera_depth_optical_frame")
    h.stamp.sec, h.stamp.nanosec = stamp_sec, stamp_nanosec
    return h


def image_request(depth_encoding="16UC1", top_k=1, **overrides) -> PlanGrasp.Request:
    request = PlanGrasp.Request(depth=depth_metres_to_msg(DEPTH_M, depth_encoding, header()),
                                camera_info=make_camera_info(K, 640, 480, header()), top_k=top_k)
    for name, value in overrides.items():
        setattr(request, name, value)
    return request


def objects_request(objects) -> PlanGrasp.Request:
    return image_request(objects=objects)


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
    assert grasp.pose_base.header.frame_id == BASE_FRAME
    # The camera is 0.40 m above the table (z = 0): the grasp point is on an object top.
    assert p.z == pytest.approx(0.40 - DEPTH_M[v, u], abs=5e-3) and 0.03 < p.z < 0.055
    rotation = quaternion_xyzw_to_matrix([o.x, o.y, o.z, o.w])
    np.testing.assert_allclose(rotation[:, 2], [0, 0, -1], atol=1e-6)


def test_without_a_calibration_no_grasp_is_in_the_robots_frame(inference_service, executor, call):
    """No pose on TF and base_T_camera not set, a camera looking straight down 0.40 m above the table: until
    2026-12-02 the schema's placeholder pose (top-down at 0.40 m) found its table level there and the grasps came
    in the robot's frame, so a camera mounted near that pose (or a frame before /tf_static) would have sent the arm
    where nothing was measured. Now they are in the table frame, which the executor refuses; with
    camera_pose_from_table off the frame is refused, saying why."""
    _, _, client = inference_service("uncalibrated_client")
    response = plan(executor, call, client, image_request(top_k=3))
    assert response.success, response.message
    assert {g.pose_base.header.frame_id for g in response.grasps} == {"defgg_table_estimate"}
    _, _, strict = inference_service("uncalibrated_strict_client", camera_pose_from_table=False,
                                     plan_grasp_service="/test/strict_plan", perceive_service="/test/strict_perceive")
    refused = plan(executor, call, strict, image_request())
    assert not refused.success and not refused.grasps
    assert "no camera pose" in refused.message and "base_T_camera is not set" in refused.message, refused.message


def test_a_request_with_its_depth_is_perceived_by_the_segmentation_node(cell, executor, call):
    node, _, client = cell
    response = plan(executor, call, client, image_request("32FC1", top_k=3))
    assert response.success, response.message
    assert 1 <= len(response.grasps) <= 3 and response.inference_time_s > 0
    for grasp in response.grasps:
        assert_valid_grasp(grasp)
    assert node.segmentation_node.diagnostics.values()["perceive service count"] >= 1


def test_grasps_carry_the_pads_contacts_lines_on_the_standing_cylinder_none_on_the_box(cell, executor, call):
    """Grasp.contact_radii_m and contact_line_lengths_m (planning/contact_radii.py via TabletopGrasp): the standing
    2.5 cm cylinder's side touches each pad along a vertical line (radius: the curved way's, ~its own; length: the
    pad's 18 mm, the cylinder stands above the pad's top), the box's faces nothing (the squeeze's flat law)."""
    _, _, client = cell
    response = plan(executor, call, client, image_request(top_k=2))
    assert response.success, response.message
    contacts = {int(TRUTH[int(round(g.center_v_px)), int(round(g.center_u_px))]):
                (list(g.contact_radii_m), list(g.contact_line_lengths_m)) for g in response.grasps}
    assert set(contacts) == {1, 2}, contacts          # one grasp per object first
    assert contacts[1] == ([], []), contacts
    radii, lengths = contacts[2]
    assert len(radii) == 2 and all(0.0125 <= r <= 0.05 for r in radii), contacts
    assert len(lengths) == 2 and all(0.015 <= length <= 0.018 + 1e-9 for length in lengths), contacts
    # The section the pads squeeze (the squeeze's section law): the object's outline at the pads' height in the
    # grasp's frame; the cylinder (radius 2.5 cm, 4 cm high): a disc of ~19.6 cm^2 at its height
    for g in response.grasps:
        heights = np.reshape(g.section_heights_m, (g.section_rows, -1))
        assert g.section_cell_m == pytest.approx(0.003) and heights[g.section_rows // 2].any()
    cylinder = next(g for g in response.grasps
                    if int(TRUTH[int(round(g.center_v_px)), int(round(g.center_u_px))]) == 2)
    heights = np.asarray(cylinder.section_heights_m)
    assert np.count_nonzero(heights) * 0.003 ** 2 == pytest.approx(math.pi * 0.025 ** 2, rel=0.2)
    assert np.median(heights[heights > 0]) == pytest.approx(0.04, abs=0.003)


def test_plan_grasp_on_a_perceive_answer_gives_the_same_grasps(cell, executor, call):
    node, client_node, client = cell
    perceive = client_node.create_client(Perceive, topics.PERCEIVE_SERVICE)
    assert perceive.wait_for_service(timeout_sec=10.0)
    request = image_request(top_k=3)
    perceived = call(executor, perceive, Perceive.Request(depth=request.depth, camera_info=request.camera_info),
                     60.0, "perceive")
    assert perceived.success, perceived.message
    assert len(perceived.perceived.objects) == 2 and perceived.perceived.camera_pose_source == "parameter"
    labels = image_to_numpy(perceived.perceived.labels)
    assert labels.shape == (480, 640) and set(np.unique(labels)) == {0, 1, 2}
    given = plan(executor, call, client, image_request(top_k=3, perceived=perceived.perceived))
    forwarded = plan(executor, call, client, request)
    assert given.success and forwarded.success
    assert [(g.center_u_px, g.center_v_px, g.angle_rad, g.width_m) for g in given.grasps] == \
        [(g.center_u_px, g.center_v_px, g.angle_rad, g.width_m) for g in forwarded.grasps]


def test_plan_grasp_with_objects_gives_them_their_modulus(cell, executor, call):
    _, _, client = cell
    response = plan(executor, call, client, objects_request([entry(2e5)]))
    assert response.success, response.message
    assert_valid_grasp(response.grasps[0])
    assert response.grasps[0].youngs_modulus_pa == pytest.approx(2e5)


def test_synchronised_streams_publish_and_serve_empty_requests(cell, executor, spin, call):
    node, client_node, client = cell
    pubs = {name: client_node.create_publisher(kind, topic, qos.SENSOR_DATA) for name, kind, topic in (
        ("depth", Image, topics.DEPTH_IMAGE), ("info", CameraInfo, topics.DEPTH_CAMERA_INFO))}
    got = {"grasp": [], "quality": [], "markers": [], "perceived": []}
    client_node.create_subscription(Grasp, topics.BEST_GRASP, got["grasp"].append, qos.STATE)
    client_node.create_subscription(Image, topics.QUALITY_IMAGE, got["quality"].append, qos.SENSOR_DATA)
    client_node.create_subscription(MarkerArray, topics.GRASP_MARKERS, got["markers"].append, qos.STATE)
    client_node.create_subscription(PerceivedObjects, topics.PERCEIVED_OBJECTS, got["perceived"].append,
                                    qos.SENSOR_DATA)
    ticks = [0]

    def outputs_arrived():
        ticks[0] += 1
        if ticks[0] % 10 == 1:
            # Best effort + discovery: resend until synchronised, each time as a new frame (stamp 42 s + n ms):
            # a stamp the nodes have handled is never handled again, and under load the first depth can reach
            # the segmentation node before its camera_info (that frame is answered "no camera_info yet").
            h = header(stamp_sec=42, stamp_nanosec=ticks[0] * 10**6)
            pubs["info"].publish(make_camera_info(K, 640, 480, h))
            pubs["depth"].publish(depth_metres_to_msg(DEPTH_M, "16UC1", h))
        return bool(got["grasp"] and got["quality"] and got["markers"])

    spin(executor, outputs_arrived, 30.0, "perceived objects, best grasp, quality image and markers")
    assert node.synced_frames >= 1
    grasp_stamp_ns = stamp_to_ns(got["grasp"][0].header.stamp)
    assert grasp_stamp_ns // 10**9 == 42 and grasp_stamp_ns in {stamp_to_ns(m.header.stamp) for m in got["perceived"]}
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


def _perceived(**changes):
    msg = PerceivedObjects(header=header(), error="")
    for name, value in changes.items():
        setattr(msg, name, value)
    return msg


BAD_REQUESTS = {
    "empty request, nothing synchronised yet": (PlanGrasp.Request, "no synchronised"),
    "rgb8 depth": (_wrong(image_request, depth=numpy_to_image(np.zeros((480, 640, 3), np.uint8), "rgb8")),
                   "16UC1"),
    "unknown encoding": (_wrong(image_request, depth__encoding="bayer_grbg8"), "16UC1"),
    "depth with zero width": (_wrong(image_request, depth=Image(height=480, encoding="16UC1")), "0x480"),
    "truncated data": (_wrong(image_request, depth__data=bytes(100)), "B, expected"),
    "camera_info size mismatch": (_wrong(image_request, camera_info=make_camera_info(K, 320, 240)), "camera_info"),
    "no camera_info": (_wrong(image_request, camera_info=CameraInfo()), "no camera_info"),
    "zero focal length": (_wrong(image_request, camera_info__k=[0.0] * 9), "focal"),
    "all-NaN depth": (_wrong(image_request, depth=NAN_DEPTH), "no valid pixel"),
    "metres in 16UC1": (_wrong(image_request, depth=numpy_to_image(np.ones((480, 640), np.uint16), "16UC1")),
                        "look like metres"),
    "perceived without depth": (lambda: PlanGrasp.Request(perceived=_perceived(error="x")), "without the depth"),
    "a frame the segmentation node could not perceive": (
        _wrong(image_request, perceived=_perceived(error="no table found")), "no table found"),
    "perceived of another size": (_wrong(image_request, perceived=_perceived(
        labels=numpy_to_image(np.zeros((240, 320), np.uint8), "mono8"))), "perceived labels is 320x240"),
    "perceived and objects": (_wrong(image_request, objects=[entry(2e5)], perceived=_perceived(
        labels=numpy_to_image(np.zeros((480, 640), np.uint8), "mono8"))), "either"),
    "E = 0": (lambda: objects_request([entry(0.0)]), "> 0"),
    "E < 0": (lambda: objects_request([entry(-2e5)]), "> 0"),
    "E NaN": (lambda: objects_request([entry(float("nan"))]), "> 0"),
    "E absurd": (lambda: objects_request([entry(1e30)]), "plausible"),
    "roi off image": (lambda: objects_request([entry(2e5, (5000, 0, 10, 10))]), "outside"),
    "top_k too big": (lambda: image_request(top_k=1000), "top_k"),
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


def test_depth_only_model_via_use_stiffness_false(executor, spin, inference_service, call):
    from defgg_ros.nodes.grasp_inference_node import default_model_path

    checkpoint = default_model_path(False)
    node, _, client = inference_service("depth_only_client", model_path=str(checkpoint), use_stiffness=False,
                                        base_T_camera=BASE_T_CAMERA, plan_grasp_service="/test/depth_only_plan")
    assert not node.predictor.uses_stiffness
    response = plan(executor, call, client, image_request())
    assert response.success, response.message
    assert_valid_grasp(response.grasps[0])


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
    assert node.get_parameter("perceived_topic").value == topics.PERCEIVED_OBJECTS


def test_default_model_paths_are_the_shipped_checkpoints():
    from defgg_ros.model.inference import GraspPredictor
    from defgg_ros.nodes.grasp_inference_node import default_model_path

    for use_stiffness, name in ((True, "defgg_cnn.pt"), (False, "ggcnn_depth_only.pt")):
        path = default_model_path(use_stiffness)
        assert path.name == name and path.is_file()
        assert GraspPredictor.from_checkpoint(path).uses_stiffness == use_stiffness


def test_the_executors_grasp_height_rule_reaches_the_planner(executor, checkpoint):
    """PerceivedObjects carries no grasp height rule: the node's grasp_height_rule and
    grasp_depth_below_surface_m (the executor's) go into the view its searches read."""
    from defgg_ros.nodes.perceived_msg import perceived_to_msg
    from defgg_ros.perception.geometry import transform_from_list
    from defgg_ros.perception.tabletop import TabletopConfig
    from defgg_ros.planning.perceived_frame import perceive_frame

    parts, _, _ = perceive_frame(DEPTH_M, K, transform_from_list(BASE_T_CAMERA), TabletopConfig())
    matched = {"depth": depth_metres_to_msg(DEPTH_M, "16UC1", header()),
               "perceived": perceived_to_msg(parts, header(), BASE_FRAME, "parameter"),
               "info": make_camera_info(K, 640, 480, header())}
    node = GraspInferenceNode(context=executor.context, parameter_overrides=[
        Parameter("model_path", value=str(checkpoint)), Parameter("grasp_height_rule", value="below_surface"),
        Parameter("grasp_depth_below_surface_m", value=0.007), Parameter("prepare_on_arrival", value=False)])
    try:
        config = node._convert(matched).objects.view.config
    finally:
        node.destroy_node()
    assert (config.grasp_height_rule, config.grasp_depth_below_surface_m) == ("below_surface", 0.007)

"""Fuzz PlanGrasp: hundreds of malformed requests, every one refused, then a valid one served. Requests with
depth alone go through the segmentation node's Perceive service; malformed perceived objects are refused too."""
import numpy as np
from defgg_interfaces.msg import ObjectStiffness, PerceivedObjects
from defgg_interfaces.srv import PlanGrasp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import Image

from defgg_ros.perception.synthetic_scene import SceneObject, SyntheticScene, default_camera_k, render
from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info, numpy_to_image

SERVICE = "/fuzz/plan_grasp"
K = default_camera_k()
DEPTH_M, TRUTH = render(SyntheticScene(objects=(SceneObject((0.0, 0.0), 0.05, (0.05, 0.05)),)))
DEPTH_MSG = depth_metres_to_msg(DEPTH_M, "16UC1")
INFO_MSG = make_camera_info(K, 640, 480)
PERCEIVE_PREFIX = "the segmentation node could not perceive the request's depth: "


def valid_request() -> PlanGrasp.Request:
    return PlanGrasp.Request(depth=DEPTH_MSG, camera_info=INFO_MSG)


def _perceived(labels: Image, source="parameter", plane=(0.0, 0.0, 1.0, 0.0)) -> PerceivedObjects:
    """Perceived objects of DEPTH_MSG's frame with this label image (the rest empty: malformed anyway)."""
    return PerceivedObjects(header=DEPTH_MSG.header, labels=labels, camera_pose_source=source,
                            table_plane=list(plane))


def _copy_image(msg: Image, **changes) -> Image:
    out = Image(height=msg.height, width=msg.width, encoding=msg.encoding, is_bigendian=msg.is_bigendian,
                step=msg.step, data=bytes(msg.data))
    for name, value in changes.items():
        setattr(out, name, value)
    return out


random_images = st.builds(
    lambda enc, w, h, step, data, be: Image(encoding=enc, width=w, height=h, step=step, data=data, is_bigendian=be),
    st.sampled_from(["16UC1", "32FC1", "mono8", "rgb8", "", "32FC3", "bayer_rggb8"]),
    st.integers(0, 40), st.integers(0, 40), st.integers(0, 200), st.binary(max_size=600), st.integers(0, 1))

bad_moduli = st.one_of(st.floats(max_value=0.0), st.just(float("nan")), st.just(float("inf")),
                       st.floats(min_value=2e12, allow_infinity=False))


MUTATIONS = {
    "depth encoding": st.sampled_from(["mono8", "rgb8", "8UC3", "", "16SC1"]).map(
        lambda e: ("depth", _copy_image(DEPTH_MSG, encoding=e))),
    "truncated depth": st.integers(0, len(DEPTH_MSG.data) - 1).map(
        lambda n: ("depth", _copy_image(DEPTH_MSG, data=bytes(DEPTH_MSG.data)[:n]))),
    "random depth": random_images.map(lambda m: ("depth", m)),
    # An empty perceived objects means "not given" (the segmentation node perceives the depth), so not malformed.
    "random perceived labels": random_images.filter(lambda m: m.width and m.height).map(
        lambda m: ("perceived", _perceived(m))),
    "bad perceived pose source or plane": st.tuples(st.sampled_from(["", "guess", "parameter"]),
                                                    st.sampled_from([(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 2.0, 0.0),
                                                                     (float("nan"), 0.0, 1.0, 0.0)])).map(
        lambda t: ("perceived", _perceived(numpy_to_image(np.zeros((480, 640), np.uint8), "mono8"), *t))),
    "bad focal": st.tuples(st.sampled_from([0.0, -385.0, float("nan"), float("inf")]), st.integers(0, 1)).map(
        lambda t: ("k", t)),
    "camera size": st.tuples(st.integers(0, 2000), st.integers(0, 2000)).filter(lambda s: s != (640, 480)).map(
        lambda s: ("info_size", s)),
    "bad objects": st.lists(bad_moduli, min_size=1, max_size=3).map(lambda values: ("objects", values)),
    "top_k": st.integers(51, 2**32 - 1).map(lambda k: ("top_k", k)),
    "invalid depth values": st.sampled_from(["nan", "zero", "metres_u16"]).map(lambda k: ("depth_values", k)),
}


def apply(request: PlanGrasp.Request, mutation) -> None:
    kind, value = mutation
    if kind in ("depth", "perceived"):
        setattr(request, kind, value)
    elif kind == "k":
        k = list(request.camera_info.k)
        k[0 if value[1] == 0 else 4] = value[0]
        request.camera_info = make_camera_info(K, 640, 480)
        request.camera_info.k = k
    elif kind == "info_size":
        request.camera_info = make_camera_info(K, 640, 480)
        request.camera_info.width, request.camera_info.height = value
    elif kind == "objects":
        request.perceived = PerceivedObjects()
        request.objects = [ObjectStiffness(name="fuzz", youngs_modulus_pa=v) for v in value]
    elif kind == "top_k":
        request.top_k = value
    elif kind == "depth_values":
        if value == "nan":
            request.depth = numpy_to_image(np.full((480, 640), np.nan, np.float32), "32FC1")
        elif value == "zero":
            request.depth = numpy_to_image(np.zeros((480, 640), np.uint16), "16UC1")
        else:
            request.depth = numpy_to_image(np.rint(DEPTH_M).astype(np.uint16) + 1, "16UC1")


malformed_requests = st.one_of(
    st.builds(lambda d, s, t: PlanGrasp.Request(depth=d, perceived=_perceived(s), camera_info=INFO_MSG, top_k=t),
              random_images, random_images, st.integers(0, 60)),
    st.lists(st.sampled_from(sorted(MUTATIONS)), min_size=1, max_size=3).flatmap(
        lambda names: st.tuples(*[MUTATIONS[n] for n in names])),
)


def test_fuzzed_requests_are_refused_then_a_valid_one_is_served(executor, spin, inference_service, call):
    _, _, client = inference_service("fuzz_client", plan_grasp_service=SERVICE)
    seen = []

    @settings(max_examples=250, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(malformed_requests)
    def fuzz(example):
        if isinstance(example, PlanGrasp.Request):
            request = example
        else:
            request = valid_request()
            for mutation in example:
                apply(request, mutation)
        response = call(executor, client, request, 20.0, "fuzzed plan_grasp response")
        assert not response.success, f"malformed request accepted: {example!r:.300}"
        assert response.message and not response.grasps
        assert not response.message.startswith("internal error"), response.message
        seen.append(response.message.removeprefix(PERCEIVE_PREFIX))

    fuzz()
    assert len(seen) >= 200
    assert len({message.split(":")[0][:40] for message in seen}) >= 10  # many different failure paths
    response = call(executor, client, valid_request(), 20.0, "valid plan_grasp response")
    assert response.success, response.message
    grasp = response.grasps[0]
    assert TRUTH[int(round(grasp.center_v_px)), int(round(grasp.center_u_px))] > 0

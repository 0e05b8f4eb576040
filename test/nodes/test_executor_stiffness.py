"""The executor's side of a squeeze (defgg_ros/nodes/executor_stiffness.py): what it sends to the segmentation node,
and that a missing service or a grasp without an image position is said, never raised (the goal's outcome stands).

A real SetStiffness server in this test (a stand-in for the segmentation node's: it records the request and
publishes the set as the segmentation node does, latched), over real DDS.
"""
import threading

import pytest
from defgg_interfaces.msg import Grasp, ObjectStiffness, StiffnessAssignment
from defgg_interfaces.srv import SetStiffness
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from defgg_ros.nodes.executor_stiffness import MIN_ROI_PX, StiffnessUpdater, measured_roi
from defgg_ros.ros import qos

pytestmark = pytest.mark.ros


def _grasp(u=320.0, v=240.0, width_px=60.0):
    return Grasp(center_u_px=u, center_v_px=v, width_px=width_px)


def _teller(executor, name: str, service: str, assignments: str, on_set) -> StiffnessUpdater:
    """A stand-in segmentation node serving `service` with on_set, and an updater on its own node, both spun."""
    server = Node(f"stand_in_for_{name}", context=executor.context)
    server.create_service(SetStiffness, service, on_set)
    node = Node(name, context=executor.context)
    updater = StiffnessUpdater(node, service, assignments, ReentrantCallbackGroup())
    executor.add_node(server)
    executor.add_node(node)
    return updater


def test_the_roi_is_a_square_around_the_grasp_pixel_as_wide_as_its_opening():
    assert measured_roi(_grasp(320, 240, 60)) == (290, 210, 60, 60)
    assert measured_roi(_grasp(5, 5, 2)) == (0, 0, MIN_ROI_PX, MIN_ROI_PX)   # at least MIN_ROI_PX, inside the image
    assert measured_roi(_grasp(0, 0, 60)) is None                            # a hand-made grasp: no image position


def test_the_measurement_is_appended_to_the_entries_in_force_and_replaces_an_older_one(executor, spin):
    server = Node("stand_in_segmentation", context=executor.context)
    requests = []
    latched = server.create_publisher(StiffnessAssignment, "/test_squeeze/assignments", qos.LATCHED)
    sponge = ObjectStiffness(name="sponge", youngs_modulus_pa=2e4)
    sponge.roi.x_offset, sponge.roi.y_offset, sponge.roi.width, sponge.roi.height = 0, 0, 100, 100
    latched.publish(StiffnessAssignment(objects=[sponge]))

    def on_set(request, response):
        requests.append(list(request.objects))
        latched.publish(StiffnessAssignment(objects=list(request.objects)))
        response.success, response.message = True, f"{len(request.objects)} stiffness entries"
        return response

    server.create_service(SetStiffness, "/test_squeeze/set", on_set)
    client_node = Node("squeeze_teller", context=executor.context)
    updater = StiffnessUpdater(client_node, "/test_squeeze/set", "/test_squeeze/assignments", ReentrantCallbackGroup())
    executor.add_node(server)
    executor.add_node(client_node)
    spin(executor, lambda: updater._in_force is not None, 20.0, "the latched assignments")
    said = []
    worker = threading.Thread(target=lambda: said.append(updater.tell(_grasp(), 1.5e5, 10.0)))
    worker.start()
    spin(executor, lambda: bool(said), 30.0, "the first measurement sent")
    assert said[0].startswith("sent 1.5e+05 Pa"), said
    assert [(e.name, e.youngs_modulus_pa) for e in requests[0]] == [("sponge", 2e4), ("measured at (320, 240) px",
                                                                                        1.5e5)]
    spin(executor, lambda: len(updater._in_force.objects) == 2, 20.0, "the new set, latched")
    worker = threading.Thread(target=lambda: said.append(updater.tell(_grasp(322, 241), 3e5, 10.0)))
    worker.start()
    spin(executor, lambda: len(said) == 2, 30.0, "the second measurement sent")
    assert [(e.name, e.youngs_modulus_pa) for e in requests[1]] == [("sponge", 2e4), ("measured at (322, 241) px",
                                                                                        3e5)]


def test_no_service_or_no_image_position_is_said_not_raised(executor, spin):
    node = Node("squeeze_teller_alone", context=executor.context)
    updater = StiffnessUpdater(node, "/test_squeeze/nobody", "/test_squeeze/none", ReentrantCallbackGroup())
    executor.add_node(node)
    assert updater.tell(_grasp(0, 0), 1e5, 0.5).startswith("not sent: the grasp has no image position")
    assert "is not available" in updater.tell(_grasp(), 1e5, 0.5)


def test_nothing_is_sent_while_the_entries_in_force_are_unknown(executor, spin):
    """A service but no latched set heard (another assignments topic, a start-up race): the request would have
    replaced every configured and measured entry with the one measurement."""
    requests = []

    def on_set(request, response):
        requests.append(list(request.objects))
        response.success, response.message = True, "ok"
        return response

    updater = _teller(executor, "squeeze_teller_unheard", "/test_squeeze/quiet_set", "/test_squeeze/unheard", on_set)
    said = []
    worker = threading.Thread(target=lambda: said.append(updater.tell(_grasp(), 1.5e5, 1.0)))
    worker.start()
    spin(executor, lambda: bool(said), 30.0, "the answer")
    assert said[0].startswith("not sent: nothing heard on /test_squeeze/unheard") and not requests

"""The custom interfaces are built and a PlanGrasp call crosses real DDS."""
import math

import pytest
from defgg_interfaces.action import PickAndPlace
from defgg_interfaces.msg import Grasp
from defgg_interfaces.srv import PlanGrasp


def _server_node(context):
    from rclpy.node import Node

    node = Node("plan_grasp_echo_server", context=context)

    def handle(request, response):
        # Echo what arrived so the client can check the request crossed intact.
        if request.depth.width == 0:
            response.success = False
            response.message = "empty depth image"
            return response
        response.success = True
        response.message = f"{request.depth.width}x{request.depth.height} {request.depth.encoding}"
        for rank in range(max(1, request.top_k)):
            grasp = Grasp()
            grasp.quality = 1.0 / (rank + 1)
            grasp.width_m = 0.04
            grasp.angle_rad = math.pi / 4
            grasp.center_u_px = float(request.depth.data[rank])
            grasp.contact_radii_m = [0.01 * (rank + 1), 0.02] if rank else []   # the first: flat (empty)
            grasp.contact_line_lengths_m = [0.0, 0.018] if rank == 2 else []    # the last: a line at one pad
            response.grasps.append(grasp)
        return response

    node.create_service(PlanGrasp, "plan_grasp", handle)
    return node


def test_plan_grasp_round_trip_between_two_nodes(rclpy_context, executor, spin, call):
    from rclpy.node import Node

    server = _server_node(rclpy_context)
    client_node = Node("plan_grasp_client", context=rclpy_context)
    executor.add_node(server)
    executor.add_node(client_node)
    client = client_node.create_client(PlanGrasp, "plan_grasp")
    spin(executor, lambda: client.service_is_ready(), 10.0, "PlanGrasp service to appear")

    request = PlanGrasp.Request()
    request.depth.width, request.depth.height, request.depth.encoding = 2, 2, "16UC1"
    request.depth.step = 4
    request.depth.data = bytes([7, 0, 9, 0, 1, 0, 2, 0])
    request.top_k = 3
    response = call(executor, client, request, 10.0, "PlanGrasp response")
    assert response.success, response.message
    assert response.message == "2x2 16UC1"
    assert [g.quality for g in response.grasps] == pytest.approx([1.0, 0.5, 1 / 3])
    assert [g.center_u_px for g in response.grasps] == [7.0, 0.0, 9.0]
    assert [list(g.contact_radii_m) for g in response.grasps] == [[], [0.02, 0.02], [0.03, 0.02]]
    assert [list(g.contact_line_lengths_m) for g in response.grasps] == [[], [], [0.0, 0.018]]

    empty = call(executor, client, PlanGrasp.Request(), 10.0, "PlanGrasp response to empty request")
    assert not empty.success and "empty" in empty.message


def test_action_and_message_fields_exist():
    goal = PickAndPlace.Goal()
    assert goal.plan_grasp is False
    result = PickAndPlace.Result()
    for field in ("success", "failure_reason", "phase_reached", "contact_height_m",
                  "gripper_width_closed_m", "held_after_transfer"):
        assert hasattr(result, field)
    assert hasattr(PickAndPlace.Feedback(), "phase")

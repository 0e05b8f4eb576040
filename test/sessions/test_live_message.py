"""Recorded goals and requests go back into the live graph as today's types, also after an interface
gained fields (sessions/live_message.py): a PickAndPlace goal recorded before Grasp had estimated_mass_kg
and finger_force_n (sessions recorded until 2026-11-27)."""
import pytest
from defgg_interfaces.action import PickAndPlace
from rclpy.serialization import deserialize_message, serialize_message
from support.session_bag_helpers import GRASP_BEFORE_GRIP_FIELDS, GRASP_BEFORE_LINE_LENGTHS

from defgg_ros.sessions.bag import BagMessage, recorded_typestore
from defgg_ros.sessions.live_message import live_message

GOAL = "defgg_interfaces/action/PickAndPlace_Goal"
OLD_GOAL_DEF = ("bool plan_grasp\ndefgg_interfaces/Grasp grasp\ngeometry_msgs/PoseStamped place_pose\n"
                + "=" * 80 + "\nMSG: defgg_interfaces/Grasp\n" + GRASP_BEFORE_GRIP_FIELDS)


def old_goal_raw() -> bytes:
    store = recorded_typestore(GOAL, OLD_GOAL_DEF)
    t = store.types

    def stamped(x):
        header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=12, nanosec=5),
                                          frame_id="panda_link0")
        pose = t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=x, y=0.1, z=0.05),
                                           orientation=t["geometry_msgs/msg/Quaternion"](x=1.0, y=0.0, z=0.0, w=0.0))
        return t["geometry_msgs/msg/PoseStamped"](header=header, pose=pose)

    grasp = t["defgg_interfaces/msg/Grasp"](
        header=stamped(0.0).header, pose_base=stamped(0.5), pose_camera=stamped(0.1), width_m=0.04, quality=0.9,
        angle_rad=0.3, center_u_px=1.0, center_v_px=2.0, width_px=30.0, youngs_modulus_pa=2e5, object_id=3)
    return bytes(store.serialize_cdr(t[GOAL](plan_grasp=False, grasp=grasp, place_pose=stamped(0.3)), GOAL))


def test_a_goal_recorded_before_grasp_gained_fields_is_sent_as_todays_goal():
    raw = old_goal_raw()
    with pytest.raises(Exception, match="deserialize"):
        deserialize_message(raw, PickAndPlace.Goal)       # what the replay did before: the bytes do not fit
    goal = live_message(BagMessage("/defgg/session/pick_goal", GOAL, 0, raw, OLD_GOAL_DEF), PickAndPlace.Goal)
    g = goal.grasp
    assert (g.width_m, g.quality, g.youngs_modulus_pa, g.object_id) == (0.04, 0.9, 2e5, 3)
    assert (g.pose_base.pose.position.x, g.pose_base.header.stamp.sec, g.header.frame_id) == (0.5, 12, "panda_link0")
    assert goal.place_pose.pose.position.x == 0.3 and goal.place_pose.pose.orientation.x == 1.0
    assert g.estimated_mass_kg == 0.0 and g.finger_force_n == 0.0     # unknown then: the executor's own rule
    assert list(g.contact_radii_m) == []                                # unknown then: the squeeze's flat law
    assert list(g.contact_line_lengths_m) == []                         # and no line contacts


def test_a_message_of_the_installed_layout_round_trips():
    goal = PickAndPlace.Goal(plan_grasp=True)
    goal.grasp.finger_force_n, goal.grasp.width_m, goal.grasp.contact_radii_m = 0.7, 0.05, [0.02, 0.03]
    goal.grasp.contact_line_lengths_m = [0.0, 0.018]
    goal.grasp.section_cell_m, goal.grasp.section_rows, goal.grasp.section_heights_m = 0.003, 2, [0.0, 0.03, 0.03, 0.0]
    raw = serialize_message(goal)
    current = "bool plan_grasp\ndefgg_interfaces/Grasp grasp\ngeometry_msgs/PoseStamped place_pose\n" + "=" * 80 + \
        "\nMSG: defgg_interfaces/Grasp\n" + GRASP_BEFORE_LINE_LENGTHS + "float64[] contact_line_lengths_m\n" + \
        "float64 section_cell_m\nuint32 section_rows\nfloat32[] section_heights_m\n"
    for msgdef in ("", current):         # no definition recorded: the installed one
        back = live_message(BagMessage("/defgg/session/pick_goal", GOAL, 0, raw, msgdef), PickAndPlace.Goal)
        assert back == goal


def test_a_request_with_images_and_fixed_arrays_copies_every_byte():
    from defgg_interfaces.srv import PlanGrasp
    from sensor_msgs.msg import Image

    from defgg_ros.sessions.interfaces import session_typestore
    from defgg_ros.sessions.live_message import copy_fields

    request = PlanGrasp.Request(top_k=2)
    request.depth = Image(height=2, width=3, encoding="32FC1", step=12, data=bytes(range(24)))
    request.camera_info.k = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
    decoded = session_typestore().deserialize_cdr(serialize_message(request), "defgg_interfaces/srv/PlanGrasp_Request")
    assert copy_fields(decoded, PlanGrasp.Request()) == request

"""Small real session bags for the tests, written with the project's own SessionWriter."""
import numpy as np
from defgg_interfaces.msg import Grasp, StiffnessAssignment
from defgg_interfaces.srv import PlanGrasp
from rclpy.serialization import serialize_message
from std_msgs.msg import Header

from defgg_ros.ros.conversions import depth_metres_to_msg, make_camera_info, ns_to_stamp
from defgg_ros.sessions import session_topics as st
from defgg_ros.sessions.bag import SessionWriter
from defgg_ros.sessions.compare import Tolerances
from defgg_ros.sessions.metadata import make_metadata
from defgg_ros.sessions.session_topics import topics  # absolute names (bag channels)

REPO = __import__("pathlib").Path(__file__).resolve().parents[2]
# defgg_interfaces/Grasp as sessions recorded it: until 2026-11-27 (before estimated_mass_kg and finger_force_n),
# and until 2026-11-30 (before contact_line_lengths_m).
GRASP_BEFORE_GRIP_FIELDS = """std_msgs/Header header
geometry_msgs/PoseStamped pose_base
geometry_msgs/PoseStamped pose_camera
float64 width_m
float64 quality
float64 angle_rad
float64 center_u_px
float64 center_v_px
float64 width_px
float64 youngs_modulus_pa
int32 object_id
"""
GRASP_BEFORE_LINE_LENGTHS = GRASP_BEFORE_GRIP_FIELDS + """float64 estimated_mass_kg
float64 finger_force_n
float64[] contact_radii_m
"""
K = np.array([[385.0, 0, 31.5], [0, 385.0, 23.5], [0, 0, 1]])


def metadata(name="unit"):
    return make_metadata(name, source="real", scene_path=None, model_path=REPO / "models" / "defgg_cnn.pt",
                         use_stiffness=True, parameters={}, pick=False, tolerances=Tolerances())


def grasp(stamp_ns, x_m=0.5, angle_rad=0.2, width_m=0.03):
    g = Grasp(header=Header(stamp=ns_to_stamp(stamp_ns)), width_m=width_m, angle_rad=angle_rad, quality=0.9)
    g.pose_base.pose.position.x = x_m
    return g


def write_small_session(path, n_frames=3, with_plan=True):
    """n depth frames (64x48) 1 s apart, a grasp on each, an assignment first and one plan call."""
    writer = SessionWriter(path, metadata(path.name), 1_000)
    writer.write(topics.STIFFNESS_ASSIGNMENTS, serialize_message(StiffnessAssignment(default_youngs_modulus_pa=2e6)),
                 2_000)
    depth = np.full((48, 64), 0.4, dtype=np.float32)
    for i in range(n_frames):
        stamp = (i + 1) * 1_000_000_000
        header = Header(stamp=ns_to_stamp(stamp), frame_id="cam")
        t = 10_000 + i * 1_000_000
        writer.write(topics.DEPTH_CAMERA_INFO, serialize_message(make_camera_info(K, 64, 48, header)), t)
        writer.write(topics.DEPTH_IMAGE, serialize_message(depth_metres_to_msg(depth, "16UC1", header)), t + 1)
        writer.write(topics.BEST_GRASP, serialize_message(grasp(stamp, x_m=0.5 + 0.01 * i)), t + 2)
    if with_plan:
        writer.write(st.PLAN_REQUEST, serialize_message(PlanGrasp.Request(top_k=1)), 50_000_000)
        response = PlanGrasp.Response(success=True, grasps=[grasp(n_frames * 1_000_000_000)])
        writer.write(st.PLAN_RESPONSE, serialize_message(response), 50_000_001)
    return writer.close()

"""What a session bag holds: topic name -> message type, and which topics are latched.

Camera, robot and cell topics keep their live names (so `ros2 bag play`
feeds a graph directly). Service calls and action goals are not topics; the
recorder, acting as the client, writes them on `/defgg/session/...` topics
with the srv/action part types.
"""
from types import SimpleNamespace

from defgg_ros.ros import topics as _names


def absolute(name: str) -> str:
    """The name at the root namespace: what rosbag2 writes as a channel name."""
    return name if name.startswith("/") else "/" + name


# Sessions record and replay a cell at the root namespace, and a bag's channels carry absolute names
# (as rosbag2 writes them); the names in defgg_ros/ros/topics.py are relative (resolved in a node's
# namespace), so the sessions code uses these absolute forms of them.
topics = SimpleNamespace(**{key: absolute(value) for key, value in vars(_names).items()
                            if key.isupper() and isinstance(value, str)
                            and not key.endswith("_FRAME") and key != "DEFAULT_ROBOT_TYPE"})

SESSION_PREFIX = "/defgg/session"
METADATA = f"{SESSION_PREFIX}/metadata"                      # std_msgs/String, JSON (also in metadata.yaml)
PLAN_REQUEST = f"{SESSION_PREFIX}/plan_grasp_request"
PLAN_RESPONSE = f"{SESSION_PREFIX}/plan_grasp_response"
PICK_GOAL = f"{SESSION_PREFIX}/pick_goal"
PICK_FEEDBACK = f"{SESSION_PREFIX}/pick_feedback"
PICK_RESULT = f"{SESSION_PREFIX}/pick_result"
# The fake driver's latched scene description (JSON), recorded when present.
DRIVER_SCENE = topics.FAKE_SCENE

TOPIC_TYPES = {
    topics.DEPTH_IMAGE: "sensor_msgs/msg/Image",
    topics.DEPTH_CAMERA_INFO: "sensor_msgs/msg/CameraInfo",
    topics.COLOR_IMAGE: "sensor_msgs/msg/Image",
    topics.JOINT_STATES: "sensor_msgs/msg/JointState",
    topics.STIFFNESS_ASSIGNMENTS: "defgg_interfaces/msg/StiffnessAssignment",
    topics.BEST_GRASP: "defgg_interfaces/msg/Grasp",
    DRIVER_SCENE: "std_msgs/msg/String",
    topics.TF_STATIC: "tf2_msgs/msg/TFMessage",     # the camera's calibration (and the camera's own frames)
    METADATA: "std_msgs/msg/String",
    PLAN_REQUEST: "defgg_interfaces/srv/PlanGrasp_Request",
    PLAN_RESPONSE: "defgg_interfaces/srv/PlanGrasp_Response",
    PICK_GOAL: "defgg_interfaces/action/PickAndPlace_Goal",
    PICK_FEEDBACK: "defgg_interfaces/action/PickAndPlace_Feedback",
    PICK_RESULT: "defgg_interfaces/action/PickAndPlace_Result",
}

# Offered as transient-local in the bag so `ros2 bag play` re-latches them.
LATCHED_TOPICS = frozenset({topics.STIFFNESS_ASSIGNMENTS, DRIVER_SCENE, METADATA, topics.TF_STATIC})

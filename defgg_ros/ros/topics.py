"""Default ROS names of the cell's interfaces, in one place.

Nodes declare these as parameter defaults (defgg_ros/ros/params/*.yaml) so a real cell can remap them.
Camera names follow realsense2_camera (Jazzy: camera/camera/...), robot names follow franka_ros2
(docs/real_cell.md): the joint_trajectory_controller's FollowJointTrajectory action, the gripper
node's franka_msgs actions, the external wrench of the robot state broadcaster.

Every name is relative: a node resolves it in its own namespace, so `-r __ns:=/left` moves all of
a node's topics, services and actions, and at the root namespace they are the same names as
before (`joint_states` is `/joint_states`). Three names stay absolute because ROS fixes them for
the whole graph: /clock (sim time), /tf and /tf_static (tf2); remap them explicitly if needed.
"""

# Camera (realsense2_camera or the fake driver)
DEPTH_IMAGE = "camera/camera/depth/image_rect_raw"           # 16UC1 mm or 32FC1 m
DEPTH_CAMERA_INFO = "camera/camera/depth/camera_info"
COLOR_IMAGE = "camera/camera/color/image_raw"

# Robot (franka_ros2 or the fake driver). The defaults are the Panda's; an FR3 uses arm_id "fr3"
# and the fr3_* names (see arm_names below and sim_bringup/config/real_cell.yaml).
DEFAULT_ARM_ID = "panda"
JOINT_STATES = "joint_states"
ARM_TRAJECTORY_ACTION = "panda_arm_controller/follow_joint_trajectory"  # control_msgs/action/FollowJointTrajectory
JOINT_TRAJECTORY = "panda_arm_controller/joint_trajectory"   # trajectory_msgs/JointTrajectory (same controller)
GRIPPER_MOVE_ACTION = "franka_gripper/move"                  # franka_msgs/action/Move
GRIPPER_GRASP_ACTION = "franka_gripper/grasp"                # franka_msgs/action/Grasp
GRIPPER_HOMING_ACTION = "franka_gripper/homing"              # franka_msgs/action/Homing
EXTERNAL_WRENCH = "franka_robot_state_broadcaster/external_wrench_in_base_frame"  # geometry_msgs/WrenchStamped

# Segmentation node
STIFFNESS_IMAGE = "defgg/stiffness/youngs_modulus_pa"        # 32FC1, Pa per pixel, 0 = background
OBJECT_MASK = "defgg/object_mask"                            # mono8 labels, 0 = background
STIFFNESS_ASSIGNMENTS = "defgg/stiffness_assignments"        # defgg_interfaces/StiffnessAssignment (latched)
SET_STIFFNESS_SERVICE = "defgg/set_stiffness"                # defgg_interfaces/srv/SetStiffness
CAPTURE_BACKGROUND_SERVICE = "defgg/segmentation/capture_background"  # std_srvs/srv/Trigger

# Grasp inference node
BEST_GRASP = "defgg/best_grasp"                              # defgg_interfaces/Grasp
QUALITY_IMAGE = "defgg/quality_image"                        # 32FC1 grasp quality map
GRASP_MARKERS = "defgg/grasp_markers"                        # visualization_msgs/MarkerArray
PLAN_GRASP_SERVICE = "defgg/plan_grasp"                      # defgg_interfaces/srv/PlanGrasp

# Executor node
PICK_AND_PLACE_ACTION = "defgg/pick_and_place"               # defgg_interfaces/action/PickAndPlace

# Fake driver only (ground truth of the simulation)
FAKE_SCENE = "fake_panda/scene"                              # std_msgs/String JSON (latched)
FAKE_OBJECT_POSES = "fake_panda/object_poses"                # geometry_msgs/PoseArray
FAKE_CAPTURE_SERVICE = "fake_panda/capture_depth"            # std_srvs/srv/Trigger

# Graph-wide names (absolute on purpose, see above)
CLOCK = "/clock"
TF = "/tf"                                                   # tf2_msgs/TFMessage
TF_STATIC = "/tf_static"                                     # tf2_msgs/TFMessage, latched

# Frames
BASE_FRAME = "panda_link0"
CAMERA_OPTICAL_FRAME = "camera_depth_optical_frame"
GRASP_FRAME = "defgg_grasp"                                  # the planned grasp (TCP pose), child of the base


def arm_names(arm_id: str = DEFAULT_ARM_ID) -> dict:
    """franka_ros2's names for arm `arm_id` ("panda" or "fr3"): joints, fingers, base frame, controller."""
    if not arm_id or not arm_id.replace("_", "").isalnum():
        raise ValueError(f"arm_id must be a plain name like 'fr3' or 'panda', got {arm_id!r}")
    return {
        "joints": tuple(f"{arm_id}_joint{i}" for i in range(1, 8)),
        "fingers": (f"{arm_id}_finger_joint1", f"{arm_id}_finger_joint2"),
        "base_frame": f"{arm_id}_link0",
        "trajectory_action": f"{arm_id}_arm_controller/follow_joint_trajectory",
        "trajectory_topic": f"{arm_id}_arm_controller/joint_trajectory",
    }

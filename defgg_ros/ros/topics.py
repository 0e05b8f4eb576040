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
COLOR_CAMERA_INFO = "camera/camera/color/camera_info"

# Robot (franka_ros2 3.x on Jazzy, or the fake driver): the names a cell started with franka_bringup's
# franka.launch.py (load_gripper:=true) and a JointTrajectoryController serves; docs/franka_contract.md
# has each topic's QoS and rate, read from franka_ros2's sources. Names that carry the robot type
# (joints, base frame, controller) come from robot_names() below; the defaults are robot type "fer".
ROBOT_TYPES = ("fer", "fr3")          # franka_ros2 Jazzy's robot_type values this cell knows; fer = the Panda
DEFAULT_ROBOT_TYPE = "fer"            # the simulated arm is a Panda
FROM_ROBOT_TYPE = ""                  # a name parameter left empty: robot_names(robot_type)'s name
JOINT_STATES = "joint_states"         # joint_state_publisher: arm + fingers merged (franka.launch.py)
ARM_JOINT_STATES = "franka/joint_states"   # joint_state_broadcaster, remapped by franka.launch.py: arm only
GRIPPER_JOINT_STATES = "franka_gripper/joint_states"  # franka_gripper node: the two fingers only, depth 1
ARM_TRAJECTORY_ACTION = "fer_arm_controller/follow_joint_trajectory"  # control_msgs/action/FollowJointTrajectory
JOINT_TRAJECTORY = "fer_arm_controller/joint_trajectory"     # trajectory_msgs/JointTrajectory (same controller)
GRIPPER_MOVE_ACTION = "franka_gripper/move"                  # franka_msgs/action/Move
GRIPPER_GRASP_ACTION = "franka_gripper/grasp"                # franka_msgs/action/Grasp
GRIPPER_HOMING_ACTION = "franka_gripper/homing"              # franka_msgs/action/Homing
GRIPPER_COMMAND_ACTION = "franka_gripper/gripper_action"     # control_msgs/action/GripperCommand (MoveIt's)
GRIPPER_STOP_SERVICE = "franka_gripper/stop"                 # std_srvs/srv/Trigger: Gripper::stop()
# Robot errors (docs/franka_contract.md): franka_hardware's node `action_server` and the controller manager
ERROR_RECOVERY_ACTION = "action_server/error_recovery"      # franka_msgs/action/ErrorRecovery
LIST_CONTROLLERS_SERVICE = "controller_manager/list_controllers"              # controller_manager_msgs/srv/...
SWITCH_CONTROLLER_SERVICE = "controller_manager/switch_controller"
SET_HARDWARE_STATE_SERVICE = "controller_manager/set_hardware_component_state"
FRANKA_HARDWARE_COMPONENT = "FrankaHardwareInterface"       # ros2_control's name of the arm's hardware (no prefix)
JOINT_STATE_BROADCASTER = "joint_state_broadcaster"
ROBOT_STATE_BROADCASTER = "franka_robot_state_broadcaster"
# The joint_trajectory_controller's result text for the goal its deactivation aborts (INVALID_GOAL)
CONTROLLER_DEACTIVATED_TEXT = "Current goal cancelled during deactivate transition."
# What a person does after a robot error (franka_hardware's doc, "Error Recovery"; docs/real_cell.md)
RECOVERY_STEPS = (f"ros2 action send_goal /{ERROR_RECOVERY_ACTION} franka_msgs/action/ErrorRecovery {{}}; "
                  f"ros2 control set_hardware_component_state {FRANKA_HARDWARE_COMPONENT} active; ros2 control "
                  f"switch_controllers --activate {JOINT_STATE_BROADCASTER} {ROBOT_STATE_BROADCASTER} "
                  "<robot_type>_arm_controller")
# franka_robot_state_broadcaster's convenience topics: best effort, depth 1 (franka_ros2 >= 3.3.0)
EXTERNAL_WRENCH = "franka_robot_state_broadcaster/external_wrench_in_base_frame"  # geometry_msgs/WrenchStamped
CURRENT_POSE = "franka_robot_state_broadcaster/current_pose"                       # geometry_msgs/PoseStamped
MEASURED_JOINT_STATES = "franka_robot_state_broadcaster/measured_joint_states"     # sensor_msgs/JointState
DESIRED_JOINT_STATES = "franka_robot_state_broadcaster/desired_joint_states"       # sensor_msgs/JointState

# Segmentation node
STIFFNESS_IMAGE = "defgg/stiffness/youngs_modulus_pa"        # 32FC1, Pa per pixel, 0 = background
OBJECT_MASK = "defgg/object_mask"                            # mono8 labels, 0 = background
STIFFNESS_ASSIGNMENTS = "defgg/stiffness_assignments"        # defgg_interfaces/StiffnessAssignment (latched)
SET_STIFFNESS_SERVICE = "defgg/set_stiffness"                # defgg_interfaces/srv/SetStiffness
CAPTURE_BACKGROUND_SERVICE = "defgg/segmentation/capture_background"  # std_srvs/srv/Trigger
PERCEIVED_OBJECTS = "defgg/perceived_objects"                # defgg_interfaces/PerceivedObjects
PERCEIVE_SERVICE = "defgg/perceive"                          # defgg_interfaces/srv/Perceive

# Grasp inference node
BEST_GRASP = "defgg/best_grasp"                              # defgg_interfaces/Grasp
QUALITY_IMAGE = "defgg/quality_image"                        # 32FC1 grasp quality map
GRASP_MARKERS = "defgg/grasp_markers"                        # visualization_msgs/MarkerArray
PLAN_GRASP_SERVICE = "defgg/plan_grasp"                      # defgg_interfaces/srv/PlanGrasp

# Executor node
PICK_AND_PLACE_ACTION = "defgg/pick_and_place"               # defgg_interfaces/action/PickAndPlace
RESET_BIN_SERVICE = "defgg/reset_bin"                         # std_srvs/Trigger: the bin was emptied

# Fake driver only (ground truth of the simulation)
FAKE_SCENE = "fake_panda/scene"                              # std_msgs/String JSON (latched)
FAKE_OBJECT_POSES = "fake_panda/object_poses"                # geometry_msgs/PoseArray
FAKE_CAPTURE_SERVICE = "fake_panda/capture_depth"            # std_srvs/srv/Trigger

# Graph-wide names (absolute on purpose, see above)
CLOCK = "/clock"
TF = "/tf"                                                   # tf2_msgs/TFMessage
TF_STATIC = "/tf_static"                                     # tf2_msgs/TFMessage, latched

# Frames
BASE_FRAME = "fer_link0"                                     # robot_names()["base_frame"]
CAMERA_OPTICAL_FRAME = "camera_depth_optical_frame"          # <camera_name>_depth_optical_frame (realsense_frames.py)
# The frame ids franka_ros2 stamps its state with (docs/franka_contract.md, "Frames"): franka_robot_state_broadcaster's
# topics carry the URDF's root link, franka_description's `base` (connected_to's default), fixed to
# <robot_type>_link0 with the identity; joint_state_broadcaster its frame_id parameter's default; joint_state_publisher
# and franka_gripper set none ("").
FRANKA_STATE_FRAME = "base"
JOINT_STATE_BROADCASTER_FRAME = "base_link"
GRASP_FRAME = "defgg_grasp"                                  # the planned grasp (TCP pose), child of the base


def robot_names(robot_type: str = DEFAULT_ROBOT_TYPE) -> dict:
    """franka_ros2 3.x's names for robot type `robot_type` ("fer" or "fr3"): joints, fingers, base frame,
    the JointTrajectoryController's name, action and topic, and the joint limits the executor plans within.
    ValueError for any other type (Jazzy has no "panda": the Panda is "fer")."""
    if robot_type not in ROBOT_TYPES:
        hint = " (franka_ros2 on Jazzy names the Panda 'fer')" if robot_type == "panda" else ""
        raise ValueError(f"robot_type must be one of {', '.join(ROBOT_TYPES)}{hint}, got {robot_type!r}")
    arm_controller = f"{robot_type}_arm_controller"   # franka_bringup's controllers.yaml
    return {
        "joints": tuple(f"{robot_type}_joint{i}" for i in range(1, 8)),
        "fingers": (f"{robot_type}_finger_joint1", f"{robot_type}_finger_joint2"),
        "base_frame": f"{robot_type}_link0",
        "arm_controller": arm_controller,
        "trajectory_action": f"{arm_controller}/follow_joint_trajectory",
        "trajectory_topic": f"{arm_controller}/joint_trajectory",
        "joint_limits": "panda" if robot_type == "fer" else robot_type,
    }

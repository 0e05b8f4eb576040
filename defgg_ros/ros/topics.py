"""Default ROS names of the cell's interfaces, in one place.

Nodes declare these as parameter defaults so a real cell can remap them.
Camera names follow realsense2_camera (Jazzy: /camera/camera/...), robot
names follow franka_ros2 (joint trajectory controller, gripper actions,
external wrench from the robot state broadcaster).
"""

# Camera (realsense2_camera or the fake driver)
DEPTH_IMAGE = "/camera/camera/depth/image_rect_raw"          # 16UC1 mm or 32FC1 m
DEPTH_CAMERA_INFO = "/camera/camera/depth/camera_info"
COLOR_IMAGE = "/camera/camera/color/image_raw"

# Robot (franka_ros2 or the fake driver)
JOINT_STATES = "/joint_states"
JOINT_TRAJECTORY = "/panda_arm_controller/joint_trajectory"  # trajectory_msgs/JointTrajectory
GRIPPER_MOVE_ACTION = "/panda_gripper/move"                  # defgg_interfaces/action/GripperMove
GRIPPER_GRASP_ACTION = "/panda_gripper/grasp"                # defgg_interfaces/action/GripperGrasp
EXTERNAL_WRENCH = "/franka_robot_state_broadcaster/external_wrench_in_base_frame"  # geometry_msgs/WrenchStamped

# Segmentation node
STIFFNESS_IMAGE = "/defgg/stiffness/youngs_modulus_pa"       # 32FC1, Pa per pixel, 0 = background
OBJECT_MASK = "/defgg/object_mask"                           # mono8 labels, 0 = background
STIFFNESS_ASSIGNMENTS = "/defgg/stiffness_assignments"       # defgg_interfaces/StiffnessAssignment (latched)
SET_STIFFNESS_SERVICE = "/defgg/set_stiffness"               # defgg_interfaces/srv/SetStiffness

# Grasp inference node
BEST_GRASP = "/defgg/best_grasp"                             # defgg_interfaces/Grasp
QUALITY_IMAGE = "/defgg/quality_image"                       # 32FC1 grasp quality map
GRASP_MARKERS = "/defgg/grasp_markers"                       # visualization_msgs/MarkerArray
PLAN_GRASP_SERVICE = "/defgg/plan_grasp"                     # defgg_interfaces/srv/PlanGrasp

# Executor node
PICK_AND_PLACE_ACTION = "/defgg/pick_and_place"              # defgg_interfaces/action/PickAndPlace

# Frames
BASE_FRAME = "panda_link0"
CAMERA_OPTICAL_FRAME = "camera_depth_optical_frame"

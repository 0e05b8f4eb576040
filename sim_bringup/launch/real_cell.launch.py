"""The real cell's three nodes (segmentation, grasp inference, executor) for a Franka FR3 or Panda (fer) under
franka_ros2 3.x and a RealSense under realsense2_camera, started by `ros2 launch` after those drivers:

    ros2 launch defgg_ros real_cell.launch.py robot_type:=fr3

The same nodes with the same parameter files as `defgg-bringup --set real_cell` (robot_type fr3) and
`--set real_cell_fer` (fer): each node's sim_bringup/config/<node>.yaml, then config_file (default
sim_bringup/config/real_cell/<robot_type>.yaml). What the bringup adds and ROS launch has not: it refuses nodes
that disagree on a cell parameter, and warns when a simulated driver shares the domain (docs/real_cell.md).
Kept declarative; test/foundation/test_launch_files.py loads it and checks what it would start.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

CONFIG = PathJoinSubstitution([FindPackageShare("defgg_ros"), "sim_bringup", "config"])
CELL_NODES = ("segmentation_node", "grasp_inference_node", "executor_node")   # node name = console script
CAMERA_READERS = ("segmentation_node", "grasp_inference_node")


def camera_topics(camera_namespace):
    """realsense2_camera publishes the depth stream under <camera_namespace>/<camera_name> (its rs_launch.py)."""
    return {"depth_topic": PathJoinSubstitution([camera_namespace, "depth", "image_rect_raw"]),
            "camera_info_topic": PathJoinSubstitution([camera_namespace, "depth", "camera_info"])}


def cell_node(name, config_file, namespace, camera_namespace):
    # Later entries win: the node's own file, the robot's file, then the camera topics of the launch argument.
    parameters = [PathJoinSubstitution([CONFIG, f"{name}.yaml"]), config_file]
    if name in CAMERA_READERS:
        parameters.append(camera_topics(camera_namespace))
    return Node(package="defgg_ros", executable=name, name=name, namespace=namespace, parameters=parameters,
                output="screen")


def generate_launch_description():
    robot_type = LaunchConfiguration("robot_type")
    arguments = [
        DeclareLaunchArgument("robot_type", default_value="fr3", choices=["fr3", "fer"],
                              description="franka_ros2's robot_type: fr3, or fer (the Panda); the same value as "
                                          "franka.launch.py's"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="ROS namespace of the cell's nodes: franka.launch.py's namespace"),
        DeclareLaunchArgument("camera_namespace", default_value="camera/camera",
                              description="where realsense2_camera publishes, relative to namespace: rs_launch.py's "
                                          "<camera_namespace>/<camera_name> (/camera/camera for a camera started "
                                          "outside the namespace)"),
        DeclareLaunchArgument("config_file",
                              # a path element is one str or substitution on Jazzy: ".yaml" is appended outside
                              default_value=[PathJoinSubstitution([CONFIG, "real_cell", robot_type]), ".yaml"],
                              description="the cell's parameter file, loaded after each node's own "
                                          "(default: sim_bringup/config/real_cell/<robot_type>.yaml)"),
    ]
    nodes = [cell_node(name, LaunchConfiguration("config_file"), LaunchConfiguration("namespace"),
                       LaunchConfiguration("camera_namespace")) for name in CELL_NODES]
    return LaunchDescription(arguments + nodes)

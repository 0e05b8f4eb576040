"""The simulated cell (the PyBullet driver standing in for franka_ros2 and realsense2_camera, and the three cell
nodes, all on the driver's /clock) started by `ros2 launch`:

    ROS_DOMAIN_ID=42 ros2 launch defgg_ros sim_cell.launch.py

The same nodes with the same parameter files and overrides as `defgg-bringup` (node set
sim_bringup/config/sim_cell.yaml). The bringup also picks a free private domain; here the shell's
ROS_DOMAIN_ID is used, and discovery is kept to this host so the simulated arm never answers a real cell's
nodes on the network (docs/real_cell.md). test/foundation/test_launch_files.py checks what it would start.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

CONFIG = PathJoinSubstitution([FindPackageShare("defgg_ros"), "sim_bringup", "config"])
# node name = console script; the set's overrides (sim_cell.yaml)
SIM_NODES = {
    "fake_panda_driver": {},
    "segmentation_node": {"stream_timeout_s": 60.0},      # the simulated camera pauses while the arm moves
    "grasp_inference_node": {"stream_timeout_s": 60.0},
    # the simulated fingers' opening is exact to ~1 um; the hand's calibration (sim_cell.yaml says where from)
    "executor_node": {"squeeze_width_resolution_m": 1.0e-5, "squeeze_hand_stiffness_npm": 13509.0,
                      "squeeze_hand_compliance_sd_mpn": 9.7e-6,
                      "squeeze_hand_calibration": "rigid 5 cm block at yaws 0-0.9 rad, bench_squeeze_stiffness.py "
                                                  "--calibrate, 2026-11-29"},
}


def sim_node(name, overrides, namespace):
    return Node(package="defgg_ros", executable=name, name=name, namespace=namespace,
                parameters=[PathJoinSubstitution([CONFIG, f"{name}.yaml"]), {**overrides, "use_sim_time": True}],
                output="screen")


def generate_launch_description():
    arguments = [
        DeclareLaunchArgument("namespace", default_value="", description="ROS namespace of every node"),
    ]
    localhost_only = SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    nodes = [sim_node(name, overrides, LaunchConfiguration("namespace")) for name, overrides in SIM_NODES.items()]
    return LaunchDescription([*arguments, localhost_only, *nodes])

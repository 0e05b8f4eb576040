"""Stand-in for ROS 2's `launch` package (README.md beside this folder)."""
from launch.launch_description import LaunchDescription

__all__ = ["LaunchDescription"]

"""Stand-in for ROS 2's `launch_ros` package (README.md beside this folder)."""

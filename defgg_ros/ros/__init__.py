"""The ROS plumbing shared by nodes, bringup, sessions and benches (rclpy helpers, names, parameters).

Cores (model, grasping, perception, control, sim, data) never import this package."""

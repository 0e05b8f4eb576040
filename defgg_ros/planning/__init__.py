"""Grasp planning on a real tabletop: perception (table, workspace, objects, self-filter), the network and
the feasibility of each grasp put together. Above the cores it combines (grasping, control, perception,
model); no rclpy here. docs/perception.md."""

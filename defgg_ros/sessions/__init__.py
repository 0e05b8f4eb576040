"""Recorded sessions: record the cell into rosbag2/MCAP bags and replay them against the simulated cell.

Pure (no rclpy): interfaces (typestore with defgg_interfaces), bag (SessionWriter/read_bag),
session (the timeline of a bag), selector (which frames a recording keeps), compare + report
(tolerances, diff table, verdict), metadata, scene_stiffness, replay_graph (which nodes a replay runs).
ROS adapters: recorder_node, client, player, params, graph (child processes).
CLIs: record.py (`defgg-record`), replay.py (`defgg-replay`). See docs/sessions.md.
"""

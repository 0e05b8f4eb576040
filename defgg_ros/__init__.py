"""defgg_ros: stiffness-aware grasp synthesis for a Franka Panda cell."""

"""The ROS 2 shell: the rclpy node, its managed variant, parameters, QoS, optional TF."""

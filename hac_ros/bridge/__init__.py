"""Between ROS messages and the core: inputs into the Calibrator, its outputs as messages."""

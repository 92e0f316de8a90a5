"""``hac_people_node``'s own command line: its ``--help`` (the ROS arguments are ROS's; the
process itself is :func:`hac_ros.ros.arguments.run`'s)."""
from __future__ import annotations

USAGE = """\
usage: {program} [-h] [--ros-args [--params-file FILE] [-p NAME:=VALUE] [-r FROM:=TO] ...]

{what}

Subscribes to camera/image_raw (sensor_msgs/Image; camera/image_raw/compressed with
-p image_transport:=compressed) and camera/camera_info; publishes hmr/joints (PoseArray: 33
landmarks per person in metres, camera optical frame; hac_node takes them with
joint_layout: blazepose33) and /diagnostics. Needs the [people] extra ({install}).

options:
  -h, --help            show this help and exit (ROS is not started)
  --ros-args ...        ROS's own arguments, e.g. -p max_rate_hz:=5.0

Parameters: docs/people.md ("Parameters").
"""

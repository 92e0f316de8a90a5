"""``hac_node``'s own command line: ``--help``, and the parameters files among the ROS arguments.

Everything after ``--ros-args`` (until a lone ``--``) is ROS's (``--params-file FILE``,
``-p name:=value``, ``-r from:=to``); before it, ``hac_node`` takes only ``-h``/``--help``, which
prints :data:`USAGE` without starting ROS.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from hac_ros.core.params import NODE_NAME

ROS_ARGS, ROS_ARGS_END, PARAMS_FILE = '--ros-args', '--', '--params-file'
HELP = ('-h', '--help')

USAGE = """\
usage: {program} [-h] [--ros-args [--params-file FILE] [-p NAME:=VALUE] [-r FROM:=TO] ...]

{what}

Subscribes to slam/pose (PoseStamped or Odometry: the camera in the SLAM map, unknown scale),
slam/cloud (PointCloud2 map), hmr/joints (PoseArray: joints in metres, camera optical frame) and
camera/camera_info; publishes hac/odometry, hac/pose, hac/cloud, hac/human_joints, hac/scale,
hac/markers and /diagnostics; services ~/reset and ~/freeze. Names are relative: a namespace
(-r __ns:=/robot1) moves them all.

options:
  -h, --help            show this help and exit (ROS is not started)
  --ros-args ...        ROS's own arguments, e.g.
                          --params-file FILE   a parameters file ({node}: ros__parameters: ...)
                          -p window_s:=20.0    one parameter

Parameters: every one, with its default, range and what a change at runtime does, in
docs/node.md ("Parameters at runtime"; `python -m hac_ros.ros.parameters` prints the table); a
file with all of them at their defaults is config/hac.yaml (installed as
share/hac_ros/config/hac.yaml); how a parameters file is read (shared files, namespaces,
wildcards): docs/interface.md ("Parameters"). Unknown names and sections that look misspelt are
warned about at start-up.
"""


class NodeClass(Protocol):
    """HacNode or HacLifecycleNode: the command's name, its one-line summary, the constructor."""

    PROGRAM: str
    SUMMARY: str

    def __call__(self, *, params_files: Sequence[str]) -> Any: ...


def usage(node_class: NodeClass) -> str:
    """The ``--help`` text of ``node_class``'s command."""
    return USAGE.format(program=node_class.PROGRAM, what=node_class.SUMMARY, node=NODE_NAME)


def wants_help(argv: Sequence[str]) -> bool:
    """``-h`` or ``--help`` among the node's own arguments (those before ``--ros-args``)."""
    own = list(argv)
    if ROS_ARGS in own:
        own = own[:own.index(ROS_ARGS)]
    return any(arg in HELP for arg in own)


def params_files(argv: Sequence[str]) -> list[str]:
    """The ``--params-file`` paths of every ``--ros-args`` block, in order."""
    files: list[str] = []
    inside = False
    args = iter(argv)
    for arg in args:
        if arg == ROS_ARGS:
            inside = True
        elif arg == ROS_ARGS_END:
            inside = False
        elif inside and arg == PARAMS_FILE:
            path = next(args, None)
            if path is not None:
                files.append(path)
    return files

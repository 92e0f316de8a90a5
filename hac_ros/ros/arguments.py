"""``hac_node``'s own command line: ``--help``, and the parameters files among the ROS arguments.

Everything after ``--ros-args`` (until a lone ``--``) is ROS's (``--params-file FILE``,
``-p name:=value``, ``-r from:=to``); before it, ``hac_node`` takes only ``-h``/``--help``, which
prints :data:`USAGE` without starting ROS. :func:`run` is the process of ``hac_node`` and
``hac_lifecycle_node``: init, spin, a clean shutdown on a signal.
"""
from __future__ import annotations

import gc
import re
import signal
import sys
import textwrap
from collections.abc import Sequence
from typing import Any, Protocol

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterException,
)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from hac_ros.bridge.topics import names_line
from hac_ros.core.basics.errors import HacError, ParameterError
from hac_ros.core.basics.printable import printable
from hac_ros.core.rules.params import NODE_NAME
from hac_ros.files.params_file import check_params_file

ROS_ARGS, ROS_ARGS_END, PARAMS_FILE = '--ros-args', '--', '--params-file'
HELP = ('-h', '--help')
TOPICS_TEXT = textwrap.fill(
    'Subscribes to slam/pose (PoseStamped or Odometry: the camera in the SLAM map, unknown '
    'scale), slam/cloud (PointCloud2 map), hmr/joints (PoseArray: joints in metres, camera '
    f'optical frame) and camera/camera_info; publishes {names_line()}; services ~/reset and '
    '~/freeze. Names are relative: a namespace (-r __ns:=/robot1) moves them all.', 99)

USAGE = """\
usage: {program} [-h] [--ros-args [--params-file FILE] [-p NAME:=VALUE] [-r FROM:=TO] ...]

{what}

{topics}

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
    """The ``--help`` text of ``node_class``'s command (its own ``USAGE`` template when it has
    one: ``hac_people_node``)."""
    template = getattr(node_class, 'USAGE', USAGE)
    return template.format(program=node_class.PROGRAM, what=node_class.SUMMARY, node=NODE_NAME,
                           install=getattr(node_class, 'INSTALL', ''), topics=TOPICS_TEXT)


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


def refused_params_file(argv: Sequence[str]) -> str:
    """One line naming the first ``--params-file`` that rcl would refuse, its line and what is
    wrong (:func:`hac_ros.files.params_file.check_params_file`), or '' when all are good."""
    for path in params_files(argv):
        try:
            check_params_file(path)
        except ParameterError as exc:
            return printable(exc)
    return ''


def rcl_reason(exc: Exception) -> str:
    """rcl's error, one line without its source locations (``, at /project/src/...``)."""
    text = ' '.join(str(exc).split())
    return printable(re.sub(r',? at /\S+:\d+', '', text))


# SIGINT and SIGTERM are Python's here, not rclpy's: rclpy's (Jazzy) signal thread triggers the
# executor's guard condition while the main thread may already be destroying it (a segfault at
# shutdown, about once in 30 SIGINTs, core dump in rcl_trigger_guard_condition), and its wake-up
# could be seen before the context's shutdown, leaving executor.spin() waiting forever. A Python
# handler only sets a flag; the loop sees it within this long.
SHUTDOWN_POLL_S = 0.5


def run(node_class: NodeClass, args: list[str] | None = None) -> int:
    """init → spin ``node_class()`` → clean shutdown on SIGINT, SIGTERM or SIGHUP (exit code 0);
    2 on invalid parameters (a parameters file rcl would refuse is said in one line before ROS
    starts: its file, line and what is wrong); ``-h``/``--help`` prints the usage
    (:mod:`hac_ros.ros.arguments`) and exits 0 without starting ROS.

    The signals set a flag (see SHUTDOWN_POLL_S): one during start-up ends the loop before it
    spins, and everything made so far is destroyed in order.
    """
    argv = sys.argv if args is None else args
    if wants_help(argv):
        print(usage(node_class))
        return 0
    refused = refused_params_file(argv)
    if refused:  # rcl parses the files in rclpy.init and would end with a traceback
        print(f'{node_class.PROGRAM}: {refused}', file=sys.stderr)
        return 2
    stop: list[int] = []
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, lambda number, _frame: stop.append(number))
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:  # what rcl refuses that the check above let through
        print(f'{node_class.PROGRAM}: ROS refused its arguments: {rcl_reason(exc)}',
              file=sys.stderr)
        return 2
    executor = SingleThreadedExecutor()
    node = None
    try:
        node = node_class(params_files=params_files(argv))
        # the objects made so far (modules, message types, serializers: ~85k) are left out of
        # the garbage collector's full collections, which otherwise stalled the node 70 ms
        # about every 15 s at 1 kHz of poses (docs/node.md, "Performance")
        gc.freeze()
        executor.add_node(node)
        while rclpy.ok() and not stop:  # not executor.spin(): see SHUTDOWN_POLL_S
            executor.spin_once(timeout_sec=SHUTDOWN_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ParameterError, InvalidParameterValueException, InvalidParameterTypeException,
            ParameterException) as exc:
        print(f'{node_class.PROGRAM}: invalid parameter: {exc}', file=sys.stderr)
        return 2
    except HacError as exc:  # a node that cannot start with what is installed (a model missing)
        print(f'{node_class.PROGRAM}: {exc}', file=sys.stderr)
        return 2
    finally:
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0

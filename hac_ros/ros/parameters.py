"""The node's parameters as ROS sees them: descriptors, what a runtime change does, the docs table.

The values, defaults, ranges and validation are :class:`hac_ros.core.rules.params.HacParams`'; this
module adds what only the ROS node needs: a ``ParameterDescriptor`` per field (type, range,
choices, the runtime note), which parameters re-subscribe or rebuild the estimator when changed at
runtime, how a node declares them, what it warns about at start-up, and the markdown table of
docs/node.md (``python -m hac_ros.ros.parameters`` prints it). Importing it needs no ROS; the
functions that take a node import rclpy when called.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from hac_ros.bridge.topics import INPUTS, InputKind
from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.basics.param_fields import lengths_text
from hac_ros.core.rules.params import HacParams, describe, names
from hac_ros.files.params_file import (
    ROS_OWN_PARAMETERS,
    ROS_OWN_PREFIXES,
    read_params_file,
    unknown_names,
)

# ROS types `window_s: 30` (YAML, `ros2 param set`) as an integer and would refuse it for a double;
# dynamic typing lets it through, and HacParams converts integers and rejects anything else
# (also the range, which ROS checks only for double values).
INTEGERS_FOR_DOUBLES = True

# What a runtime change does (docs/node.md, "Parameters at runtime"):
# - these re-create the named subscriptions (topics and QoS cannot change on a live subscription);
POSE, JOINTS, CAMERA_INFO, CLOUD = (InputKind.POSE, InputKind.JOINTS, InputKind.CAMERA_INFO,
                                    InputKind.CLOUD)
RESUBSCRIBE: dict[str, tuple[str, ...]] = {
    **{each.topic_param: (each.kind,) for each in INPUTS},
    'pose_type': (POSE,), 'pose_source': (POSE,), 'slam_map_frame': (POSE,),
    'slam_pose_frame': (POSE,), 'cloud_qos': (CLOUD,), 'input_qos': (POSE, JOINTS, CAMERA_INFO),
}
# - these only change what the shell publishes (the calibrator does not read them);
SHELL_ONLY = frozenset({'metric_frame', 'odom_frame', 'publish_markers', 'publish_tf',
                        'publish_odom_tf', 'publish_obstacles', 'obstacle_min_height',
                        'obstacle_max_height', 'joints_backlog_max', 'latency_warn_s',
                        'stale_after_s', 'pose_coalesce_s', 'log_period_s', 'autostart'})
TF_PARAMETERS = frozenset({'metric_frame', 'odom_frame', 'publish_tf', 'publish_odom_tf'})
# - every other parameter is an estimator parameter: the calibrator is rebuilt with the new values
#   (its estimate restarts; the current map and CameraInfo are handed to the new one).
# - and these are read once, when the node starts.
AT_START = frozenset({'autostart'})
RUNTIME_NOTE = {**{name: 're-subscribes' for name in RESUBSCRIBE},
                **{name: 'takes effect at once' for name in SHELL_ONLY},
                **{name: 'read at start-up only' for name in AT_START}}
ESTIMATOR_NOTE = 'rebuilds the estimator (estimate restarts)'


def runtime_effect(name: str) -> str:
    """What changing parameter ``name`` at runtime does (for descriptors and docs)."""
    return RUNTIME_NOTE.get(name, ESTIMATOR_NOTE)


@dataclass
class Change:
    """A runtime change of the node's parameters, judged (docs/node.md, "Parameters at runtime").

    params: the new values; changed: the names whose value differs; resubscribe: the input kinds
    whose subscription must be re-created; tf: whether the TF senders must be remade; estimator:
    the estimator parameters among them (non-empty: the calibrator is rebuilt).
    """

    params: HacParams
    changed: frozenset[str]
    resubscribe: list[str]
    tf: bool
    estimator: list[str]


def our_values(parameters: Sequence[Any]) -> dict[str, Any]:
    """name -> value of the rclpy Parameters that are the node's (HacParams fields)."""
    ours = set(names())
    return {p.name: p.value for p in parameters if p.name in ours}


def judge_change(params: HacParams, values: dict[str, Any]) -> Change:
    """What setting ``values`` over ``params`` does (ParameterError naming a bad value)."""
    new = params.replace(**values)
    changed = frozenset(k for k in values if getattr(new, k) != getattr(params, k))
    return Change(new, changed,
                  sorted({kind for name in changed for kind in RESUBSCRIBE.get(name, ())}),
                  bool(changed & TF_PARAMETERS), sorted(changed - SHELL_ONLY - set(RESUBSCRIBE)))


def parameter_descriptor(name: str) -> Any:
    """The rcl_interfaces ParameterDescriptor of one HacParams field: type, description (with
    what changing it at runtime does), range or choices."""
    info = describe(name)
    return descriptor_of(info, f"{info['description']} [at runtime: {runtime_effect(name)}]")


def descriptor_of(info: dict[str, Any], description: str, read_only: bool = False) -> Any:
    """The rcl_interfaces ParameterDescriptor of a parameter field described by ``info`` (a
    ParamSet's ``describe``: HacParams', PeopleParams'): its type, range or choices."""
    from rcl_interfaces.msg import (
        FloatingPointRange,
        IntegerRange,
        ParameterDescriptor,
        ParameterType,
    )

    default = info['default']
    descriptor = ParameterDescriptor(name=info['name'], description=description,
                                     read_only=read_only)
    if isinstance(default, bool):
        descriptor.type = ParameterType.PARAMETER_BOOL
    elif isinstance(default, int):
        descriptor.type = ParameterType.PARAMETER_INTEGER
        if info['low'] is not None and info['high'] is not None:
            descriptor.integer_range = [IntegerRange(from_value=int(info['low']),
                                                     to_value=int(info['high']), step=1)]
    elif isinstance(default, float):
        descriptor.type = ParameterType.PARAMETER_DOUBLE
        descriptor.dynamic_typing = INTEGERS_FOR_DOUBLES
        if info['low'] is not None and info['high'] is not None:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(info['low']), to_value=float(info['high']), step=0.0)]
    elif info['kind'] == 'indices':
        descriptor.type = ParameterType.PARAMETER_INTEGER_ARRAY
        descriptor.additional_constraints = 'joint indices (integers >= 0)'
    elif isinstance(default, list):
        descriptor.type = ParameterType.PARAMETER_DOUBLE_ARRAY
        descriptor.dynamic_typing = INTEGERS_FOR_DOUBLES
        descriptor.additional_constraints = f"{lengths_text(info['length'])} finite numbers"
    else:
        descriptor.type = ParameterType.PARAMETER_STRING
    if info['choices']:
        descriptor.additional_constraints = 'one of: ' + ', '.join(info['choices'])
    return descriptor


def declare_parameters(node: Any) -> None:
    """Declare every HacParams field on the rclpy ``node`` with its default and descriptor. The
    empty joint-index lists (joint_layout custom) are declared as integer arrays: rclpy would
    declare ``[]`` as a byte array and then refuse the integers of a parameters file."""
    from rclpy.parameter import Parameter

    for name in names():
        info = describe(name)
        if info['default'] == [] and info['kind'] == 'indices':
            declared = node.declare_parameter(name, Parameter.Type.INTEGER_ARRAY,
                                              parameter_descriptor(name))
            if declared.value is None:  # not overridden: set [] with its type
                node.set_parameters([Parameter(name, Parameter.Type.INTEGER_ARRAY, [])])
            continue
        node.declare_parameter(name, info['default'], parameter_descriptor(name))


def unknown_overrides(node: Any) -> list[str]:
    """The names overridden at start-up (a parameters file, ``-p`` on the ROS command line) that
    no parameter of the node has: misspelt, ROS would ignore them silently."""
    overrides = getattr(node, '_parameter_overrides', {})  # rclpy keeps them on the node
    return sorted(name for name in overrides if name not in names()
                  and name not in ROS_OWN_PARAMETERS and not name.startswith(ROS_OWN_PREFIXES))


def startup_warnings(node: Any, params_files: Sequence[str]) -> list[str]:
    """What the node warns about at start-up, one line each: parameters it does not have (with
    the closest valid name), and in each parameters file it was given, sections a few edits from
    its name and a file with no section for it (:mod:`hac_ros.files.params_file`, read for the
    node's own name and namespace). ROS applies the values itself; nothing here stops the node."""
    warnings = []
    unknown = unknown_overrides(node)
    if unknown:
        warnings.append(f'{unknown_names(unknown)} ignored (the parameters: docs/node.md, '
                        'config/hac.yaml)')
    for path in params_files:
        try:
            read = read_params_file(path, node.get_name(), node.get_namespace())
        except ParameterError as exc:
            warnings.append(str(exc))
            continue
        warnings += read.section_problems()
    return warnings


def parameter_table() -> str:
    """The README-style markdown table of every parameter (docs/node.md holds exactly this)."""
    def shown(value: Any) -> str:
        if isinstance(value, bool):
            return '`true`' if value else '`false`'
        if isinstance(value, list):
            return '`[' + ', '.join(f'{v:g}' for v in value) + ']`'  # [] for the index lists
        return '`""`' if value == '' else f'`{value}`'

    rows = ['| name | default | allowed | at runtime | meaning |', '|---|---|---|---|---|']
    for name in names():
        info = describe(name)
        if info['choices']:
            allowed = ', '.join(f'`{c}`' for c in info['choices'])
        elif info['low'] is not None:
            allowed = f"{info['low']:g} … {info['high']:g}"
        elif info['kind'] == 'indices':
            allowed = 'joint indices'
        elif info['length']:
            allowed = f"{lengths_text(info['length'])} numbers"
        elif isinstance(info['default'], bool):
            allowed = '`true`, `false`'
        else:
            allowed = 'a string'
        meaning = info['description'].replace('|', '/')
        rows.append(f"| `{name}` | {shown(info['default'])} | {allowed} | {runtime_effect(name)} "
                    f"| {meaning} |")
    return '\n'.join(rows)


# the config's sections: the first parameter of each, and its heading
CONFIG_SECTIONS = {
    'pose_topic': 'Inputs (docs/interface.md, "Topics")',
    'contact_mode': 'Method (docs/method.md)',
    'joint_layout': "The HMR model's joints (docs/inputs.md)",
    'window_s': 'Estimator: rolling window of per-frame scales',
    'sync_slop_s': 'Synchronisation of joints and SLAM poses',
    'cloud_mode': 'Map',
    'input_qos': 'QoS and outputs (node only)',
    'interp_max_gap_s': 'Tuning (metric or scene-relative units)',
}
# examples shown for the custom layout's index lists (a ROS parameters file cannot hold [])
INDEX_EXAMPLES = {'contact_joints': [15, 16], 'root_joints': [11, 12],
                  'body_axis_lower_joints': [11, 12], 'body_axis_upper_joints': [5, 6],
                  'skeleton_edges': [11, 13, 13, 15]}


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return '[' + ', '.join(_yaml_value(v) for v in value) + ']'
    return repr(value)


def _config_comment(info: dict[str, Any]) -> str:
    comment = info['description']
    if info['choices']:
        comment += ' (' + ' | '.join(info['choices']) + ')'
    elif info['low'] is not None:
        comment += f" [{info['low']!r}, {info['high']!r}]"
    return comment


def config_parameters() -> str:
    """The parameters of config/hac.yaml (the lines under ``ros__parameters:``): every one at
    its default, with its description, choices or range as a comment, in sections; the custom
    layout's index lists as comments."""
    lines, indices = [], [n for n in names() if describe(n)['kind'] == 'indices']
    for name in names():
        if name in CONFIG_SECTIONS:
            lines.append(f'    # --- {CONFIG_SECTIONS[name]}')
        info = describe(name)
        if name in indices:
            if name == indices[0]:
                lines += ['    # joint_layout custom also needs these index lists (ROS parameter '
                          'files cannot hold an',
                          '    # empty list, so they are left out here; a list of several '
                          'indices means their mean):']
            lines.append(f'    # {name}: {_yaml_value(INDEX_EXAMPLES[name])}  # '
                         f"{_config_comment(info)}")
            continue
        lines.append(f"    {name}: {_yaml_value(info['default'])}  # {_config_comment(info)}")
    return '\n'.join(lines) + '\n'


if __name__ == '__main__':
    print(parameter_table())

"""One parameters file for the node and every command, read as ROS 2 reads it
(:mod:`hac_ros.files.params_file`); the node's side over a real node is in test_node_process.py."""
from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest

from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.rules.params import HacParams
from hac_ros.files.params_file import load_params, read_params_file

REPO = Path(__file__).resolve().parents[1]

# A file shared by a robot's nodes, as a launch file would pass it to every one of them
SHARED = """\
/**:
  ros__parameters:
    use_sim_time: true
    window_s: 10.0
slam_node:
  ros__parameters:
    vocabulary: orb.txt
    window_s: 99.0
hac_node:
  ros__parameters:
    min_samples: 4
    qos_overrides:
      /hac/pose:
        publisher:
          depth: 5
/**/hac_node:
  ros__parameters:
    contact_mode: feet
"""


def write(tmp_path: Path, text: str, name: str = 'params.yaml') -> Path:
    path = tmp_path / name
    path.write_text(text, encoding='utf-8')
    return path


def test_a_shared_file_gives_the_node_its_sections_in_file_order(tmp_path):
    read = read_params_file(write(tmp_path, SHARED))
    assert read.node == '/hac_node' and read.sections == ['/**', 'hac_node', '/**/hac_node']
    assert read.values == {'window_s': 10.0, 'min_samples': 4, 'contact_mode': 'feet'}
    assert read.ros_own == {'use_sim_time': True, 'qos_overrides./hac/pose.publisher.depth': 5}
    assert read.unknown == [] and read.near_misses == [] and read.section_problems() == []
    params = load_params(read.path)
    assert (params.window_s, params.min_samples, params.contact_mode) == (10.0, 4, 'feet')


def test_a_later_section_wins_as_in_rclpy(tmp_path):
    text = 'hac_node:\n  ros__parameters:\n    min_samples: 4\n' \
           '/**:\n  ros__parameters:\n    min_samples: 7\n'
    assert load_params(write(tmp_path, text)).min_samples == 7


@pytest.mark.parametrize('text', [
    '/robot1/hac_node:\n  ros__parameters:\n    min_samples: 4\n',
    'robot1/hac_node:\n  ros__parameters:\n    min_samples: 4\n',
    'robot1:\n  hac_node:\n    ros__parameters:\n      min_samples: 4\n',
    '/*/hac_node:\n  ros__parameters:\n    min_samples: 4\n/robot1/hac_node:\n  ros__parameters:\n'
    '    window_s: 5.0\n',
])
def test_namespaced_sections(tmp_path, text):
    """A namespaced node's section, written any way rcl reads it, serves the replay (which has no
    namespace) when the file names one namespace; the node reads it for its own namespace."""
    path = write(tmp_path, text)
    assert load_params(path).min_samples == 4
    assert read_params_file(path, namespace='/robot1').values['min_samples'] == 4
    assert read_params_file(path, namespace='/').sections == []


def test_sections_in_two_namespaces_are_ambiguous_for_the_replay(tmp_path):
    path = write(tmp_path, '/a/hac_node:\n  ros__parameters:\n    min_samples: 4\n'
                           '/b/hac_node:\n  ros__parameters:\n    min_samples: 5\n')
    with pytest.raises(ParameterError, match='namespaces /a, /b'):
        load_params(path)
    assert read_params_file(path, namespace='/b').values == {'min_samples': 5}


def test_a_misspelt_parameter_names_the_closest_one_and_the_replay_refuses_it(tmp_path):
    path = write(tmp_path, 'hac_node:\n  ros__parameters:\n    window_sec: 10.0\n'
                           '    contact_mod: feet\n')
    assert read_params_file(path).unknown == ['window_sec', 'contact_mod']
    with pytest.raises(ParameterError, match=r"unknown parameters 'window_sec' \(did you mean "
                       r"'window_s'\?\), 'contact_mod' \(did you mean 'contact_mode'\?\)"):
        load_params(path)


def test_a_misspelt_node_name_is_warned_about_not_ignored(tmp_path, caplog):
    path = write(tmp_path, '/**:\n  ros__parameters:\n    use_sim_time: true\n'
                           'hac_nod:\n  ros__parameters:\n    min_samples: 4\n'
                           'hac_node2:\n  ros__parameters:\n    min_samples: 5\n'
                           'slam_node:\n  ros__parameters:\n    min_samples: 6\n')
    read = read_params_file(path)
    assert read.near_misses == ['hac_nod', 'hac_node2'] and read.values == {}
    with caplog.at_level(logging.WARNING, logger='hac_ros'):
        assert load_params(path) == HacParams()
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 2 and "section 'hac_nod' is not /hac_node's" in warned[0]


def test_a_file_with_no_section_for_the_node_says_so(tmp_path, caplog):
    path = write(tmp_path, 'slam_node:\n  ros__parameters:\n    vocabulary: orb.txt\n')
    with caplog.at_level(logging.WARNING, logger='hac_ros'):
        assert load_params(path) == HacParams()
    assert [r.getMessage() for r in caplog.records] == [
        f'{path} has no section for /hac_node (a "hac_node: {{ros__parameters: ...}}" or "/**:" '
        'one): the defaults are used']


@pytest.mark.parametrize('text, reason', [
    ('window_s: 10.0\n', 'holds 10.0, not "ros__parameters:"'),  # flat: rcl refuses it too
    ('hac_node:\n  window_s: 10.0\n', 'holds 10.0'),
    ('hac_node:\n  ros__parameters: 3\n', 'a mapping under it'),
    ('- a\n- b\n', 'expected node names at the top'),
    ('hac_node: [\n', 'not valid YAML'),
    ('hac_node:\n  ros__parameters:\n    window_s: -3.0\n', 'window_s'),
])
def test_what_is_not_a_parameters_file_is_an_error(tmp_path, text, reason):
    with pytest.raises(ParameterError, match=reason.replace('(', r'\(').replace('"', '"')):
        load_params(write(tmp_path, text))


def test_the_replay_says_the_file_problems_on_the_terminal(tmp_path):
    from hac_ros.simulate import make_scenario, write_recording

    source = write_recording(make_scenario('walk', seed=1, duration=3.0), tmp_path / 'in')
    typo = write(tmp_path, 'hac_nod:\n  ros__parameters:\n    min_samples: 4\n', 'typo.yaml')
    result = subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'replay', str(source), '-o',
                             str(tmp_path / 'out'), '--params', str(typo)], cwd=REPO, text=True,
                            capture_output=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert f"hac replay: warning: {typo}: section 'hac_nod' is not /hac_node's" in result.stderr
    misspelt = write(tmp_path, 'hac_node:\n  ros__parameters:\n    min_sample: 4\n', 'bad.yaml')
    result = subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'replay', str(source), '-o',
                             str(tmp_path / 'out2'), '--params', str(misspelt)], cwd=REPO,
                            text=True, capture_output=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr == (f"hac replay: error: {misspelt}: unknown parameter 'min_sample' "
                             "(did you mean 'min_samples'?)\n")


@pytest.mark.parametrize('module, command', [('hac_ros.ros.node', 'hac_node'),
                                             ('hac_ros.ros.lifecycle_node', 'hac_lifecycle_node')])
@pytest.mark.parametrize('flag', ['--help', '-h'])
def test_hac_node_help_prints_usage_without_starting_ros(module, command, flag):
    """A parameters file that does not exist follows: ROS, started, would refuse it."""
    result = subprocess.run([sys.executable, '-m', module, flag, '--ros-args', '--params-file',
                             '/nonexistent.yaml'], cwd=REPO, text=True, capture_output=True,
                            timeout=60)
    assert result.returncode == 0 and result.stderr == '', result.stderr
    assert result.stdout.startswith(f'usage: {command} [-h] [--ros-args')
    for needed in ('--params-file FILE', 'docs/node.md', 'config/hac.yaml'):
        assert needed in result.stdout

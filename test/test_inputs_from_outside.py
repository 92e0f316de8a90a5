"""Whatever a file or a recording holds, every command answers in one line (issue 35, items 7, 8).

No traceback for any input file in any command: bytes that are not UTF-8, a YAML alias cycle,
binary junk, a directory, malformed YAML (said with its line and column), nesting too deep; exit 2
and one line naming the file. ``hac_node`` checks its parameters files before ``rclpy.init`` (rcl
parses them there) and says the same line. Every string from a recording or a file (topic and
type names, frame ids, paths) reaches the terminal and the logs escaped: no ESC, BEL or CR is ever
written raw.
"""
from __future__ import annotations

import copy
import random
import subprocess
import sys
from pathlib import Path

import pytest
from injected import CLOUD, JOINTS, POSE, rewrite, simulate

from hac_ros.cli import main

REPO = Path(__file__).resolve().parents[1]
# Each a file's bytes (None: a directory); with what the one line must say
BAD_FILES: dict[str, tuple[bytes | None, str]] = {
    'not_utf8': (b'hac_node:\n  ros__parameters:\n    window_s: 20.0  # caf\xe9\n',
                 'line 3, column 26: not UTF-8'),
    'alias_cycle': (b'hac_node: &n\n  ros__parameters: *n\n', 'line 2, column 20: the alias *n'),
    'self_list': (b'a: &a [*a]\n', 'line 1, column 8: the alias *a'),
    'junk': (random.Random(35).randbytes(4096), 'not UTF-8'),
    'malformed': (b'hac_node:\n  ros__parameters:\n    window_s: [1, 2\n',
                  "line 4, column 1: not valid YAML: did not find expected ',' or ']'"),
    'tab': (b'hac_node:\n\tros__parameters: {}\n', 'line 2, column 1: not valid YAML'),
    'nul': (b'hac_node:\n  ros__parameters:\n    window_s: 1\x00\n',
            "line 3, column 16: not valid YAML: the character '\\x00'"),
    'deep': (b'a: ' + b'[' * 5000 + b']' * 5000 + b'\n', 'not valid YAML'),
    'directory': (None, 'is a directory'),
}
# what a terminal obeys: clear the screen, ring, retitle the window, overwrite the line
HOSTILE = '\x1b[2J\x07\x1b]0;owned\x07\r'


def bad_file(directory: Path, kind: str) -> Path:
    path = directory / f'{kind}.yaml'
    content = BAD_FILES[kind][0]
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    return path


def hac(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', *argv], cwd=REPO, text=True,
                          capture_output=True, timeout=300)


def one_line_error(code: int, err: str, command: str, code_wanted: int = 2) -> str:
    """The one error line of a command's stderr (asserted: exit code, no traceback)."""
    assert code == code_wanted, err
    assert 'Traceback' not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'{command}: '), err
    return lines[0]


@pytest.fixture(scope='module')
def walk(tmp_path_factory) -> Path:
    return simulate(tmp_path_factory.mktemp('walk') / 'walk', 'walk', seed=2, duration=4.0)


# ============================================================================ parameters files
@pytest.mark.parametrize('command', ['replay', 'batch', 'eval', 'demo'])
@pytest.mark.parametrize('kind', sorted(BAD_FILES))
def test_a_bad_parameters_file_is_one_line_in_every_command(walk, tmp_path, capsys, command,
                                                            kind):
    params = bad_file(tmp_path, kind)
    argv = {'replay': ['replay', str(walk), '-o', str(tmp_path / 'out')],
            'batch': ['batch', str(walk), '-o', str(tmp_path / 'out')],
            'eval': ['eval', str(walk), '--gt', str(walk)],
            'demo': ['demo', '--live', '--recording', str(walk)]}[command]
    code = main([*argv, '--params', str(params)])
    line = one_line_error(code, capsys.readouterr().err, f'hac {command}')
    assert f'parameters file {params}' in line and BAD_FILES[kind][1] in line, line
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('module', ['hac_ros.ros.node', 'hac_ros.ros.lifecycle_node'])
@pytest.mark.parametrize('kind', ['not_utf8', 'alias_cycle', 'malformed', 'directory'])
def test_hac_node_says_what_is_wrong_with_its_parameters_file_before_ros_starts(tmp_path, module,
                                                                                kind):
    params = bad_file(tmp_path, kind)
    result = subprocess.run([sys.executable, '-m', module, '--ros-args', '--params-file',
                             str(params)], cwd=REPO, text=True, capture_output=True, timeout=60)
    program = module.rsplit('.', 1)[1].replace('lifecycle_node', 'hac_lifecycle_node')
    program = 'hac_node' if program == 'node' else program
    line = one_line_error(result.returncode, result.stderr, program)
    assert f'parameters file {params}' in line and BAD_FILES[kind][1] in line, line


def test_what_rcl_alone_refuses_is_one_line_too(tmp_path):
    """A list of mixed types is a YAML the check above lets through (another node's section may
    hold anything YAML can): rcl refuses it in rclpy.init, and hac_node says rcl's reason in one
    line, its source locations left out."""
    params = tmp_path / 'mixed.yaml'
    params.write_text('slam_node:\n  ros__parameters:\n    x: [1, a]\n', encoding='utf-8')
    result = subprocess.run([sys.executable, '-m', 'hac_ros.ros.node', '--ros-args',
                             '--params-file', str(params)], cwd=REPO, text=True,
                            capture_output=True, timeout=60)
    assert result.returncode == 2 and 'Traceback' not in result.stderr, result.stderr
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith('hac_node: ROS refused its arguments: ') and 'line_num 3' in line, line
    assert '/project/src' not in line


# ============================================================================ recordings, files
def _bad_recordings(directory: Path) -> dict[str, Path]:
    """A rosbag2 directory whose metadata.yaml is each bad file, bare storage files of junk."""
    directory.mkdir(parents=True, exist_ok=True)
    out = {}
    for kind in ('not_utf8', 'alias_cycle', 'junk', 'malformed', 'deep'):
        recording = directory / f'rec_{kind}'
        recording.mkdir()
        (recording / 'metadata.yaml').write_bytes(BAD_FILES[kind][0] or b'')
        out[kind] = recording
    for suffix in ('mcap', 'db3', 'bag'):
        junk = directory / f'junk_{suffix}.{suffix}'
        junk.write_bytes(BAD_FILES['junk'][0] or b'')
        out[f'junk {suffix}'] = junk
    out['empty directory'] = directory / 'empty'
    out['empty directory'].mkdir()
    return out


@pytest.mark.parametrize('command', ['replay', 'eval', 'eval --gt', 'plot', 'export', 'demo',
                                     'recover'])
def test_a_bad_recording_is_one_line_in_every_command(walk, tmp_path, capsys, command):
    for name, recording in _bad_recordings(tmp_path / 'in').items():
        out = tmp_path / 'out' / name.replace(' ', '_')
        argv = {'replay': ['replay', str(recording), '-o', str(out)],
                'eval': ['eval', str(recording), '--gt', str(walk), '--no-references'],
                'eval --gt': ['eval', str(walk), '--gt', str(recording), '--no-references'],
                'plot': ['plot', str(recording), '-o', str(out)],
                'export': ['export', str(recording), '-o', str(out) + '.npz'],
                'demo': ['demo', '--recording', str(recording), '-o', str(out)],
                'recover': ['recover', str(recording), '-o', str(out)]}[command]
        line = one_line_error(main(argv), capsys.readouterr().err, f'hac {command.split()[0]}')
        assert str(recording) in line, (name, line)
        assert not out.exists() and not Path(str(out) + '.npz').exists(), name


def test_a_bad_recording_is_a_failed_row_of_one_line_in_batch(walk, tmp_path, capsys):
    recordings = _bad_recordings(tmp_path / 'in')
    code = main(['batch', *map(str, recordings.values()), str(walk), '-o', str(tmp_path / 'out')])
    out, err = capsys.readouterr()
    assert code == 1 and 'Traceback' not in out + err, out + err
    failed = [line for line in out.splitlines() if line.startswith('  failed: ')]
    assert len(failed) == len(recordings)
    assert all('cannot read' in line and 'as a recording' in line for line in failed), failed


def test_play_and_simulate_refuse_bad_files_in_one_line(tmp_path):
    recordings = _bad_recordings(tmp_path / 'in')
    result = hac('play', str(recordings['alias_cycle']))
    line = one_line_error(result.returncode, result.stderr, 'hac play')
    assert str(recordings['alias_cycle']) in line
    for motion in (recordings['junk mcap'], bad_file(tmp_path, 'not_utf8'), tmp_path / 'in'):
        code = main(['simulate', 'walk', '-o', str(tmp_path / 'sim'), '--motion', str(motion)])
        assert code == 2 and not (tmp_path / 'sim').exists()


@pytest.mark.parametrize('slot', ['--trajectory', '--map', '--joints', '--gt-trajectory',
                                  '--gt-joints'])
@pytest.mark.parametrize('kind', ['not_utf8', 'junk', 'directory', 'alias_cycle'])
def test_import_refuses_every_bad_file_in_one_line(walk, tmp_path, capsys, slot, kind):
    """The other slots get files that would not do either: the bad one is refused first or
    alongside, always in one line naming a file, never a traceback."""
    bad = bad_file(tmp_path, kind)
    argv = ['import', '-o', str(tmp_path / 'out')]
    for flag in ('--trajectory', '--map', '--joints', '--gt-trajectory', '--gt-joints'):
        argv += [flag, str(bad if flag == slot else walk / 'metadata.yaml')]
    line = one_line_error(main(argv), capsys.readouterr().err, 'hac import')
    assert str(bad) in line or str(walk) in line, line
    assert not (tmp_path / 'out').exists()


# ============================================================================ escaped strings
def _renamed(topic_names: dict[str, str], frame_from: int | None = None):
    """A copy of a recording's messages with topics renamed and, from the ``frame_from``-th SLAM
    pose on, the SLAM's frame id made hostile (a re-initialisation into a frame named so)."""
    def edit(messages):
        poses = 0
        for topic, log_ns, msg in messages:
            if frame_from is not None and topic in (POSE, CLOUD):
                if topic == POSE:
                    poses += 1
                if poses >= frame_from:
                    msg = copy.deepcopy(msg)
                    msg.header.frame_id = 'map' + HOSTILE
            yield topic_names.get(topic, topic), log_ns, msg
    return edit


def rewrite_renamed(source: Path, target: Path, edit) -> Path:
    """injected.rewrite with the connections of the renamed topics."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    with AnyReader([source], default_typestore=store) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        writer = Writer(target, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        conns: dict[str, object] = {}

        def messages():
            for conn, log_ns, raw in reader.messages():
                yield conn.topic, log_ns, reader.deserialize(raw, conn.msgtype)
        renamed_types = {}
        for topic, log_ns, msg in edit(messages()):
            original = next((t for t in types if topic.startswith(t)), topic)
            msgtype = renamed_types.setdefault(topic, types[original])
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], log_ns, store.serialize_cdr(msg, msgtype))
        writer.close()
    return target


def assert_escaped(text: str) -> None:
    for char in '\x1b\x07\r':
        assert char not in text, repr(text)


@pytest.fixture(scope='module')
def hostile(walk, tmp_path_factory) -> dict[str, Path]:
    """A recording whose joints topic has a hostile name, and one whose SLAM frame becomes one,
    in a directory whose name is hostile too."""
    base = tmp_path_factory.mktemp('hostile') / ('in' + HOSTILE)
    base.mkdir()
    return {'topic': rewrite_renamed(walk, base / 'topic', _renamed({JOINTS: JOINTS + HOSTILE})),
            'frame': rewrite(walk, base / ('frame' + HOSTILE), _renamed({}, frame_from=60)),
            'dir': base}


def test_a_hostile_topic_name_is_listed_escaped(hostile, tmp_path, capsys):
    """The issue's case: the joints topic is missing and the recording's topics are listed."""
    assert main(['replay', str(hostile['topic']), '-o', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert_escaped(err)
    assert '/hmr/joints\\x1b[2J\\x07\\x1b]0;owned\\x07\\r (geometry_msgs/msg/PoseArray' in err
    result = hac('play', str(hostile['topic']), '--topics', '/nothing')
    assert result.returncode == 2 and '/hmr/joints\\x1b[2J' in result.stderr
    assert_escaped(result.stdout + result.stderr)


def test_hostile_frame_ids_and_paths_are_escaped_in_every_command(hostile, tmp_path, capsys):
    frame = hostile['frame']
    out = tmp_path / ('out' + HOSTILE)
    runs = [['replay', str(frame), '-o', str(out)],
            ['eval', str(out), '--gt', str(frame), '--no-references'],
            ['plot', str(out), '--gt', str(frame), '-o', str(tmp_path / ('fig' + HOSTILE))],
            ['export', str(out), '-o', str(tmp_path / ('x' + HOSTILE + '.npz'))],
            ['batch', str(frame), '-o', str(tmp_path / ('batch' + HOSTILE))],
            ['demo', '--recording', str(frame), '-o', str(tmp_path / ('demo' + HOSTILE))],
            ['simulate', 'walk', '-o', str(tmp_path / ('sim' + HOSTILE)), '--duration', '2'],
            ['replay', str(tmp_path / ('missing' + HOSTILE)), '-o', str(tmp_path / 'x')],
            ['import', '-o', str(tmp_path / 'imported'), '--trajectory',
             str(hostile['dir'] / ('none' + HOSTILE + '.tum')), '--map', 'm', '--joints', 'j']]
    for argv in runs:
        code = main(argv)
        captured = capsys.readouterr()
        assert_escaped(captured.out + captured.err)
        assert code in (0, 2), (argv, captured.err)
    replayed = main(['replay', str(frame), '-o', str(tmp_path / 'again')])
    err = capsys.readouterr().err
    assert replayed == 0 and "SLAM map frame changed 'map' -> 'map\\x1b[2J" in err, err
    logs = tmp_path / ('batch' + HOSTILE) / 'logs'
    text = ''.join(p.read_text(encoding='utf-8') for p in logs.iterdir())
    assert 'map\\x1b[2J' in text
    assert_escaped(text)
    summary = (tmp_path / ('batch' + HOSTILE) / 'summary.md').read_text(encoding='utf-8')
    assert 'frame\\x1b[2J' in summary  # the input's name, in the table for people
    assert_escaped(summary)

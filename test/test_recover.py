"""Recordings whose recorder died (hac_ros.recording.recover, ``hac recover``): a real rosbag2
MCAP recording cut short at several places; what comes before the cut is kept, byte for byte."""
from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from hac_ros.cli import main as hac
from hac_ros.simulate import make_scenario, write_recording


@pytest.fixture(scope='module')
def recording(tmp_path_factory) -> Path:
    """A 20 s walk, rosbag2 MCAP (several chunks: rosbag2's writer closes one per ~1 MB)."""
    sc = make_scenario('walk', seed=4, duration=20.0, hmr_bias=0.0)
    return write_recording(sc, tmp_path_factory.mktemp('rec') / 'walk')


def mcap_of(directory: Path) -> Path:
    file, = directory.glob('*.mcap')
    return file


def cut(recording: Path, tmp_path: Path, fraction: float) -> Path:
    """A copy of ``recording`` whose MCAP file ends after ``fraction`` of its bytes."""
    copy = tmp_path / f'cut_{fraction:g}'
    shutil.copytree(recording, copy)
    file = mcap_of(copy)
    data = file.read_bytes()
    file.write_bytes(data[:int(len(data) * fraction)])
    return copy


def raw_messages(path: Path) -> list[tuple[str, int, bytes]]:
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize('fraction', [0.5, 0.9, 0.999])
def test_a_cut_off_recording_is_named_and_its_complete_part_recovered(recording, tmp_path,
                                                                     capsys, fraction):
    broken = cut(recording, tmp_path, fraction)
    before = digest(mcap_of(broken))
    assert hac(['replay', str(broken), '-o', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert 'ends short (cut off while it was recorded?): hac recover keeps' in err, err
    target = tmp_path / 'recovered.mcap'
    assert hac(['recover', str(broken), '-o', str(target)]) == 0
    assert 'hac recover:' in capsys.readouterr().out
    assert digest(mcap_of(broken)) == before  # IN is only read
    kept, whole = raw_messages(target), raw_messages(recording)
    # the same messages, in the same order: every whole chunk before the cut (the last 0.1 %
    # is the summary, written after every message: nothing is lost)
    assert 0 < len(kept) <= len(whole) and kept == [m for m in whole if m in set(kept)]
    assert (len(kept) == len(whole)) == (fraction > 0.99)
    if fraction > 0.7:  # enough of the walk to calibrate
        assert hac(['replay', str(target), '-o', str(tmp_path / 'replayed')]) == 0


def test_a_whole_recording_has_nothing_to_recover(recording, tmp_path, capsys):
    assert hac(['recover', str(recording), '-o', str(tmp_path / 'x.mcap')]) == 2
    assert 'is whole' in capsys.readouterr().err
    assert not (tmp_path / 'x.mcap').exists()


@pytest.mark.parametrize('fraction', [0.001, 0.3])
def test_a_cut_before_the_first_whole_chunk_leaves_nothing_to_recover(recording, tmp_path,
                                                                      capsys, fraction):
    broken = cut(recording, tmp_path, fraction)  # in the header; in the first chunk (1 MB)
    assert hac(['recover', str(broken), '-o', str(tmp_path / 'x.mcap')]) == 2
    assert 'no complete message before the cut' in capsys.readouterr().err
    assert not (tmp_path / 'x.mcap').exists()


def test_a_directory_without_its_metadata_names_the_file_to_read(recording, tmp_path, capsys):
    """rosbag2 writes metadata.yaml when it closes: a recorder that died leaves none."""
    bare = tmp_path / 'no_metadata'
    shutil.copytree(recording, bare)
    (bare / 'metadata.yaml').unlink()
    assert hac(['replay', str(bare), '-o', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert f'no metadata.yaml (a recorder that did not close?): read its storage file ' \
           f'{mcap_of(bare)} itself' in err, err
    assert hac(['replay', str(mcap_of(bare)), '-o', str(tmp_path / 'out')]) == 0


def test_a_sqlite3_recording_is_not_for_recover(tmp_path, capsys):
    sc = make_scenario('walk', seed=4, duration=3.0, hmr_bias=0.0)
    path = write_recording(sc, tmp_path / 'db', storage='sqlite3')
    assert hac(['recover', str(path), '-o', str(tmp_path / 'x.mcap')]) == 2
    assert 'is not an MCAP recording' in capsys.readouterr().err

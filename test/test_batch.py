"""``hac batch``: many recordings on a process pool and on Ray, the summary, resume, exit codes.

Six short simulated recordings (5 s each): a rosbag2 mcap directory, a bare ``.mcap`` file, a
sqlite3 recording, one with Odometry SLAM poses (mixed pose types, no flags), one without ground
truth, and a corrupt one (its mcap truncated half-way). Every successful output must equal the
single replay of its input (same topics, types, log times and bytes per message).
"""
from __future__ import annotations

import csv
import json
import logging
import os
import re
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from hac_ros.batch.jobs import COLUMNS, Job, recording_name, run_job
from hac_ros.batch.ray_tasks import RAY_MAX_RETRIES, probe_ray_address
from hac_ros.batch.runner import batch
from hac_ros.core.basics.errors import HacError
from hac_ros.core.rules.params import HacParams
from hac_ros.recording.diff import recording_differences
from hac_ros.recording.reader import Recording
from hac_ros.recording.writer import OutputWriter
from hac_ros.replay.replayer import replay
from hac_ros.simulate import make_scenario, write_recording

REPO = Path(__file__).resolve().parents[1]
SPEC_COLUMNS = ['input', 'status', 'error', 'frames', 'final_scale', 'spread', 'fallback_pct',
                'resets', 'warn_pct', 'reasons', 'wall_s', 'ATE', 'ATE_S', 'W_MPJPE',
                'scale_err_pct']
METRIC_COLUMNS = ('ATE', 'ATE_S', 'W_MPJPE', 'scale_err_pct')
DURATION_S = 20.0  # the estimate converges once its own uncertainty is under 1 %: ~8 s
OK = ('walk', 'ego', 'stairs', 'odom', 'nogt')  # output names of the inputs that must succeed
CORRUPT = 'truncated'


# ============================================================================ recordings
def _without_ground_truth(source: Path, target: Path) -> Path:
    """A copy of ``source`` without its /gt/ topics."""
    with Recording(source) as recording:
        writer = OutputWriter(target, 'mcap')
        try:
            keep = [t for t in recording.topics if not t.startswith('/gt/')]
            for topic, log_ns, raw in recording.messages(keep):
                writer.write(topic, recording.topics[topic], log_ns, raw)
        finally:
            writer.close()
    return target


def _truncated(source: Path, target: Path) -> Path:
    """A copy of the rosbag2 directory ``source`` whose mcap file stops half-way."""
    target.mkdir()
    for f in source.iterdir():
        data = f.read_bytes()
        (target / f.name).write_bytes(data[:len(data) // 2] if f.suffix == '.mcap' else data)
    return target


@pytest.fixture(scope='module')
def inputs(tmp_path_factory) -> list[Path]:
    """The six inputs, in the order given to hac batch."""
    root = tmp_path_factory.mktemp('inputs')
    walk = write_recording(make_scenario('walk', seed=1, duration=DURATION_S), root / 'walk')
    ego_dir = write_recording(make_scenario('ego', seed=2, duration=DURATION_S), root / 'ego_dir')
    ego = root / 'ego.mcap'  # a bare .mcap file: its output is DIR/ego
    shutil.copy(next(ego_dir.glob('*.mcap')), ego)
    stairs = write_recording(make_scenario('stairs', seed=3, duration=DURATION_S),
                             root / 'stairs', storage='sqlite3')
    odom = write_recording(make_scenario('walk', seed=4, duration=DURATION_S), root / 'odom',
                           pose_type='Odometry')
    nogt = _without_ground_truth(write_recording(make_scenario('skate', seed=5,
                                                               duration=DURATION_S),
                                                 root / 'skate'), root / 'nogt')
    truncated = _truncated(walk, root / CORRUPT)
    return [walk, ego, stairs, odom, nogt, truncated]


@pytest.fixture(scope='module')
def singles(inputs, tmp_path_factory) -> dict[str, Path]:
    """Each good input replayed alone (what ``hac replay IN -o OUT`` writes), by output name."""
    root = tmp_path_factory.mktemp('singles')
    return {recording_name(p): replay(p, root / recording_name(p)).output_path
            for p in inputs if recording_name(p) in OK}


@pytest.fixture(scope='module')
def pool_run(inputs, tmp_path_factory):
    """The batch on a process pool of two workers (in this process: the library call)."""
    out = tmp_path_factory.mktemp('pool') / 'out'
    return batch(inputs, out, workers=2)


@pytest.fixture(scope='module')
def local_ray():
    """A Ray on this machine for this module: 2 CPUs, no dashboard, its files under /tmp."""
    ray = pytest.importorskip('ray')
    temp_dir = tempfile.mkdtemp(prefix='hacray_', dir='/tmp')  # short: Ray's socket paths
    ray.init(address='local', num_cpus=2, include_dashboard=False, logging_level=logging.ERROR,
             log_to_driver=False, _temp_dir=temp_dir)
    try:
        yield ray
    finally:
        ray.shutdown()
        shutil.rmtree(temp_dir, ignore_errors=True)


def read_summary(out: Path) -> list[dict[str, str]]:
    with open(out / 'summary.csv', newline='', encoding='utf-8') as f:
        return list(csv.DictReader(f))


def hac(*args: str, timeout: float = 180.0, env: dict[str, str] | None = None
        ) -> subprocess.CompletedProcess:
    """The ``hac`` command line in a subprocess (stderr is a pipe: no progress bar)."""
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', *args], cwd=REPO, text=True,
                          capture_output=True, timeout=timeout, env={**os.environ, **(env or {})})


def assert_outputs_equal(out: Path, singles: dict[str, Path]) -> None:
    for name, single in singles.items():
        assert recording_differences(out / name, single) == [], name


# ============================================================================ the process pool
def test_every_successful_output_equals_its_single_replay(pool_run, singles):
    assert_outputs_equal(pool_run.out_dir, singles)


def test_a_corrupt_input_fails_its_own_row_with_a_one_line_reason(pool_run, inputs):
    rows = {recording_name(p): row for p, row in zip(inputs, pool_run.rows)}
    assert [name for name, row in rows.items() if row.ok] == list(OK)
    failed = rows[CORRUPT]
    assert failed.status == 'failed' and CORRUPT in failed.error and '\n' not in failed.error
    assert pool_run.exit_code == 1
    out = pool_run.out_dir
    assert not (out / CORRUPT).exists() and not (out / f'{CORRUPT}.done.json').exists()
    assert not list(out.glob('.*partial'))  # no staging left behind
    assert failed.error in (out / 'logs' / f'{CORRUPT}.log').read_text()


def test_each_recording_has_its_own_log_with_the_replay_summary(pool_run):
    for name in OK:
        log = (pool_run.out_dir / 'logs' / f'{name}.log').read_text()
        assert 'hac replay (offline)' in log and f'/{name}' in log and 'ok in' in log, name


def test_a_job_logs_to_its_file_and_leaves_the_process_streams_alone(inputs, tmp_path, capfd):
    """run_job gives its log file a logging handler: a thread printing meanwhile stays on stdout
    (a redirected sys.stdout would have sent it into the job's log)."""
    out = tmp_path / 'out'
    job = Job('walk', str(inputs[0]), str(out / 'walk'), HacParams().as_dict(), 'online')
    running = threading.Event()

    def bystander() -> None:
        while not running.is_set():
            time.sleep(0.001)
        while running.is_set():
            print('bystander', flush=True)
            time.sleep(0.01)
    thread = threading.Thread(target=bystander)
    thread.start()
    try:
        running.set()
        row = run_job(job)
    finally:
        running.clear()
        thread.join()
    assert row.ok, row.error
    log = job.log_path.read_text()
    assert 'bystander' not in log
    assert 'hac replay (online)' in log and 'ok in' in log
    assert 'bystander' in capfd.readouterr().out
    assert logging.getLogger('hac_ros').handlers == []  # the job's handler is gone


def test_summary_csv_has_specs_columns_and_metrics_where_there_is_ground_truth(pool_run, inputs):
    rows = read_summary(pool_run.out_dir)
    with open(pool_run.out_dir / 'summary.csv', encoding='utf-8') as f:
        assert f.readline().strip().split(',') == SPEC_COLUMNS
    assert list(COLUMNS) == SPEC_COLUMNS
    assert [r['input'] for r in rows] == [str(p) for p in inputs]
    by_name = {recording_name(r['input']): r for r in rows}
    for name in OK:
        row = by_name[name]
        assert row['status'] == 'ok' and row['error'] == ''
        assert int(row['frames']) == round(DURATION_S * 30) + 1
        assert float(row['final_scale']) > 0 and float(row['spread']) >= 0
        assert 0 <= float(row['fallback_pct']) <= 100 and int(row['resets']) >= 0
        # converging: not_converged until the estimate's own uncertainty is under 1 % (some 8 s
        # of a walk; on the stairs its samples disagree, the walker on the steps: not in 20 s)
        assert 0 < float(row['warn_pct']) < (50 if name in ('walk', 'odom') else 100.1), name
        assert row['reasons'].startswith('not_converged '), row['reasons']
        assert float(row['wall_s']) > 0
        has_truth = name != 'nogt'
        assert all((row[c] != '') == has_truth for c in METRIC_COLUMNS), (name, row)
    assert 0 < float(by_name['walk']['ATE_S']) < 1.0
    assert float(by_name['walk']['scale_err_pct']) < 25.0
    assert all(by_name[CORRUPT][c] == '' for c in ('frames', 'final_scale', *METRIC_COLUMNS))


def test_summary_md_is_the_same_table_and_the_medians_line(pool_run):
    rows = read_summary(pool_run.out_dir)
    text = (pool_run.out_dir / 'summary.md').read_text()
    table = [line for line in text.splitlines() if line.startswith('| `')]
    assert len(table) == len(rows)
    for line, row in zip(table, rows):
        assert line.startswith(f'| `{row["input"]}` | {row["status"]} |')
        assert all(row[c] in line for c in ('final_scale', 'ATE_S', 'W_MPJPE') if row[c])
    truth = [r for r in rows if r['status'] == 'ok' and r['scale_err_pct']]
    assert len(truth) == len(OK) - 1

    medians = re.search(r'Medians over (\d+) recordings with ground truth: scale error '
                        r'([\d.]+) %, ATE-S ([\d.]+) m, W-MPJPE ([\d.]+) mm\.', text)
    assert medians is not None and int(medians[1]) == len(truth)
    # the medians of the unrounded values; the CSV's are rounded to the same digits
    for k, (column, digit) in enumerate((('scale_err_pct', 0.01), ('ATE_S', 1e-4),
                                         ('W_MPJPE', 0.1)), start=2):
        expected = statistics.median(float(r[column]) for r in truth)
        assert float(medians[k]) == pytest.approx(expected, abs=digit), column


# ============================================================================ resume
def test_resume_redoes_only_what_an_interrupted_run_left_unfinished(pool_run, singles, inputs,
                                                                    tmp_path):
    out = tmp_path / 'out'
    shutil.copytree(pool_run.out_dir, out)
    # interrupted: walk was being written (its staging left behind, no output, no marker),
    # ego's process died between its output and its marker
    shutil.rmtree(out / 'walk')
    (out / 'walk.done.json').unlink()
    staging = out / '.walk.abc123.partial' / 'walk'
    staging.mkdir(parents=True)
    (staging / 'walk_0.mcap').write_bytes(b'half a recording')
    (out / 'ego.done.json').unlink()
    # and stairs' input changed since
    stairs_input = next(p for p in inputs if recording_name(p) == 'stairs')
    stairs_file = next(stairs_input.glob('*.db3'))
    stat = stairs_file.stat()
    os.utime(stairs_file, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    kept = {name: (out / f'{name}.done.json').stat().st_mtime_ns for name in ('odom', 'nogt')}
    try:
        result = batch(inputs, out, workers=2, resume=True)
    finally:
        os.utime(stairs_file, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    rows = {recording_name(r.input): r for r in result.rows}
    assert {name for name, r in rows.items() if r.skipped} == {'odom', 'nogt'}
    assert {name for name, r in rows.items() if r.ok} == set(OK)
    assert result.exit_code == 1  # the corrupt input is tried again, and fails again
    for name, mtime_ns in kept.items():
        assert (out / f'{name}.done.json').stat().st_mtime_ns == mtime_ns
        assert 'skipped (resumed)' in (out / 'logs' / f'{name}.log').read_text()
    for name in ('walk', 'ego', 'stairs'):
        assert 'skipped' not in (out / 'logs' / f'{name}.log').read_text()
        assert (out / f'{name}.done.json').exists()
    assert not list(out.glob('.*partial'))
    assert_outputs_equal(out, singles)
    before, after = read_summary(pool_run.out_dir), read_summary(out)
    for a, b in zip(before, after):
        assert {k: v for k, v in a.items() if k != 'wall_s'} == \
            {k: v for k, v in b.items() if k != 'wall_s'}


def test_ctrl_c_keeps_what_finished_and_resume_does_the_rest(inputs, singles, tmp_path):
    out = tmp_path / 'out'
    args = [sys.executable, '-m', 'hac_ros.cli', 'batch', *map(str, inputs), '-o', str(out),
            '--workers', '1']
    process = subprocess.Popen(args, cwd=REPO, text=True, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.monotonic() + 600
        while not list(out.glob('*.done.json')):
            assert process.poll() is None and time.monotonic() < deadline
            time.sleep(0.02)
        # the command held where it is (it can start nothing more, however loaded the machine),
        # then Ctrl-C to the command and its worker
        os.kill(process.pid, signal.SIGSTOP)
        os.killpg(process.pid, signal.SIGINT)
        os.kill(process.pid, signal.SIGCONT)
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == 130, stderr
    finished = {p.name[:-len('.done.json')] for p in out.glob('*.done.json')}
    assert finished and finished < set(OK)
    assert not list(out.glob('.*partial')) and not (out / 'summary.csv').exists()
    assert {p.name for p in out.iterdir() if p.is_dir()} == finished | {'logs'}
    marker_mtimes = {name: (out / f'{name}.done.json').stat().st_mtime_ns for name in finished}
    result = batch(inputs, out, workers=2, resume=True)
    assert {recording_name(r.input) for r in result.rows if r.skipped} == finished
    assert {recording_name(r.input) for r in result.rows if r.ok} == set(OK)
    for name, mtime_ns in marker_mtimes.items():
        assert (out / f'{name}.done.json').stat().st_mtime_ns == mtime_ns
    assert_outputs_equal(out, singles)


def test_resume_redoes_an_output_of_another_mode(pool_run, inputs, tmp_path):
    out = tmp_path / 'out'
    walk = inputs[0]
    shutil.copytree(pool_run.out_dir / 'walk', out / 'walk')
    shutil.copy(pool_run.out_dir / 'walk.done.json', out / 'walk.done.json')
    assert batch([walk], out, resume=True).rows[0].skipped
    online = batch([walk], out, mode='online', resume=True)
    assert online.rows[0].ok and not online.rows[0].skipped
    assert json.loads((out / 'walk.done.json').read_text())['mode'] == 'online'
    single = replay(walk, tmp_path / 'single', mode='online')
    assert recording_differences(out / 'walk', single.output_path) == []


# ============================================================================ the command line
def test_exit_codes_and_what_the_terminal_shows(inputs, tmp_path):
    walk, corrupt = inputs[0], inputs[-1]
    good = hac('batch', str(walk), '-o', str(tmp_path / 'a'), '--workers', '1')
    assert good.returncode == 0, good.stderr
    assert 'summary.csv' in good.stdout and '1 ok' in good.stdout
    assert 'hac replay' not in good.stderr and '\r' not in good.stderr  # logs, no bar
    bad = hac('batch', str(walk), str(corrupt), '-o', str(tmp_path / 'b'))
    assert bad.returncode == 1, bad.stderr
    assert f'failed: {corrupt}' in bad.stdout
    assert (tmp_path / 'b' / 'walk').is_dir() and (tmp_path / 'b' / 'summary.md').exists()


def test_usage_errors_exit_2_and_write_nothing(inputs, tmp_path):
    walk, ego = inputs[0], inputs[1]
    other = tmp_path / 'other'
    other.mkdir()
    shutil.copy(ego, other / 'walk.mcap')  # another recording with the name "walk"
    out = tmp_path / 'out'
    cases = {
        'the same name': ([str(walk), str(other / 'walk.mcap')], "the same name 'walk'"),
        'a missing input': ([str(walk), str(tmp_path / 'nope')], 'not found'),
        'an unreachable Ray': ([str(walk), '--ray', '127.0.0.1:1'], 'no Ray cluster reachable'),
        'no workers': ([str(walk), '--workers', '0'], '--workers'),
    }
    for case, (args, needle) in cases.items():
        result = hac('batch', *args, '-o', str(out), timeout=60)
        assert result.returncode == 2, (case, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and needle in lines[0] and 'Traceback' not in result.stderr, case
        assert not out.exists(), case
    out.mkdir()
    (out / 'walk').mkdir()
    exists = hac('batch', str(walk), '-o', str(out))
    assert exists.returncode == 2 and '--resume' in exists.stderr


def test_ray_missing_is_a_usage_error(inputs, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, 'ray', None)  # import ray -> ImportError
    with pytest.raises(HacError, match=r'pip install "hac_ros\[cluster\]"'):
        batch(inputs[:1], tmp_path / 'out', ray='local')
    assert not (tmp_path / 'out').exists()


def test_an_address_where_no_ray_answers_is_refused_quickly():
    with socket.create_server(('127.0.0.1', 0)) as server:  # speaks HTTP/1, not gRPC
        def answer() -> None:
            conn, _ = server.accept()
            with conn:
                conn.recv(64)
                conn.sendall(b'HTTP/1.0 400 Bad Request\r\n\r\n')
        thread = threading.Thread(target=answer, daemon=True)
        thread.start()
        with pytest.raises(HacError, match='not a Ray cluster'):
            probe_ray_address(f'127.0.0.1:{server.getsockname()[1]}', timeout_s=2.0)
    with pytest.raises(HacError, match='expected local, auto, HOST:PORT'):
        probe_ray_address('my-head-node')


def test_output_names_drop_the_recording_suffix():
    assert [recording_name(p) for p in ('a/walk', 'a/walk/', 'b/walk.mcap', 'c/x.db3',
                                        'd/y.bag', 'e/.mcap')] == \
        ['walk', 'walk', 'walk', 'x', 'y', '.mcap']


# ============================================================================ Ray
@pytest.mark.slow
def test_ray_tasks_give_the_pools_outputs_and_summary(local_ray, pool_run, inputs, tmp_path):
    assert RAY_MAX_RETRIES >= 1
    result = batch(inputs, tmp_path / 'ray', ray='local')
    assert local_ray.is_initialized()  # the caller's Ray is used and left running
    assert result.exit_code == 1
    for name in OK:
        assert recording_differences(tmp_path / 'ray' / name, pool_run.out_dir / name) == [], name
    for a, b in zip(read_summary(pool_run.out_dir), read_summary(tmp_path / 'ray')):
        assert {k: v for k, v in a.items() if k != 'wall_s'} == \
            {k: v for k, v in b.items() if k != 'wall_s'}


@pytest.mark.slow
def test_the_command_line_joins_a_running_cluster_by_its_address(local_ray, pool_run, inputs,
                                                                 tmp_path):
    address = local_ray.get_runtime_context().gcs_address
    odom, nogt = inputs[3], inputs[4]
    result = hac('batch', str(odom), str(nogt), '-o', str(tmp_path / 'out'), '--ray', address)
    assert result.returncode == 0, result.stderr
    for name in ('odom', 'nogt'):
        assert recording_differences(tmp_path / 'out' / name, pool_run.out_dir / name) == []


@pytest.mark.slow
def test_the_command_line_starts_a_local_ray(inputs, pool_run, tmp_path):
    pytest.importorskip('ray')
    ray_tmp = tempfile.mkdtemp(prefix='hacray_', dir='/tmp')
    try:
        result = hac('batch', str(inputs[0]), str(inputs[2]), '-o', str(tmp_path / 'out'),
                     '--ray', 'local', '--workers', '2', env={'RAY_TMPDIR': ray_tmp})
    finally:
        shutil.rmtree(ray_tmp, ignore_errors=True)
    assert result.returncode == 0, result.stderr
    for name in ('walk', 'stairs'):
        assert recording_differences(tmp_path / 'out' / name, pool_run.out_dir / name) == []

"""One recording of ``hac batch``: the job, its summary row, its completion marker, the plan."""
from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import shutil
import socket
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from hac_ros import __version__
from hac_ros.core.basics.errors import ArgumentError, HacError
from hac_ros.core.basics.printable import printable, printable_lines
from hac_ros.core.rules.params import HacParams
from hac_ros.recording.atomic import PARTIAL_SUFFIX, staged_output
from hac_ros.recording.reader import GT_CAMERA, GT_JOINTS, GT_SCALE, Recording
from hac_ros.replay.replayer import MODES

RECORDING_SUFFIXES = ('.mcap', '.db3', '.bag')  # left out of an output's name
PACKAGE_LOGGER = 'hac_ros'  # a job's log file gets what this logger and its children log
JOB_LOG_FORMAT = '%(asctime)s %(levelname)s %(name)s: %(message)s'

log = logging.getLogger(__name__)


LOGS, SUMMARY_CSV, SUMMARY_MD = 'logs', 'summary.csv', 'summary.md'


MARKER_SUFFIX = '.done.json'


# summary.csv's columns (docs/batch.md) -> (Row field, format, summary.md header)
COLUMNS = {
    'input': ('input', 's', 'input'),
    'status': ('status', 's', 'status'),
    'error': ('error', 's', 'error'),
    'frames': ('frames', 'd', 'frames'),
    'final_scale': ('final_scale', '.6g', 'final scale (m/SLAM unit)'),
    'spread': ('spread', '.4g', 'spread (m/SLAM unit)'),
    'fallback_pct': ('fallback_pct', '.1f', 'fallback (%)'),
    'resets': ('resets', 'd', 'resets'),
    'warn_pct': ('warn_pct', '.1f', 'WARN (%)'),
    'reasons': ('reasons', 's', 'reasons'),
    'wall_s': ('wall_s', '.2f', 'wall (s)'),
    'ATE': ('ate_m', '.4f', 'ATE (m)'),
    'ATE_S': ('ate_s_m', '.4f', 'ATE-S (m)'),
    'W_MPJPE': ('w_mpjpe_mm', '.1f', 'W-MPJPE (mm)'),
    'scale_err_pct': ('scale_err_pct', '.2f', 'scale err. (%)'),
}


# hac_ros.evaluation.evaluate's row keys -> Row fields
METRICS = {'ate_m': 'ate_m', 'ate_s_m': 'ate_s_m', 'w_mpjpe_mm': 'w_mpjpe_mm',
           'scale_error_pct': 'scale_err_pct'}


# ============================================================================ one recording
@dataclass
class Job:
    """One recording to calibrate; every path absolute (a Ray node has its own working
    directory)."""

    input: str  # as the user gave it (summary.csv's input column)
    input_path: str
    output_path: str  # DIR/<name>
    params: dict[str, Any]  # HacParams.as_dict()
    mode: str
    version: str = __version__  # the driver's hac_ros: every worker must run the same

    @property
    def name(self) -> str:
        return Path(self.output_path).name

    @property
    def log_path(self) -> Path:
        return Path(self.output_path).parent / LOGS / f'{self.name}.log'

    @property
    def marker_path(self) -> Path:
        return Path(self.output_path).parent / f'{self.name}{MARKER_SUFFIX}'


@dataclass
class Row:
    """One line of the summary. Scale and spread in metres per SLAM unit (the last segment's),
    fallback_pct: ground-plane share of the samples (%), warn_pct: share of its /diagnostics
    statuses that were not OK (%), reasons: the reasons they gave with their shares (the replay
    summary's ``floor_unknown 30 %, ...``), wall_s: seconds this recording took (replay and
    evaluation), ate_m / ate_s_m: metres, w_mpjpe_mm: mm, scale_err_pct: % of the
    final scale against the truth; None where not known (no ground truth, a failed row)."""

    input: str
    status: str = 'failed'  # 'ok' or 'failed'
    error: str = ''
    frames: int | None = None
    final_scale: float | None = None
    spread: float | None = None
    fallback_pct: float | None = None
    resets: int | None = None
    warn_pct: float | None = None
    reasons: str = ''
    wall_s: float | None = None
    ate_m: float | None = None
    ate_s_m: float | None = None
    w_mpjpe_mm: float | None = None
    scale_err_pct: float | None = None
    skipped: bool = False  # complete from an earlier run (resume); not a column

    @property
    def ok(self) -> bool:
        return self.status == 'ok'

    @property
    def has_ground_truth(self) -> bool:
        return any(_finite(getattr(self, f)) for f in METRICS.values())

    def cells(self) -> dict[str, str]:
        """summary.csv's cells: numbers formatted, empty where unknown."""
        return {column: _format(getattr(self, attr), fmt)
                for column, (attr, fmt, _) in COLUMNS.items()}


def run_job(job: Job) -> Row:
    """Calibrate one recording (the function a pool worker or a Ray task runs). Never raises for a
    bad input: the error becomes the row's one-line reason and no output is left behind."""
    start = time.perf_counter()
    done = completed_row(job)
    if done is not None:  # an earlier attempt finished it (a retried Ray task)
        return done
    with job_log(job.log_path):
        log.info('%s -> %s (%s, hac_ros %s, pid %d on %s)', job.input_path, job.output_path,
                 job.mode, __version__, os.getpid(), socket.gethostname())
        try:
            key = _marker_key(job)  # the input as it is before it is read
            row = _calibrate(job)
            row.wall_s = time.perf_counter() - start
            write_text(job.marker_path, json.dumps({**key, 'row': asdict(row)}, indent=1) + '\n')
        except Exception as exc:
            reason = one_line(exc)
            log.error('failed: %s', reason, exc_info=not isinstance(exc, HacError))
            _remove(Path(job.output_path))
            return Row(job.input, 'failed', reason, wall_s=time.perf_counter() - start)
        except BaseException:  # interrupted (Ctrl-C, a cancelled Ray task): nothing half-done
            log.warning('interrupted')
            _remove(Path(job.output_path))
            raise
        log.info('ok in %.2f s', row.wall_s)
    return row


class JobLogFormatter(logging.Formatter):
    """A job log's line, every character a terminal would obey escaped (names and paths from the
    recording: :mod:`hac_ros.core.basics.printable`); a traceback is left as it is."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        return printable_lines(super().formatMessage(record))


@contextlib.contextmanager
def job_log(path: Path) -> Iterator[None]:
    """Everything hac_ros logs meanwhile (the replay's notices, the summaries) goes to ``path``
    (replaced), through a handler on the package's logger, at level INFO, every character a terminal
    would obey escaped (:mod:`hac_ros.core.basics.printable`); the process's streams are left alone.
    Used in a pool worker or a Ray task, one job at a time."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, mode='w', encoding='utf-8')
    handler.setFormatter(JobLogFormatter(JOB_LOG_FORMAT))
    package = logging.getLogger(PACKAGE_LOGGER)
    level = package.level
    package.addHandler(handler)
    package.setLevel(logging.INFO)
    try:
        yield
    finally:
        package.removeHandler(handler)
        package.setLevel(level)
        handler.close()


def _calibrate(job: Job) -> Row:
    """The replay and, where IN has ground truth, the metrics of its output against it."""
    from hac_ros.evaluation.evaluate import evaluate
    from hac_ros.replay.replayer import replay

    if job.version != __version__:
        raise HacError(f'this worker runs hac_ros {__version__}, the driver {job.version}: '
                       'install the same version on every node')
    output = Path(job.output_path)
    job.marker_path.unlink(missing_ok=True)
    _remove(output)  # written by an attempt that died before its marker
    for staging in output.parent.glob(f'.{output.name}.*{PARTIAL_SUFFIX}'):  # a killed attempt's
        shutil.rmtree(staging, ignore_errors=True)
    params = HacParams.from_dict(job.params)
    summary = replay(job.input_path, output, params, mode=job.mode)
    log.info('%s', summary.text())
    status = summary.status
    if summary.last_scale is None:  # as hac replay's exit 3: the row fails with the reason
        raise HacError(summary.why_not_calibrated())
    row = Row(job.input, 'ok', frames=status.frames, final_scale=summary.last_scale.scale,
              spread=summary.last_scale.spread, fallback_pct=100.0 * status.fallback_rate,
              resets=status.resets, warn_pct=summary.statuses.warn_pct,
              reasons=summary.statuses.reasons_text())
    if has_ground_truth(job.input_path):
        evaluation = evaluate(output, job.input_path, params)
        log.info('%s', evaluation.text())
        for key, attr in METRICS.items():
            setattr(row, attr, evaluation.rows['hac'].get(key))
    else:
        log.info('no ground truth in the input: no metrics')
    return row


def has_ground_truth(path: str | Path) -> bool:
    """Whether the recording holds any of the ground-truth topics (with messages)."""
    with Recording(path) as recording:
        return any(recording.has(*topic) for topic in (GT_CAMERA, GT_JOINTS, GT_SCALE))


# ============================================================================ completion markers
def input_fingerprint(path: str | Path) -> dict[str, Any]:
    """The input as a resumed batch compares it: its absolute path and each file's relative name,
    size (bytes) and modification time (ns)."""
    path = Path(path).resolve()
    files = [path] if path.is_file() else sorted(p for p in path.rglob('*') if p.is_file())
    return {'path': str(path),
            'files': [[str(f.relative_to(path)) if f != path else f.name, f.stat().st_size,
                       f.stat().st_mtime_ns] for f in files]}


def _marker_key(job: Job) -> dict[str, Any]:
    """What makes an output complete: the same input, parameters and mode (as JSON values)."""
    return json.loads(json.dumps({'input': input_fingerprint(job.input_path),
                                  'params': job.params, 'mode': job.mode}))


def completed_row(job: Job) -> Row | None:
    """The row of an output that is complete for this job's input, parameters and mode, or None
    (no output, no marker, or a marker of another input, parameters or mode)."""
    try:
        marker = json.loads(job.marker_path.read_text(encoding='utf-8'))
        if not Path(job.output_path).is_dir() or any(
                marker.get(k) != v for k, v in _marker_key(job).items()):
            return None
        row = Row(**marker['row'])
    except (OSError, ValueError, TypeError, KeyError):
        return None
    row.input = job.input
    return row


def write_text(path: Path, text: str) -> None:
    """``text`` (UTF-8) into ``path``, atomically (an existing file is replaced whole)."""
    with staged_output(path, replace=True) as staged:
        staged.write_text(text, encoding='utf-8')


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


# ============================================================================ planning
def recording_name(path: str | Path) -> str:
    """The output name of an input: its file or directory name without a recording suffix."""
    name = Path(path).name
    for suffix in RECORDING_SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[:-len(suffix)]
    return name


def plan(inputs: Sequence[str | Path], out_dir: Path, params: HacParams, mode: str,
         resume: bool) -> tuple[list[Job], dict[str, Row]]:
    """The jobs to run and the rows already complete (``resume``), by output name. Writes
    nothing; raises HacError on a usage error. (An output that is not complete for its job is
    removed by :func:`run_job`, before it replays.)"""
    if mode not in MODES:
        raise ArgumentError(f'{{mode}} must be offline or online, not {mode!r}', 'mode')
    if not inputs:
        raise HacError('no input recordings')
    missing = [str(p) for p in inputs if not Path(p).exists()]
    if missing:
        raise HacError(f'input recording(s) not found: {", ".join(missing)}')
    if out_dir.exists() and not out_dir.is_dir():
        raise HacError(f'output {out_dir} exists and is not a directory')
    jobs: dict[str, Job] = {}
    for given in inputs:
        name = recording_name(given)
        if name in (LOGS, SUMMARY_CSV, SUMMARY_MD) or name.endswith(MARKER_SUFFIX):
            raise HacError(f'input {given}: its name {name!r} is one of hac batch\'s own files '
                           f'in {out_dir}: rename it')
        if name in jobs:
            raise HacError(f'inputs {jobs[name].input} and {given} have the same name {name!r}: '
                           f'both would be written to {out_dir / name} (rename one)')
        source, output = Path(given).resolve(), (out_dir / name).resolve()
        if output == source or source in output.parents or output in source.parents:
            raise HacError(f'output {out_dir / name} would overwrite or contain the input {given}')
        jobs[name] = Job(str(given), str(source), str(output), params.as_dict(), mode)
    done: dict[str, Row] = {}
    existing = [job for job in jobs.values() if Path(job.output_path).exists()]
    if existing and not resume:
        raise ArgumentError(f'output(s) already exist: '
                            f'{", ".join(j.output_path for j in existing)} ({{resume}} skips '
                            'complete ones and redoes the others)', 'resume')
    for job in existing:
        row = completed_row(job)
        if row is not None:
            row.skipped = True
            done[job.name] = row
    return [job for name, job in jobs.items() if name not in done], done


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _format(value: Any, fmt: str) -> str:
    if value is None or fmt == 's':
        return '' if value is None else str(value)
    if not _finite(value):
        return ''
    return format(int(value), 'd') if fmt == 'd' else format(float(value), fmt)


def one_line(exc: BaseException) -> str:
    """An exception as one line: a HacError's own text, otherwise prefixed with its type."""
    from msg_adapters import MessageError

    text = printable((str(exc).strip().splitlines() or [''])[0])
    if isinstance(exc, (HacError, MessageError)) and text:
        return text
    return f'{type(exc).__name__}: {text}' if text else type(exc).__name__

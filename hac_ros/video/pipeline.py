"""``hac video VIDEO|IMAGE_DIR -o OUT``: from a video alone, a metric camera trajectory, a metric
map and the people in the world (docs/video.md).

Keyframes, the people in them (masked out of the features), pycolmap's reconstruction, its gates,
the people lifted with the camera it settled, then the importer and the replay, in this process:
OUT holds what ``hac import``, ``hac replay --export-tum``, ``hac export`` and ``hac plot``
write, under their names, and the map in metres (``map_metric.ply``). The stages before the
calibration are kept in a cache outside OUT (:mod:`hac_ros.video.stages`), so an interrupted run
resumes; OUT appears whole or not at all.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import time
from collections import Counter
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.errors import ArgumentError, HacError, InputError
from hac_ros.core.rules.params import HacParams
from hac_ros.people.params import PeopleParams
from hac_ros.progress import Progress
from hac_ros.recording.atomic import staged_output
from hac_ros.replay.replayer import ReplaySummary
from hac_ros.video.gates import Gate, failed, judge
from hac_ros.video.keyframes import DEFAULT_MOTION, check_rate
from hac_ros.video.sfm import Reconstruction
from hac_ros.video.stages import STILL, Keyframes, People

log = logging.getLogger(__name__)

LAYOUT = 'blazepose33'  # the people front end's
# The replay's parameters without --params: a reconstruction's map is sparse next to the people
# (they are masked out of it), and there the points near a contact's ray say its depth poorly:
# paired on the same people with the true geometry, the floor plane found in the map added
# -0.7 % and +0.7 % to the scale, cone_plane -1.5 % and +0.9 %, nearest_to_ray +2.0 % and +1.3 %
# (bench/video.py runs; docs/video.md, "Accuracy")
VIDEO_PARAMS = HacParams(joint_layout=LAYOUT, reference_mode='floor_plane')
MIN_KEYFRAMES = 3
CACHE_VERSION = 1  # bumped when a stage's files change meaning
# the reconstruction's share of the scale's uncertainty (relative, one sigma), paired on the same
# people with the true geometry (bench/video.py; docs/video.md, "Accuracy"): self-calibrated,
# its focal errs up to 1 % and the floor, and so the scale, follow it; with the intrinsics given
RECONSTRUCTION_REL = {'self_calibrated': 0.01, 'given': 0.005}
FILES = {'recording': 'recording', 'replay': 'replay', 'people': 'people.npz',
         'map': 'map_metric.ply', 'summary': 'summary.txt', 'figures': 'figures',
         'inputs': 'inputs'}  # inputs: the files hac import took (SLAM units, metres)
INPUTS = {'trajectory': 'trajectory.tum', 'map': 'map.ply', 'joints': 'joints.npz'}


@dataclass
class VideoOptions:
    """``camera``: ``fx,fy,cx,cy[,k1,k2,p1,p2]`` pixels, kept as given (None: self-calibrated,
    behind :mod:`hac_ros.video.gates`); ``fps``: the frames' rate (default the video's; a folder
    needs it); ``start``: frame 0's stamp, seconds; ``keyframe_rate``: keyframes per second
    (None: by motion, ``keyframe_motion`` of the width); ``threads``: for the reconstruction (0:
    the cores this process may use); ``cache``: the cache directory (None:
    :func:`default_cache`)."""

    camera: str | None = None
    fps: float | None = None
    start: float = 0.0
    keyframe_rate: float | None = None
    keyframe_motion: float = DEFAULT_MOTION
    threads: int = 0
    cache: Path | None = None


@dataclass
class VideoResult:
    """What ``hac video`` did: the keyframes and the frames, the reconstruction and its gates,
    the people lifted (and dropped by reason), the replay's summary, the seconds per stage."""

    output: Path
    frames: int
    keyframes: int
    model: Reconstruction
    gates: list[Gate]
    people: int = 0
    dropped: Counter[str] = field(default_factory=Counter)
    replay: ReplaySummary | None = None
    resumed: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)

    def uncertainty(self) -> tuple[float, float, float] | None:
        """(scale, its relative ±, the people's relative ±): the replay's standard error of the
        scale (the people's) and the reconstruction's RECONSTRUCTION_REL, in quadrature; None
        when nothing was calibrated."""
        if self.replay is None or self.replay.final_scale is None:
            return None
        scale = self.replay.final_scale
        segments = self.replay.offline.segments if self.replay.offline is not None else []
        error = segments[-1].error if segments else math.nan
        people = error / scale if math.isfinite(error) and scale > 0 else 0.0
        return scale, math.hypot(people, self.reconstruction_rel), people

    @property
    def reconstruction_rel(self) -> float:
        return RECONSTRUCTION_REL['self_calibrated' if self.model.self_calibrated else 'given']

    def text(self) -> str:
        m = self.model
        others = (f'; {len(m.model_sizes) - 1} smaller models left out (sizes '
                  f'{", ".join(map(str, m.model_sizes[1:]))}): the largest is used'
                  if len(m.model_sizes) > 1 else '')
        camera = ('self-calibrated' if m.self_calibrated else 'as given')
        lines = [f'hac video: {self.output}',
                 f'  keyframes {self.keyframes} of {self.frames} frames; reconstruction: '
                 f'{len(m.names)} registered, {len(m.points)} points, reprojection '
                 f'{m.reprojection_px:.2f} px{others}',
                 f'  camera ({camera}): fx {m.K[0, 0]:.1f} fy {m.K[1, 1]:.1f} cx {m.K[0, 2]:.1f} '
                 f'cy {m.K[1, 2]:.1f} px, D {np.round(m.D, 4).tolist()}',
                 f'  people lifted: {self.people}'
                 + (f' (dropped: {dict(self.dropped)})' if self.dropped else ''),
                 '  stages: ' + ', '.join(f'{name} {s:.0f} s' for name, s in self.seconds.items())
                 + (f' (from the cache: {", ".join(self.resumed)})' if self.resumed else '')]
        known = self.uncertainty()
        if known is not None:
            scale, total, people = known
            lines.append(f'  scale {scale:.6g} m per reconstruction unit +- {scale * total:.2g} '
                         f'({total:.1%}: the people\'s {people:.1%} and the reconstruction\'s '
                         f'{self.reconstruction_rel:.1%}, docs/video.md, "Accuracy")')
        return '\n'.join(lines) + ('\n' + self.replay.text() if self.replay else '')


def default_cache() -> Path:
    """``$XDG_CACHE_HOME/hac_ros/video`` (``~/.cache/hac_ros/video``)."""
    base = os.environ.get('XDG_CACHE_HOME') or str(Path.home() / '.cache')
    return Path(base) / 'hac_ros' / 'video'


def _identity(source: Path) -> list[Any]:
    """What names a video's content cheaply: its path, size and change time (a folder: each
    image's)."""
    if source.is_dir():
        return [str(source.resolve())] + [[p.name, p.stat().st_size, p.stat().st_mtime_ns]
                                          for p in sorted(source.iterdir()) if p.is_file()]
    stat = source.stat()
    return [str(source.resolve()), stat.st_size, stat.st_mtime_ns]


def _key(*parts: Any) -> str:
    return hashlib.sha256(json.dumps([CACHE_VERSION, *parts], sort_keys=True, default=str)
                          .encode()).hexdigest()[:16]


def video(source: str | Path, output: str | Path, options: VideoOptions | None = None,
          params: HacParams | None = None, people_params: PeopleParams | None = None,
          progress: Progress | None = None) -> VideoResult:
    """Run ``hac video`` (module docstring). ``params``: the replay's (default VIDEO_PARAMS;
    ``joint_layout`` is set to ``blazepose33``); ``people_params``: the model's. Raises HacError
    (InputError: what cannot work, one line naming why; ArgumentError naming the option) before
    OUT is written."""
    from hac_ros.people.offline import check_camera, parse_camera
    from hac_ros.video.stages import choose_keyframes, find_people

    options = options or VideoOptions()
    people_params = people_params or PeopleParams()
    source, output = Path(source), Path(output)
    if output.exists() or output.is_symlink():
        raise HacError(f'{output} already exists: not overwritten (remove it or choose another '
                       'name)')
    if not source.exists():
        raise InputError(f'{source} does not exist')
    camera = parse_camera(options.camera) if options.camera else None
    check_rate(options.keyframe_rate)
    if camera is not None:
        width, height = _frame_size(source)
        check_camera(str(options.camera), camera[0], camera[2], width, height, source)
    root = (options.cache or default_cache()) / _key(_identity(source))
    seconds: dict[str, float] = {}
    resumed: list[str] = []

    def stage(name: str, key: str, make: Any, load: Any) -> Any:
        folder = root / f'{name}-{key}'
        start = time.perf_counter()
        if folder.is_dir():
            resumed.append(name)
            value = load(folder)
        else:
            value = make(folder)
        seconds[name] = time.perf_counter() - start
        return value

    frames_key = _key(options.fps, options.start, options.keyframe_rate, options.keyframe_motion)
    keyframes: Keyframes = stage(
        'keyframes', frames_key,
        lambda f: choose_keyframes(source, f, options.fps, options.start, options.keyframe_rate,
                                   options.keyframe_motion, progress),
        Keyframes.load)
    if keyframes.most_motion < STILL:
        raise InputError(f'{source}: the camera does not move (the scene shifted at most '
                         f'{keyframes.most_motion:.1%} of the width in {keyframes.frames} frames): '
                         'nothing to reconstruct; a fixed camera is the case of the parameter '
                         'static_camera (hac_node and the replay: the camera\'s height from its '
                         'people alone)')
    if len(keyframes.names) < MIN_KEYFRAMES:
        raise ArgumentError(f'{source}: {len(keyframes.names)} keyframes from '
                            f'{keyframes.frames} frames: at least {MIN_KEYFRAMES} are needed (a '
                            'longer video, or {keyframe_rate})', 'keyframe_rate')
    people_key = _key(frames_key, asdict(people_params))
    people: People = stage(
        'people', people_key, lambda f: find_people(keyframes, f, people_params, progress),
        lambda f: People.load(f / 'people.npz', keyframes.names))
    if not people.count:
        raise InputError(f'{source}: nobody found in {len(keyframes.names)} keyframes: no one to '
                         'calibrate from')
    model: Reconstruction = stage(
        'reconstruction', _key(people_key, options.camera),
        lambda f: _reconstruct(f, keyframes, root / f'people-{people_key}' / 'masks', camera,
                               options.threads, progress),
        lambda f: Reconstruction.load(f / 'reconstruction.npz'))
    gates = judge(model)
    bad = failed(gates)
    if bad:
        remedy = ('' if camera is not None or not model.self_calibrated
                  else ' (give the intrinsics: {camera})')
        raise ArgumentError(f'{source}: the reconstruction is not trusted: '
                            + '; '.join(f'{gate.name}: {gate.text}' for gate in bad) + remedy,
                            'camera')
    if len(model.model_sizes) > 1:
        log.warning('the reconstruction broke into %d models (%s keyframes): the largest is used',
                    len(model.model_sizes), ', '.join(map(str, model.model_sizes)))
    result = VideoResult(output, keyframes.frames, len(keyframes.names), model, gates,
                         resumed=resumed, seconds=seconds)
    start = time.perf_counter()
    _calibrate(result, keyframes, people, params or VIDEO_PARAMS,
               people_params.landmark_min_visibility, progress)
    seconds['calibration'] = time.perf_counter() - start
    return result


def _frame_size(source: Path) -> tuple[int, int]:
    """(width, height) of the first frame of ``source``."""
    from hac_ros.people.offline import FrameSource

    frames = FrameSource(source)
    try:
        for rgb in frames.frames():
            return rgb.shape[1], rgb.shape[0]
    finally:
        frames.close()
    raise InputError(f'{source}: no frame')


def _reconstruct(folder: Path, keyframes: Keyframes, masks: Path,
                 camera: tuple[np.ndarray, np.ndarray, Any] | None, threads: int,
                 progress: Progress | None) -> Reconstruction:
    from hac_ros.video.sfm import reconstruct

    cores = threads or len(os.sched_getaffinity(0))
    K, D = (camera[0], camera[1]) if camera is not None else (None, None)
    with staged_output(folder) as staged:
        staged.mkdir()
        with _stages(progress) as stage:
            model = reconstruct(keyframes.folder, masks, staged / 'colmap', keyframes.names,
                                (keyframes.width, keyframes.height), K=K, D=D, threads=cores,
                                stage=stage)
        model.save(staged / 'reconstruction.npz')
    return model


class _stages:
    """A progress bar per reconstruction stage (the caller's Progress), closed in turn."""

    def __init__(self, progress: Progress | None) -> None:
        self.progress = progress
        self.open: Any = None

    def __enter__(self) -> Any:
        def stage(label: str, total: int) -> Any:
            self._close()
            if self.progress is None:
                return None
            self.open = self.progress(total, label)
            bar = self.open.__enter__()
            return bar.update
        return stage

    def _close(self) -> None:
        if self.open is not None:
            self.open.__exit__(None, None, None)
            self.open = None

    def __exit__(self, *exc: Any) -> None:
        self._close()


def _calibrate(result: VideoResult, keyframes: Keyframes, people: People, params: HacParams,
               min_visibility: float, progress: Progress | None) -> None:
    """OUT from the reconstruction and the people: the importer's files (``inputs/``), the
    recording, the replay (with its TUM files), the export, the metric map, the figures and the
    summary; ``result`` gets the people lifted and the replay's summary."""
    from hac_ros.evaluation.plots import make_plots
    from hac_ros.files.exporter import export
    from hac_ros.files.importer import import_files
    from hac_ros.files.map_files import write_ply
    from hac_ros.files.tum import rotations_to_quats, write_tum
    from hac_ros.people.lifting import Camera
    from hac_ros.replay.replayer import replay
    from hac_ros.video.stages import lift_people

    model, output = result.model, result.output
    stamp_of = dict(zip(keyframes.names, keyframes.stamps))
    stamps = np.array([stamp_of[name] for name in model.names])
    camera = Camera(K=model.K, width=model.width, height=model.height, D=model.D)
    joints, dropped = lift_people(people, model.names, camera, min_visibility)
    lifted = int((~np.isnan(joints).all(axis=(2, 3))).sum())
    if not lifted:
        raise InputError(f'nobody could be lifted in the {len(model.names)} registered keyframes '
                         f'(dropped: {dict(dropped) or "none"}): no one to calibrate from')
    result.people, result.dropped = lifted, dropped
    params = params.replace(joint_layout=LAYOUT)
    with staged_output(output) as staged:
        files = staged / FILES['inputs']
        files.mkdir(parents=True)
        stamps_ns = np.round(stamps * 1e9).astype(np.int64)
        write_tum(files / INPUTS['trajectory'], stamps_ns, model.centres,
                  rotations_to_quats(model.R_wc))
        write_ply(files / INPUTS['map'], model.points, 'hac video reconstruction, SLAM units')
        np.savez(files / INPUTS['joints'], stamps=stamps, joints=joints)
        K = model.K
        import_files(staged / FILES['recording'], files / INPUTS['trajectory'],
                     files / INPUTS['map'], files / INPUTS['joints'],
                     camera=f'{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]},{model.width},'
                            f'{model.height}',
                     joint_layout=LAYOUT, params=params)
        summary = replay(staged / FILES['recording'], staged / FILES['replay'], params,
                         export_tum=staged, progress=progress)
        if summary.calibrated:
            export(staged / FILES['replay'], staged / FILES['people'], LAYOUT)
            _write_metric_map(staged / FILES['replay'], staged / FILES['map'])
        make_plots(staged / FILES['replay'], staged / FILES['figures'])
        result.replay = _moved(summary, staged, output)
        (staged / FILES['summary']).write_text(result.text() + '\n')


def _moved(summary: ReplaySummary, staged: Path, output: Path) -> ReplaySummary:
    """The summary with the paths it names where they will be: in OUT, not its staging."""
    def there(path: Path) -> Path:
        return output / path.relative_to(staged) if path.is_relative_to(staged) else path

    return replace(summary, input_path=there(summary.input_path),
                   output_path=there(summary.output_path),
                   tum={kind: there(path) for kind, path in summary.tum.items()})


def _write_metric_map(replayed: Path, target: Path) -> None:
    """The last ``/hac/cloud`` of the replay (the map in metres, gravity-aligned metric frame)
    as PLY."""
    from hac_ros.bridge.topics import CLOUD
    from hac_ros.files.map_files import write_ply
    from hac_ros.recording.reader import Recording
    from msg_adapters import cloud_to_xyz

    with Recording(replayed) as recording:
        clouds = recording.read(CLOUD.rooted) if recording.has(CLOUD.rooted) else []
        if not clouds:
            return
        _, msg = clouds[-1]
        write_ply(target, cloud_to_xyz(msg), f'hac video: the map in metres, frame '
                  f'{msg.header.frame_id}')

"""The camera's motion and a map from keyframes: pycolmap's incremental structure from motion on
the CPU (docs/video.md, "What it runs"). Needs the [video] extra.

SIFT features (people masked out), sequential matching (each keyframe against the next 1, 2, 4,
... 512: COLMAP's quadratic overlap), then incremental mapping. With given intrinsics the
camera is COLMAP's ``PINHOLE`` (``OPENCV`` with a plumb_bob D) and stays as given; without, it is
``SIMPLE_RADIAL`` (one focal and k1, the principal point at the centre) and bundle adjustment
refines its focal and k1: self-calibration, which :mod:`hac_ros.video.gates` then judges.
"""
from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.errors import InputError
from hac_ros.video.extra import require_pycolmap

log = logging.getLogger(__name__)

MAX_IMAGE_SIZE = 1024  # pixels: longer sides are reduced for the features (time grows with area)
MAX_FEATURES = 4096  # SIFT features per keyframe
OVERLAP = 10  # sequential matching: each keyframe against the next 2^k, k < OVERLAP
MIN_MODEL = 3  # keyframes: a smaller model is not kept
CHUNK = 4  # keyframes per feature extraction call
POLL_S = 0.5  # seconds between looks at a running pycolmap stage
# images this large (longer side, pixels) are described at their own size, not doubled first:
# a third of the time for the same trajectory at 640 x 480 (doubling helps small images)
NATIVE_OCTAVE_PX = 640
# The mapping's start, as given, then looser: COLMAP wants an initial pair seen 16° apart and not
# walking straight ahead (forward motion 0.95); a camera walking toward the people found none
# (with its intrinsics given) and started with these
RELAXED: tuple[dict[str, float], ...] = (
    {}, {'init_min_tri_angle': 4.0, 'init_max_forward_motion': 0.99, 'init_min_num_inliers': 50})
# COLMAP's two-view geometry kinds that constrain a focal: a fundamental or essential matrix
# (UNCALIBRATED 3, CALIBRATED 2); a plane or a pure rotation (PLANAR_OR_PANORAMIC ...) do not
GENERAL_GEOMETRIES = (2, 3)


@dataclass
class Reconstruction:
    """One reconstruction, in its own frame and unit (SLAM units: arbitrary scale).

    ``names`` (N,) the keyframe images registered, in keyframe order; ``R_wc`` (N, 3, 3) and
    ``centres`` (N, 3) their camera-to-map poses (optical axes); ``points`` (M, 3) the map;
    ``K`` (3, 3) pixels and ``D`` (4,) plumb_bob k1, k2, p1, p2 as reconstructed (given, or
    self-calibrated); ``reprojection_px`` the mean reprojection error; ``model_sizes`` the
    keyframes of every model found, largest first (this one is the first); ``keyframes`` how
    many were given; ``self_calibrated``; ``observations`` (N,) points seen per keyframe;
    ``seconds`` per stage."""

    names: list[str]
    R_wc: np.ndarray
    centres: np.ndarray
    points: np.ndarray
    K: np.ndarray
    D: np.ndarray
    width: int
    height: int
    reprojection_px: float
    model_sizes: list[int]
    keyframes: int
    self_calibrated: bool
    observations: np.ndarray
    seconds: dict[str, float] = field(default_factory=dict)
    general_pairs: float = 1.0  # share of the matched pairs whose geometry is not a plane or a
    # pure rotation (COLMAP's two-view geometry): what a self-calibrated focal rests on

    def save(self, path: Path) -> None:
        """Into an .npz (the cache)."""
        np.savez(path, names=np.array(self.names), R_wc=self.R_wc, centres=self.centres,
                 points=self.points, K=self.K, D=self.D, size=np.array([self.width, self.height]),
                 reprojection_px=self.reprojection_px, model_sizes=np.array(self.model_sizes),
                 keyframes=self.keyframes, self_calibrated=self.self_calibrated,
                 observations=self.observations, general_pairs=self.general_pairs,
                 seconds_names=np.array(list(self.seconds)),
                 seconds=np.array(list(self.seconds.values()), dtype=float))

    @classmethod
    def load(cls, path: Path) -> Reconstruction:
        with np.load(path) as data:
            return cls(names=[str(n) for n in data['names']], R_wc=data['R_wc'],
                       centres=data['centres'], points=data['points'], K=data['K'], D=data['D'],
                       width=int(data['size'][0]), height=int(data['size'][1]),
                       reprojection_px=float(data['reprojection_px']),
                       model_sizes=[int(n) for n in data['model_sizes']],
                       keyframes=int(data['keyframes']),
                       self_calibrated=bool(data['self_calibrated']),
                       observations=data['observations'],
                       general_pairs=float(data['general_pairs']),
                       seconds=dict(zip((str(n) for n in data['seconds_names']),
                                        (float(s) for s in data['seconds']))))


def _camera_options(pycolmap: Any, K: np.ndarray | None, D: np.ndarray | None) -> Any:
    reader = pycolmap.ImageReaderOptions()
    if K is None:
        reader.camera_model = 'SIMPLE_RADIAL'  # focal guessed 1.2 x the longer side, refined
        return reader
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if D is not None and np.any(D):
        reader.camera_model = 'OPENCV'
        reader.camera_params = ','.join(f'{v:.12g}' for v in (fx, fy, cx, cy, *D[:4]))
    else:
        reader.camera_model = 'PINHOLE'
        reader.camera_params = ','.join(f'{v:.12g}' for v in (fx, fy, cx, cy))
    return reader


def _intrinsics(camera: Any) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP's camera -> K (3, 3), D (4,) plumb_bob."""
    model, p = camera.model.name, np.asarray(camera.params, dtype=float)
    D = np.zeros(4)
    if model in ('SIMPLE_PINHOLE', 'SIMPLE_RADIAL', 'RADIAL'):
        fx = fy = p[0]
        cx, cy = p[1], p[2]
        D[:len(p) - 3] = p[3:5]  # SIMPLE_RADIAL: k1; RADIAL: k1, k2 (plumb_bob's)
    elif model in ('PINHOLE', 'OPENCV'):
        fx, fy, cx, cy = p[:4]
        D[:len(p) - 4] = p[4:8]
    else:
        raise InputError(f'the reconstruction used camera model {model}: not one hac video sets')
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), D


def reconstruct(images: Path, masks: Path | None, work: Path, names: list[str],
                size: tuple[int, int], K: np.ndarray | None = None,
                D: np.ndarray | None = None, threads: int = 2,
                stage: Callable[[str, int], Any] | None = None) -> Reconstruction:
    """The keyframes ``names`` (files in ``images``, in keyframe order; their masks, when given,
    ``masks/<name>.png``, 0 where people are) reconstructed in ``work`` (its database and
    models); ``size`` (width, height) their pixels. K (3, 3) pixels and D (4,) plumb_bob: given
    intrinsics, kept; None: self-calibrated.
    ``stage(label, total)`` is called as each stage starts and returns a callable advanced once
    per unit done (keyframes registered, for the mapping). Raises InputError when nothing could be
    reconstructed."""
    import time

    pycolmap = require_pycolmap()
    work.mkdir(parents=True, exist_ok=True)
    database = work / 'database.db'
    database.unlink(missing_ok=True)
    seconds: dict[str, float] = {}
    reader = _camera_options(pycolmap, K, D)
    large = max(size) >= NATIVE_OCTAVE_PX
    if masks is not None:
        reader.mask_path = str(masks)
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = threads
    extraction.max_image_size = MAX_IMAGE_SIZE
    extraction.sift.max_num_features = MAX_FEATURES
    if large:  # SIFT's first octave doubles the image by default: three times the time
        extraction.sift.first_octave = 0
    tick = _stage(stage, 'features', len(names))
    start = time.perf_counter()
    for first in range(0, len(names), CHUNK):  # a few at a time: the bar moves
        chunk = list(names[first:first + CHUNK])

        def extract(token: Any, chunk: list[str] = chunk) -> None:
            pycolmap.extract_features(
                str(database), str(images), image_names=chunk,
                camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                extraction_options=extraction, device=pycolmap.Device.cpu,
                cancellation_token=token)

        _cancellable(pycolmap, extract)
        if first == 0:  # the rest share the first chunk's camera
            with pycolmap.Database.open(str(database)) as db:
                reader.existing_camera_id = next(iter(db.read_all_cameras())).camera_id
        tick(len(chunk))
    seconds['features'] = time.perf_counter() - start
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = threads
    pairing = pycolmap.SequentialPairingOptions()
    pairing.overlap = OVERLAP
    pairing.quadratic_overlap = True
    pairing.loop_detection = False
    pairs = _sequential_pairs(len(names))
    tick = _stage(stage, 'matching', pairs)
    start = time.perf_counter()
    matched = [0]

    def matching_progress() -> None:  # the pairs matched so far, read beside the matcher
        try:
            with pycolmap.Database.open(str(database)) as db:
                now = min(pairs, int(db.num_matched_image_pairs()))
        except (RuntimeError, ValueError, OSError):  # a read that met the writer: next time
            return
        tick(now - matched[0])
        matched[0] = now

    _cancellable(pycolmap, lambda token: pycolmap.match_sequential(
        str(database), matching_options=matching, pairing_options=pairing,
        device=pycolmap.Device.cpu, cancellation_token=token), matching_progress)
    tick(pairs - matched[0])
    seconds['matching'] = time.perf_counter() - start
    with pycolmap.Database.open(str(database)) as db:
        _, geometries = db.read_two_view_geometries()
        kinds = [int(g.config) for g in geometries]
    general = sum(kind in GENERAL_GEOMETRIES for kind in kinds) / max(1, len(kinds))
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = threads
    options.multiple_models = True
    options.min_model_size = MIN_MODEL
    options.ba_refine_focal_length = K is None
    options.ba_refine_principal_point = False
    options.ba_refine_extra_params = K is None
    tick = _stage(stage, 'mapping', len(names))
    start = time.perf_counter()
    for attempt, relax in enumerate(RELAXED):  # as COLMAP's own mapper: looser when nothing starts
        if relax:
            log.info('no two keyframes started a model: again with a looser start (%s)',
                     ', '.join(f'{k} {v:g}' for k, v in relax.items()))
            for name, value in relax.items():
                setattr(options.mapper, name, value)

        def mapping(token: Any, folder: Path = work / f'models{attempt}') -> Any:
            folder.mkdir(parents=True, exist_ok=True)
            return pycolmap.incremental_mapping(
                str(database), str(images), str(folder), options=options,
                initial_image_pair_callback=lambda: tick(2),
                next_image_callback=lambda: tick(1), cancellation_token=token)

        models = _cancellable(pycolmap, mapping)
        if models:
            break
    seconds['mapping'] = time.perf_counter() - start
    ranked = sorted(models.values(), key=lambda r: r.num_reg_images(), reverse=True)
    if not ranked:
        raise InputError(f'no reconstruction: no two of the {len(names)} keyframes could start '
                         'one (too little texture, too little motion, or frames too far apart)')
    model = _read(ranked[0], names, [r.num_reg_images() for r in ranked], K is None, seconds)
    model.general_pairs = general
    return model


def _sequential_pairs(n: int) -> int:
    """The image pairs sequential matching tries for ``n`` keyframes with a quadratic overlap:
    each against the next 1, 2, 4, ... 2^(OVERLAP - 1)."""
    return sum(1 for i in range(n) for k in range(OVERLAP) if i + 2 ** k < n)


def _cancellable(pycolmap: Any, call: Callable[[Any], Any],
                 poll: Callable[[], None] | None = None) -> Any:
    """``call(token)`` in a worker thread (pycolmap releases the GIL) while this thread waits,
    calling ``poll`` twice a second: a signal (Ctrl-C) lands here at once, cancels the token and
    waits for pycolmap to stop, then goes on as the KeyboardInterrupt it is."""
    token = pycolmap.CancellationToken()
    box: dict[str, Any] = {}
    done = threading.Event()  # not Thread.join: a join a signal interrupts marks the thread
    # stopped while it runs (CPython before 3.13), and the process then exits under pycolmap

    def work() -> None:
        try:
            box['value'] = call(token)
        except BaseException as exc:  # handed to the waiting thread
            box['error'] = exc
        finally:
            done.set()

    threading.Thread(target=work, name='pycolmap', daemon=True).start()
    try:
        while not done.wait(POLL_S):
            if poll is not None:
                poll()
    except BaseException:
        token.cancel()
        done.wait()  # pycolmap stops at its next look at the token
        raise
    if 'error' in box:
        raise box['error']
    return box.get('value')


def _stage(stage: Callable[[str, int], Any] | None, label: str, total: int
           ) -> Callable[..., None]:
    advance = stage(label, total) if stage is not None else None

    def tick(n: int = 1) -> None:
        if advance is not None:
            advance(n)
    return tick


def _read(model: Any, names: list[str], sizes: list[int], self_calibrated: bool,
          seconds: dict[str, float]) -> Reconstruction:
    order = {name: i for i, name in enumerate(names)}
    posed = sorted((image for image in model.images.values() if image.has_pose),
                   key=lambda image: order[image.name])
    R_wc, centres, observations = [], [], []
    for image in posed:
        pose = image.cam_from_world()
        R_cw = np.asarray(pose.rotation.matrix(), dtype=float)
        R_wc.append(R_cw.T)
        centres.append(-R_cw.T @ np.asarray(pose.translation, dtype=float))
        observations.append(int(image.num_points3D))
    camera = next(iter(model.cameras.values()))
    K, D = _intrinsics(camera)
    points = np.array([p.xyz for p in model.points3D.values()], dtype=float).reshape(-1, 3)
    return Reconstruction(names=[image.name for image in posed], R_wc=np.array(R_wc),
                          centres=np.array(centres), points=points, K=K, D=D,
                          width=int(camera.width), height=int(camera.height),
                          reprojection_px=float(model.compute_mean_reprojection_error()),
                          model_sizes=sizes, keyframes=len(names),
                          self_calibrated=self_calibrated,
                          observations=np.array(observations, dtype=int), seconds=seconds)

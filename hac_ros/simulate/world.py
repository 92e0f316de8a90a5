"""The static world: a floor and axis-aligned boxes (walls, furniture, stair steps), z up, metres.

Boxes make every surface a scenario needs (walls, tables between the camera and the feet, stairs)
and keep ray casting exact and vectorised (the slab method). Landmarks — the points a monocular
SLAM can track — are sampled on the surfaces where there is texture.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

FLOOR_TEXTURE = 0.35  # fraction of floor area with trackable texture (default)
TEXTURE_CELL_M = 0.6  # size of the textured / blank patches of the floor


@dataclass
class Box:
    """An axis-aligned box: lo (3,), hi (3,) metres, world frame; texture: landmark density
    factor."""

    lo: np.ndarray
    hi: np.ndarray
    texture: float = 1.0


@dataclass
class World:
    """The floor z = 0 over ``extent`` (xmin, xmax, ymin, ymax) and boxes standing on or above
    it."""

    extent: tuple[float, float, float, float]
    boxes: list[Box] = field(default_factory=list)
    floor_texture: float = FLOOR_TEXTURE

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """Walkable surface height (metres) at points xy (..., 2): the floor or a box top below 1
        m."""
        xy = np.asarray(xy, dtype=float)
        h = np.zeros(xy.shape[:-1])
        for b in self.boxes:
            if b.hi[2] > 1.0:
                continue  # walls and tall furniture are not walked on
            inside = ((xy[..., 0] >= b.lo[0]) & (xy[..., 0] <= b.hi[0])
                      & (xy[..., 1] >= b.lo[1]) & (xy[..., 1] <= b.hi[1]))
            h = np.where(inside, np.maximum(h, b.hi[2]), h)
        return h

    def raycast(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Distance along each ray to the first surface (inf if none).

        origins: (R, 3) or (3,); directions: (R, 3) unit vectors, world frame, metres.
        """
        d = np.asarray(directions, dtype=float).reshape(-1, 3)
        o = np.broadcast_to(np.asarray(origins, dtype=float), d.shape)
        best = np.full(len(d), np.inf)
        with np.errstate(divide='ignore', invalid='ignore'):
            t_floor = -o[:, 2] / d[:, 2]  # the floor plane
            hit = (t_floor > 1e-9) & np.isfinite(t_floor)
            x = o[:, 0] + t_floor * d[:, 0]
            y = o[:, 1] + t_floor * d[:, 1]
            xmin, xmax, ymin, ymax = self.extent
            hit &= (x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)
            best = np.where(hit, t_floor, best)
            inv = 1.0 / d
            for b in self.boxes:
                t1 = (b.lo - o) * inv
                t2 = (b.hi - o) * inv
                near = np.nanmax(np.minimum(t1, t2), axis=1)
                far = np.nanmin(np.maximum(t1, t2), axis=1)
                ok = (far >= np.maximum(near, 1e-9)) & (near > 1e-9)
                best = np.where(ok & (near < best), near, best)
        return best

    def sample_landmarks(self, density: float, rng: np.random.Generator) -> np.ndarray:
        """Textured surface points, world frame, metres: ``density`` per m² times each texture.

        Texture comes in patches (a coarse random grid of on/off cells), as real scenes have
        textured and blank regions.
        """
        points = []
        xmin, xmax, ymin, ymax = self.extent
        area = (xmax - xmin) * (ymax - ymin)
        n = rng.poisson(density * area)
        floor = np.c_[rng.uniform(xmin, xmax, n), rng.uniform(ymin, ymax, n), np.zeros(n)]
        points.append(_patches(floor[:, :2], TEXTURE_CELL_M, self.floor_texture, rng, floor))
        for b in self.boxes:
            size = b.hi - b.lo
            faces = [(2, b.hi[2]), (0, b.lo[0]), (0, b.hi[0]), (1, b.lo[1]), (1, b.hi[1])]
            for axis, value in faces:
                other = [a for a in range(3) if a != axis]
                face_area = size[other[0]] * size[other[1]]
                m = rng.poisson(density * face_area * b.texture)
                p = np.empty((m, 3))
                p[:, axis] = value
                for a in other:
                    p[:, a] = rng.uniform(b.lo[a], b.hi[a], m)
                points.append(p)
        return np.vstack(points)


def _patches(xy: np.ndarray, cell: float, keep: float, rng: np.random.Generator,
             points: np.ndarray) -> np.ndarray:
    """Keep the points whose ``cell``-metre grid cell is textured (a fraction ``keep`` of cells)."""
    if len(xy) == 0:
        return points
    cells = np.floor(xy / cell).astype(np.int64)
    key = cells[:, 0] * 100_003 + cells[:, 1]
    uniq, inverse = np.unique(key, return_inverse=True)
    textured = rng.random(len(uniq)) < keep
    return points[textured[inverse]]


def room(size: float = 14.0, wall_height: float = 2.8) -> World:
    """A square room centred on the origin with four walls."""
    h = size / 2
    t = 0.2
    walls = [Box(np.array([-h - t, -h - t, 0]), np.array([h + t, -h, wall_height])),
             Box(np.array([-h - t, h, 0]), np.array([h + t, h + t, wall_height])),
             Box(np.array([-h - t, -h, 0]), np.array([-h, h, wall_height])),
             Box(np.array([h, -h, 0]), np.array([h + t, h, wall_height]))]
    return World((-h, h, -h, h), walls)

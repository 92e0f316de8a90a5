"""World humans: people followed across frames, their world trajectory filtered in stamp time.

HMR places each person in depth with a few centimetres of error per frame; in the world that error
becomes jitter of the whole person. ``human_filter: smooth`` filters each person's world root
(the layout's root joint) and moves the whole person with it, the pose untouched:

- online (``hac_node``, ``hac replay --mode online``), causally: a constant-velocity Kalman filter
  per person and axis (:class:`RootFilter`), in stamp time, so that it does not depend on the
  frame rate;
- offline (``hac replay``'s default mode), zero-phase: each person's root smoothed with a Gaussian
  of ``SMOOTH_SIGMA_S`` stamp seconds (:func:`smooth_people`; the authors smooth the global
  translation offline with a Gaussian of 3 frames at 30 fps).

PoseArray blocks carry no identity and detection order can change between frames, so people are
associated across frames first (:class:`PersonTracker`: each person to the nearest predicted world
root of a track within a gate that grows with the time since the track was last seen). The
outputs keep the input's order of blocks. Pure numpy/scipy; arrays in metres, metric frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import HumanJointsOut, Output
from hac_ros.core.layouts import JointLayout

GATE_M = 0.5  # a person further than this from a track's predicted root (plus...)
GATE_SPEED_M_S = 3.0  # ... this speed times the time since it was seen starts a new track
TRACK_TIMEOUT_S = 2.0  # a track not seen for this long is dropped
MEASUREMENT_SIGMA_M = 0.05  # the root's per-frame error (HMR depth noise)
# how fast a person's velocity may change (the filter's process noise)
ACCELERATION_SIGMA_M_S2 = 3.0
SMOOTH_SIGMA_S = 0.1  # offline Gaussian, stamp seconds (3 frames at 30 fps)


@dataclass
class _Track:
    track_id: int
    last_ns: int
    state: np.ndarray  # (2, 3): position (metres), velocity (m/s) per axis
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)))  # per axis (shared)

    def predicted(self, stamp_ns: int) -> np.ndarray:
        return self.state[0] + self.state[1] * ((stamp_ns - self.last_ns) / NS)


class PersonTracker:
    """Track ids for each frame's people: the nearest track's predicted root within the gate."""

    def __init__(self) -> None:
        self.tracks: dict[int, _Track] = {}
        self._next_id = 0

    def assign(self, stamp_ns: int, roots: np.ndarray) -> list[int]:
        """roots: (P, 3) the people's world roots (NaN rows: nobody). Returns a track id per row
        (-1 for a NaN row); unmatched people start tracks (state set by the caller)."""
        self.tracks = {k: t for k, t in self.tracks.items()
                       if (stamp_ns - t.last_ns) / NS <= TRACK_TIMEOUT_S}
        ids = [-1] * len(roots)
        valid = [p for p in range(len(roots)) if np.isfinite(roots[p]).all()]
        tracks = list(self.tracks.values())
        if valid and tracks:
            cost = np.array([[np.linalg.norm(roots[p] - t.predicted(stamp_ns)) for t in tracks]
                             for p in valid])
            gates = np.array([GATE_M + GATE_SPEED_M_S * (stamp_ns - t.last_ns) / NS
                              for t in tracks])
            rows, cols = linear_sum_assignment(np.where(cost <= gates, cost, 1e9))
            for r, c in zip(rows, cols):
                if cost[r, c] <= gates[c]:
                    ids[valid[r]] = tracks[c].track_id
        for p in valid:
            if ids[p] < 0:
                ids[p] = self._next_id
                self._next_id += 1
        return ids


    def follow(self, stamp_ns: int, roots: np.ndarray) -> list[int]:
        """:meth:`assign`, then each track moved to its person's root (its velocity from the
        step): people followed by their roots alone (a fixed camera's people, the offline
        smoothing). roots: (P, 3) metres, any fixed frame (NaN rows: nobody)."""
        ids = self.assign(stamp_ns, roots)
        for p, track_id in enumerate(ids):
            if track_id < 0:
                continue
            track = self.tracks.get(track_id)
            if track is None:
                track = self.tracks[track_id] = _Track(track_id, stamp_ns, np.zeros((2, 3)))
            elif stamp_ns > track.last_ns:  # the track's velocity, for the next prediction
                track.state[1] = (roots[p] - track.state[0]) / ((stamp_ns - track.last_ns) / NS)
            track.state[0], track.last_ns = roots[p], stamp_ns
        return ids


class RootFilter:
    """Online: each person's world root through a constant-velocity Kalman filter (module doc)."""

    def __init__(self, layout: JointLayout) -> None:
        self.layout = layout
        self.tracker = PersonTracker()

    def update(self, stamp_ns: int, joints_metric: np.ndarray) -> np.ndarray:
        """joints_metric: (P, K, 3) metres, metric frame (the frame's people, input order).
        Returns the same people, each moved so that its root is the filtered one."""
        roots = self.layout.root_of(joints_metric)
        ids = self.tracker.assign(stamp_ns, roots)
        out = joints_metric.copy()
        for p, track_id in enumerate(ids):
            if track_id < 0:
                continue
            track = self.tracker.tracks.get(track_id)
            if track is None:
                self.tracker.tracks[track_id] = _Track(
                    track_id, stamp_ns, np.stack([roots[p], np.zeros(3)]),
                    np.diag([MEASUREMENT_SIGMA_M ** 2, 1.0]))
                continue
            filtered = _kalman_step(track, stamp_ns, roots[p])
            out[p] += filtered - roots[p]
        return out


def _kalman_step(track: _Track, stamp_ns: int, measured: np.ndarray) -> np.ndarray:
    """One predict-update of the track's constant-velocity filter (the same on the three axes)."""
    dt = max((stamp_ns - track.last_ns) / NS, 0.0)
    F = np.array([[1.0, dt], [0.0, 1.0]])
    q = ACCELERATION_SIGMA_M_S2 ** 2
    Q = q * np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]])
    state = F @ track.state
    P = F @ track.covariance @ F.T + Q
    gain = P[:, 0] / (P[0, 0] + MEASUREMENT_SIGMA_M ** 2)
    state = state + np.outer(gain, measured - state[0])
    track.covariance = P - np.outer(gain, P[0])
    track.state, track.last_ns = state, stamp_ns
    return state[0]


def smooth_people(stamps_ns: list[int], joints_metric: list[np.ndarray],
                  layout: JointLayout, sigma_s: float = SMOOTH_SIGMA_S
                  ) -> list[np.ndarray]:
    """Offline: every person's root smoothed with a Gaussian of ``sigma_s`` stamp seconds over
    their track (zero-phase), each person moved with it. stamps_ns: (F,) the frames' stamps;
    joints_metric[f]: (P_f, K, 3) metres, metric frame. Returns the frames in the same order."""
    tracker = PersonTracker()
    rows: dict[int, list[tuple[int, int]]] = {}  # track id -> [(frame, person)]
    for f, (stamp, people) in enumerate(zip(stamps_ns, joints_metric)):
        for p, track_id in enumerate(tracker.follow(stamp, layout.root_of(people))):
            if track_id >= 0:
                rows.setdefault(track_id, []).append((f, p))
    out = [people.copy() for people in joints_metric]
    reach = int(3.0 * sigma_s * NS)
    for members in rows.values():
        t = np.array([stamps_ns[f] for f, _ in members], dtype=np.int64)
        roots = np.array([layout.root_of(joints_metric[f][p]) for f, p in members])
        lo = np.searchsorted(t, t - reach, side='left')
        hi = np.searchsorted(t, t + reach, side='right')
        for k, (f, p) in enumerate(members):
            dt = (t[lo[k]:hi[k]] - t[k]) / NS
            w = np.exp(-0.5 * (dt / sigma_s) ** 2)
            smoothed = w @ roots[lo[k]:hi[k]] / w.sum()
            out[f][p] += smoothed - roots[k]
    return out


def smooth_outputs(outputs: list[Output], layout: JointLayout) -> None:
    """Offline: the world humans among ``outputs`` (HumanJointsOut, in stamp order) smoothed by
    :func:`smooth_people`, in place."""
    humans = [o for o in outputs if isinstance(o, HumanJointsOut)]
    smoothed = smooth_people([o.stamp_ns for o in humans], [o.joints_metric for o in humans],
                             layout)
    for output, joints in zip(humans, smoothed):
        output.joints_metric = joints

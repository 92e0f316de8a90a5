"""SLAM poses from TF (``pose_source: tf``): the pose of ``slam_pose_frame`` in ``slam_map_frame``.

Some SLAM wrappers publish their pose only as a transform (DPVO's ROS 2 wrapper: ``map`` →
``drone``; stella_vslam_ros and ORB-SLAM3 wrappers: TF besides a topic). :class:`TfPoses` is fed
every transform of ``/tf`` and ``/tf_static`` (the node's TF listener, or the recording's TF topics
in the replay) and turns the SLAM's own transform messages into poses:

- The chain from the map frame to the pose frame is found in the tree of transforms seen so far
  (each frame has one parent, as in tf2). It may hold static transforms anywhere (a
  ``map`` → ``slam_map`` offset, a ``base_link`` → ``camera_optical`` extrinsic) and exactly one
  dynamic transform: the SLAM's.
- Each message of that dynamic transform gives one pose, at **its** stamp: the chain composed
  with that message and the static transforms, as numbers, the way the wrapper composed them
  (a monocular SLAM's wrapper applies its extrinsics to a trajectory of unknown scale, so their
  translations are taken in the pose's own units). No interpolation and no extrapolation here:
  joints are matched to these poses as to topic poses (within ``sync_slop_s``, or interpolated
  between two of them at most ``interp_max_gap_s`` apart; :mod:`hac_ros.core.stream.pose_stream`).
- A chain through a second dynamic transform (wheel odometry ``odom`` → ``base_link`` under a
  SLAM's ``map`` → ``odom``) would mix metric motion into SLAM units: refused, with an error
  naming the transforms (:attr:`TfUpdate.error`); the replay stops on it, the node counts and
  logs it.

Every other case is named and counted by the shell through the calibrator's rejections:
``tf_invalid`` (a transform that is not finite or not a rotation), ``tf_unconnected`` (a dynamic
transform from the map frame or of the pose frame's branch while the two cannot be connected
yet: a static transform is missing, or a frame is misnamed), ``tf_chain_dynamic`` (the error
above). Transforms of other branches are not the SLAM's and are ignored.

Pure numpy. Transforms: parent → child, ``R`` (3, 3) child to parent, ``t`` (3,) the child's origin
in the parent frame (its unit, SLAM units for the SLAM's own).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Edge:
    """One transform: parent frame, rotation (3, 3) child to parent, translation (3,), stamp (int
    ns; the latest message's for a dynamic transform), static or not."""

    parent: str
    R: np.ndarray
    t: np.ndarray
    stamp_ns: int
    static: bool


@dataclass
class TfUpdate:
    """What one transform message gave: a pose (stamp ns, R_map_pose (3, 3), c (3,) the pose
    frame's origin in the map frame), a rejection reason, an error (a chain through two dynamic
    transforms), or nothing (not the SLAM's)."""

    pose: tuple[int, np.ndarray, np.ndarray] | None = None
    rejected: str = ''
    error: str = ''
    dynamic: list[str] = field(default_factory=list)


def frame_name(frame_id: str) -> str:
    """TF frame ids without a leading slash (ROS 1 wrote ``/map``; tf2 strips it)."""
    return frame_id.lstrip('/')


class TfPoses:
    """The transforms seen so far and the SLAM's pose from them (module docstring)."""

    def __init__(self, map_frame: str, pose_frame: str) -> None:
        self.map_frame = frame_name(map_frame)
        self.pose_frame = frame_name(pose_frame)
        self.edges: dict[str, Edge] = {}  # child frame -> its transform from its parent

    def add(self, parent: str, child: str, stamp_ns: int, R: np.ndarray, t: np.ndarray,
            static: bool) -> TfUpdate:
        """One transform (parent -> child); its pose when it is the SLAM's dynamic transform."""
        parent, child = frame_name(parent), frame_name(child)
        R, t = np.asarray(R, dtype=float), np.asarray(t, dtype=float)
        if R.shape != (3, 3) or t.shape != (3,) or not (np.isfinite(R).all()
                                                        and np.isfinite(t).all()):
            return TfUpdate(rejected='tf_invalid')
        self.edges[child] = Edge(parent, R, t, int(stamp_ns), static)
        if static:
            return TfUpdate()
        chain = self.chain()
        if chain is None:  # a transform of the two frames' branches: one is missing
            near = {*self._ancestors(self.pose_frame), self.map_frame}
            return TfUpdate(rejected='tf_unconnected' if {parent, child} & near else '')
        dynamic = [c for c in reversed(chain) if not self.edges[c].static]  # from the map down
        if len(dynamic) > 1:
            names = ', '.join(f'{self.edges[c].parent} -> {c}' for c in dynamic)
            return TfUpdate(rejected='tf_chain_dynamic', dynamic=dynamic, error=(
                f'the TF chain from slam_map_frame {self.map_frame!r} to slam_pose_frame '
                f'{self.pose_frame!r} passes through {len(dynamic)} dynamic transforms ({names}): '
                'a second moving transform (wheel odometry, say) would mix metric motion into the '
                'SLAM\'s units. Set slam_map_frame and slam_pose_frame to the two ends of the '
                'SLAM\'s own transform (static transforms between may stay)'))
        if child not in chain:
            return TfUpdate()
        R_map_pose, c = self.compose(chain)
        return TfUpdate(pose=(int(stamp_ns), R_map_pose, c))

    def _ancestors(self, frame: str) -> list[str]:
        """``frame`` and the frames above it, child first (stops at a root or a loop)."""
        out = [frame]
        while out[-1] in self.edges and len(out) <= len(self.edges):
            parent = self.edges[out[-1]].parent
            if parent in out:
                break
            out.append(parent)
        return out

    def chain(self) -> list[str] | None:
        """The child frames of the transforms between the map frame and the pose frame (each
        names its edge), or None when the two are not connected."""
        up_pose = self._ancestors(self.pose_frame)
        up_map = self._ancestors(self.map_frame)
        common = next((f for f in up_pose if f in up_map), None)
        if common is None:
            return None
        return (up_pose[:up_pose.index(common)] + up_map[:up_map.index(common)])

    def compose(self, chain: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """T_map_pose (R (3, 3) pose frame to map frame, t (3,) the pose frame's origin in the map
        frame) through the common ancestor A: T_A_map⁻¹ · T_A_pose."""
        up_pose = self._ancestors(self.pose_frame)
        R_ap, t_ap = self._to_ancestor([c for c in up_pose if c in chain])
        R_am, t_am = self._to_ancestor([c for c in self._ancestors(self.map_frame) if c in chain])
        return R_am.T @ R_ap, R_am.T @ (t_ap - t_am)

    def _to_ancestor(self, path: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """The transform from the first frame of ``path`` up to the parent of its last: the
        product of the edges, the top one first."""
        R, t = np.eye(3), np.zeros(3)
        for child in path:  # child first: T = T_edge · T
            edge = self.edges[child]
            R, t = edge.R @ R, edge.R @ t + edge.t
        return R, t

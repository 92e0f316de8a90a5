"""Joints and SLAM poses whose stamps never come within reach of each other: two clocks?

A joints frame is matched to the SLAM pose of its stamp (docs/interface.md, "Processing order").
When the HMR node stamps with the wall clock and the SLAM with a simulated one (or each with its
own epoch), no frame ever finds its pose: every frame is rejected (``no_pose``, or
``pending_overflow`` while it waits for a pose that never comes) and nothing says why.
:class:`StampReach` watches those rejections while no frame has been matched and, once the poses
have come for :data:`REACH_S` of their own stamp time and a frame is still further than that from
the newest of them, says once by how many seconds the two streams are apart. The same notice
reaches the node's log and the replay's; the replay's summary names the offset when nothing was
calibrated.

A SLAM that starts late is not taken for another clock: frames before its first pose are rejected
too, but the newest frame's stamp is then close to the newest pose's.
"""
from __future__ import annotations

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import NoticeOut

REACH_S = 2.0  # seconds of stamp time: the poses' span before judging, and the distance judged
UNMATCHED = ('no_pose', 'pending_overflow')  # rejections of a frame that found no pose


class StampReach:
    """Says once when joints frames and SLAM poses are stamped apart (module docstring).

    ``apart_s``: the joints' stamp minus the newest pose's when it was said (None: not said)."""

    def __init__(self) -> None:
        self.apart_s: float | None = None

    def judge(self, frame_ns: int, first_pose_ns: int | None, newest_pose_ns: int | None,
              frames_matched: int) -> list[NoticeOut]:
        """A frame refused for want of a pose (``frame_ns``), with the stamps of the oldest and
        the newest SLAM pose known and the frames matched so far: the notice, once."""
        if frames_matched or self.apart_s is not None:
            return []
        if first_pose_ns is None or newest_pose_ns is None:
            return []  # no pose yet: the node's no_poses, not a clock
        if newest_pose_ns - first_pose_ns < REACH_S * NS:
            return []
        apart_s = (frame_ns - newest_pose_ns) / NS
        if abs(apart_s) < REACH_S:
            return []
        self.apart_s = apart_s
        which = 'after' if apart_s > 0 else 'before'
        return [NoticeOut(int(frame_ns), 'stamps_apart', f'joints and SLAM poses never come '
                          f'within reach of each other: no joints frame has found its pose, the '
                          f'joints are stamped {abs(apart_s):.6g} s {which} the newest SLAM pose '
                          '(different clocks? both must carry the image\'s stamp)', 'warn')]

"""The checks one person's joints pass before they measure, in order, each naming its reason (the
reason table, hac_ros.core.rules.reasons; docs/node.md). A new refusal is one entry in that table,
one check here and its test.

Two lists, because the bodies vote for down between them (every person in front of the camera
votes, standing or not: hac_ros.core.geometry.down_vote): :data:`JOINT_CHECKS` judge the joints
alone, :data:`BODY_CHECKS` the body against the scene's down. A check returns None when the person
passes, else the detail of its refusal ('' for none). The sample's own refusals, which depend on
the scene (no map or floor, no down yet, the contact joints behind the camera, no reference on
the ray), are hac_ros.core.bodies.sample's.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.bodies.contact import contact_seen
from hac_ros.core.bodies.posture import posture_problem
from hac_ros.core.geometry.plausibility import body_unit_problem, seen_problem
from hac_ros.core.layouts import JointLayout


@dataclass
class Person:
    """One person as the checks see them: ``joints`` (K, 3) metres, camera optical frame (NaN rows
    not seen) in ``layout``; ``contact_mode`` the parameter; ``up_cam`` (3,) the body's lower to
    upper axis and ``down_cam`` (3,) the scene's down (unit, or None while unknown), both camera
    frame, set before :data:`BODY_CHECKS`."""

    layout: JointLayout
    joints: np.ndarray
    contact_mode: str
    up_cam: np.ndarray | None = None
    down_cam: np.ndarray | None = None
    seen: np.ndarray = field(init=False)  # (K,) bool: finite rows
    every: bool = field(init=False)  # every joint seen (the checks skip what that settles)

    def __post_init__(self) -> None:
        self.seen = np.isfinite(self.joints).all(axis=1)
        self.every = bool(self.seen.all())

    @property
    def visible(self) -> np.ndarray:
        """The joints seen, (M, 3) metres."""
        return self.joints if self.every else self.joints[self.seen]


Check = Callable[[Person], 'str | None']


def _infinite(p: Person) -> str | None:
    return '' if not p.every and np.isinf(p.joints).any() else None


def _too_little_seen(p: Person) -> str | None:
    return (seen_problem(p.layout, p.seen) or None) if not p.every else None


def _not_metres(p: Person) -> str | None:
    return body_unit_problem(p.visible) or None


def _behind_camera(p: Person) -> str | None:
    return None if (p.visible[:, 2] > 0.0).any() else ''


def _contact_unseen(p: Person) -> str | None:
    return None if p.every or contact_seen(p.contact_mode, p.layout, p.joints) else ''


def _not_standing(p: Person) -> str | None:
    """Only standing people measure (hac_ros.core.bodies.posture)."""
    assert p.up_cam is not None
    return '' if posture_problem(p.layout, p.joints, p.up_cam, p.down_cam) else None


# (reason, check), in the order they are judged
JOINT_CHECKS: tuple[tuple[str, Check], ...] = (
    ('nonfinite_joints', _infinite),  # NaN is "not seen"; inf is a broken input
    ('too_little_seen', _too_little_seen),  # the body axis's ends, and enough of the joints
    ('joints_not_metres', _not_metres),  # the spread of a body in metres
    ('behind_camera', _behind_camera),  # some joint in front of the camera
)
BODY_CHECKS: tuple[tuple[str, Check], ...] = (
    ('contact_unseen', _contact_unseen),  # the contact can be told from the joints seen
    ('not_standing', _not_standing),  # a support leg, the axis along down
)


def refusal(checks: tuple[tuple[str, Check], ...], person: Person) -> tuple[str, str] | None:
    """The first check ``person`` fails, as (reason, detail), or None when they pass them all."""
    for reason, check in checks:
        detail = check(person)
        if detail is not None:
            return reason, detail
    return None

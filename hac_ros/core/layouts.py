"""Joint layouts (the ``joint_layout`` parameter; docs/inputs.md): which joint is which in an HMR
model's output.

A :class:`JointLayout` says, for one person's K joints (metres, any frame): which joints may touch
the scene (contact candidates), the root (the person's depth and world track), the body's up axis
(lower → upper), the fixed joints of the ``feet``/``pelvis``/``head`` contact modes, the legs (for
the leg length) with each contact joint's height above the sole, and the skeleton's bones (markers).
Several indices in one role mean their mean (COCO-17's root is the mid-hips). Pure Python.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.errors import ParameterError

LAYOUTS = ('smpl24', 'coco17', 'h36m17', 'custom')


@dataclass(frozen=True)
class JointLayout:
    """One layout. Indices are into a person's (K, 3) joints; ``sole_height_rel`` maps a contact
    joint to its height above the sole (or palm) as a fraction of the leg length (thigh plus shank
    of the longer leg, from ``legs``: (hip, knee, ankle) triples); joints not in it sit on the
    surface. ``contact`` empty = every joint is a candidate."""

    name: str
    joints_per_person: int
    root: tuple[int, ...]
    axis_lower: tuple[int, ...]
    axis_upper: tuple[int, ...]
    feet: tuple[int, ...]
    pelvis: tuple[int, ...]
    head: tuple[int, ...]
    contact: tuple[int, ...] = ()
    legs: tuple[tuple[int, int, int], ...] = ()
    sole_height_rel: dict[int, float] = field(default_factory=dict)
    edges: tuple[tuple[int, int], ...] = ()

    def fixed_joints(self, mode: str) -> tuple[int, ...] | None:
        """The joints of a fixed-joint contact mode (``feet``, ``pelvis``, ``head``), else None."""
        return {'feet': self.feet, 'pelvis': self.pelvis, 'head': self.head}.get(mode)

    def root_of(self, joints: np.ndarray) -> np.ndarray:
        """Each person's root (..., 3) from joints (..., K, 3), same frame and unit."""
        return _mean_of(joints, self.root)

    def up_axis(self, joints: np.ndarray) -> np.ndarray:
        """The body's up vector (..., 3), not normalised: upper minus lower, joints' frame."""
        return _mean_of(joints, self.axis_upper) - _mean_of(joints, self.axis_lower)


def _mean_of(joints: np.ndarray, indices: tuple[int, ...]) -> np.ndarray:
    if len(indices) == 1:
        return joints[..., indices[0], :]
    return joints[..., list(indices), :].mean(axis=-2)


# The foot joints of SMPL's regressor sit about 3 cm above the sole of an 0.83 m leg, its ankles
# about 7 cm, the hands about 1.5 cm above the palm (docs/method.md, "The contact is not on the
# surface"). A COCO or H36M ankle keypoint is the malleolus of a shod foot: in a real CMU
# motion-capture walk the stance ankle stands 9.3 cm above the floor on a 0.80 m leg; 0.11 of the
# leg is taken (between SMPL's bare 7 cm and that).
ANKLE_REL = 0.11
SMPL24 = JointLayout(
    name='smpl24', joints_per_person=24, root=(0,), axis_lower=(0,), axis_upper=(12,),
    feet=(10, 11), pelvis=(0,), head=(15,), legs=((1, 4, 7), (2, 5, 8)),
    sole_height_rel={10: 0.036, 11: 0.036, 7: 0.085, 8: 0.085, 22: 0.018, 23: 0.018},
    edges=((0, 1), (0, 2), (0, 3), (1, 4), (2, 5), (3, 6), (4, 7), (5, 8), (6, 9), (7, 10),
           (8, 11), (9, 12), (9, 13), (9, 14), (12, 15), (13, 16), (14, 17), (16, 18), (17, 19),
           (18, 20), (19, 21), (20, 22), (21, 23)))
# nose, l/r eye, l/r ear, l/r shoulder, l/r elbow, l/r wrist, l/r hip, l/r knee, l/r ankle
COCO17 = JointLayout(
    name='coco17', joints_per_person=17, root=(11, 12), axis_lower=(11, 12), axis_upper=(5, 6),
    feet=(15, 16), pelvis=(11, 12), head=(0,), legs=((11, 13, 15), (12, 14, 16)),
    sole_height_rel={15: ANKLE_REL, 16: ANKLE_REL},
    edges=((0, 1), (0, 2), (1, 3), (2, 4), (5, 6), (5, 7), (7, 9), (6, 8), (8, 10), (5, 11),
           (6, 12), (11, 12), (11, 13), (13, 15), (12, 14), (14, 16)))
# pelvis, r hip, knee, ankle, l hip, knee, ankle, spine, thorax, neck/nose, head, l shoulder,
# elbow, wrist, r shoulder, elbow, wrist
H36M17 = JointLayout(
    name='h36m17', joints_per_person=17, root=(0,), axis_lower=(0,), axis_upper=(8,),
    feet=(3, 6), pelvis=(0,), head=(10,), legs=((1, 2, 3), (4, 5, 6)),
    sole_height_rel={3: ANKLE_REL, 6: ANKLE_REL},
    edges=((0, 1), (1, 2), (2, 3), (0, 4), (4, 5), (5, 6), (0, 7), (7, 8), (8, 9), (9, 10),
           (8, 11), (11, 12), (12, 13), (8, 14), (14, 15), (15, 16)))
BUILT_IN = {layout.name: layout for layout in (SMPL24, COCO17, H36M17)}


CUSTOM_ROLES = ('contact_joints', 'root_joints', 'body_axis_lower_joints',
                'body_axis_upper_joints', 'skeleton_edges')


def custom_layout(k: int, index_lists: Mapping[str, Sequence[int]]) -> JointLayout:
    """``joint_layout: custom``: K = ``joints_per_person`` joints and the index list of each of
    :data:`CUSTOM_ROLES`: ``contact_joints`` (also the ``feet`` mode's joints; empty: every
    joint), ``root_joints`` (also ``pelvis``), ``body_axis_lower_joints``,
    ``body_axis_upper_joints`` (also ``head``) and ``skeleton_edges``; its contact joints are taken
    to be on the surface (no sole height). Raises :class:`ParameterError` on bad indices."""
    if k < 1:
        raise ParameterError('joints_per_person: joint_layout custom needs it (>= 1)')
    roles = {name: tuple(index_lists.get(name, ())) for name in CUSTOM_ROLES}
    for name, indices in roles.items():
        bad = [i for i in indices if not 0 <= i < k]
        if bad:
            raise ParameterError(f'{name}: indices {bad} outside 0..{k - 1} '
                                 f'(joints_per_person {k})')
    for name in ('root_joints', 'body_axis_lower_joints', 'body_axis_upper_joints'):
        if not roles[name]:
            raise ParameterError(f'{name}: joint_layout custom needs at least one index')
    edges = roles['skeleton_edges']
    if len(edges) % 2:
        raise ParameterError('skeleton_edges: expected pairs of indices (an even count)')
    contact = roles['contact_joints']
    return JointLayout(
        name='custom', joints_per_person=k, root=roles['root_joints'],
        axis_lower=roles['body_axis_lower_joints'], axis_upper=roles['body_axis_upper_joints'],
        feet=contact or tuple(range(k)), pelvis=roles['root_joints'],
        head=roles['body_axis_upper_joints'], contact=contact,
        edges=tuple(zip(edges[0::2], edges[1::2])))


def joints_per_person(name: str) -> int | None:
    """K of a built-in layout (None for ``custom``); for file checks (``hac import``)."""
    layout = BUILT_IN.get(name)
    return layout.joints_per_person if layout else None

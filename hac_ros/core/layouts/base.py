"""What a joint layout is (:class:`JointLayout`), the ``custom`` layout made from parameters, and
the check every built-in layout passes when it is registered. Pure Python and numpy.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.basics.errors import ParameterError

# (SMPL-24 joint, (forward, left, up) offset in metres in the person's own frame): where the
# simulator places one joint of a layout on its SMPL-24 bodies (hac_ros.simulate.skeletons)
SimPlacement = tuple[int, tuple[float, float, float]]
SMPL24_JOINTS = 24  # the simulator's bodies

# A COCO or H36M ankle keypoint is the malleolus of a shod foot: in a real CMU motion-capture walk
# the stance ankle stands 9.3 cm above the floor on a 0.80 m leg; 0.11 of the leg is taken
# (between SMPL's bare 7 cm and that). Used by the layouts whose contacts are ankles.
SHOD_ANKLE_REL = 0.11

# The biases no sample shows (docs/method.md, "The two parts of the ±"), each a relative standard
# deviation of the scale, fixed from figures outside the bench:
# - the person's size against the size the HMR model gives them: a model places a person too near
#   or too far by as much as their stature differs from it, and adult stature varies by 4.3 %
#   within a sex (NHANES 2015-2018: men 175.4 +- 7.6 cm, women 161.7 +- 7.1 cm);
# - the contact joint's height above the sole: shoes and gait move it by about 1 cm between people
#   (the CMU walks' lowest joints stand 3.8-5.6 cm above the floor at their medians), 0.6 % of the
#   scale seen from a camera 1.5 m above the floor.
STATURE_REL_SIGMA = 0.043
CONTACT_HEIGHT_REL_SIGMA = 0.006
SYS_REL_SIGMA = math.hypot(STATURE_REL_SIGMA, CONTACT_HEIGHT_REL_SIGMA)


@dataclass(frozen=True)
class JointLayout:
    """One layout: which joint is which in an HMR model's output. Indices are into a person's
    (K, 3) joints (metres, any frame); several indices in one role mean their mean (COCO-17's
    root is the mid-hips).

    Roles read by the core: ``root`` (the person's depth and world track), ``axis_lower`` →
    ``axis_upper`` (the body's up axis), ``feet``/``pelvis``/``head`` (the fixed-joint contact
    modes), ``contact`` (the joints that may touch the scene; empty = every joint), ``legs``
    ((hip, knee, ankle) triples: the leg length), ``sole_height_rel`` (a contact joint's height
    above the sole or palm as a fraction of the longer leg's thigh plus shank; joints not in it
    sit on the surface) and ``edges`` (the skeleton's bones, for markers).

    ``sys_rel_sigma``: the prior relative standard deviation of the biases no sample shows for
    a model that writes this layout (its size prior, its contact's height), part of the ``±`` a
    user reads (:data:`SYS_REL_SIGMA` unless the layout says otherwise).

    Read elsewhere: ``joint_names`` (docs, files), ``written_by`` (docs/inputs.md's table of
    layouts: the models that write it) and ``sim_placement`` (one :data:`SimPlacement` per joint:
    how the simulator writes this layout; empty for a layout it cannot write).
    """

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
    joint_names: tuple[str, ...] = ()
    written_by: str = ''
    sim_placement: tuple[SimPlacement, ...] = ()
    sys_rel_sigma: float = SYS_REL_SIGMA

    def fixed_joints(self, mode: str) -> tuple[int, ...] | None:
        """The joints of a fixed-joint contact mode (``feet``, ``pelvis``, ``head``), else None."""
        return {'feet': self.feet, 'pelvis': self.pelvis, 'head': self.head}.get(mode)

    def root_of(self, joints: np.ndarray) -> np.ndarray:
        """Each person's root (..., 3) from joints (..., K, 3), same frame and unit."""
        return _mean_of(joints, self.root)

    def up_axis(self, joints: np.ndarray) -> np.ndarray:
        """The body's up vector (..., 3), not normalised: upper minus lower, joints' frame (each
        end the mean of its seen joints; NaN when one end has none)."""
        return _mean_of(joints, self.axis_upper) - _mean_of(joints, self.axis_lower)

    def index(self, joint_name: str) -> int:
        """The index of the joint called ``joint_name`` (ValueError when there is none)."""
        return self.joint_names.index(joint_name)


def _mean_of(joints: np.ndarray, indices: tuple[int, ...]) -> np.ndarray:
    """The mean of the joints ``indices`` (..., 3) over those seen (finite); NaN when none is."""
    if len(indices) == 1:
        return joints[..., indices[0], :]
    group = joints[..., list(indices), :]
    if np.isfinite(group).all():
        return group.mean(axis=-2)
    seen = np.isfinite(group).all(axis=-1, keepdims=True)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(seen, group, 0.0).sum(axis=-2) / seen.sum(axis=-2)


def problems(layout: JointLayout) -> list[str]:
    """What is wrong with a built-in layout (empty when nothing): every index within 0..K-1, a
    root and a body axis, a name per joint, a simulator placement per joint (or none), the sole
    heights on contact joints."""
    k = layout.joints_per_person
    found = []
    roles: dict[str, Sequence[int]] = {
        'root': layout.root, 'axis_lower': layout.axis_lower, 'axis_upper': layout.axis_upper,
        'feet': layout.feet, 'pelvis': layout.pelvis, 'head': layout.head,
        'contact': layout.contact, 'legs': [i for leg in layout.legs for i in leg],
        'sole_height_rel': list(layout.sole_height_rel),
        'edges': [i for edge in layout.edges for i in edge]}
    for role, indices in roles.items():
        bad = sorted({i for i in indices if not 0 <= i < k})
        if bad:
            found.append(f'{layout.name}: {role} has indices outside 0..{k - 1}: {bad}')
    for role in ('root', 'axis_lower', 'axis_upper'):
        if not getattr(layout, role):
            found.append(f'{layout.name}: {role} is empty')
    if len(layout.joint_names) != k or len(set(layout.joint_names)) != k:
        found.append(f'{layout.name}: {len(layout.joint_names)} joint names '
                     f'({len(set(layout.joint_names))} distinct) for {k} joints')
    if layout.sim_placement and len(layout.sim_placement) != k:
        found.append(f'{layout.name}: {len(layout.sim_placement)} simulator placements for {k} '
                     'joints')
    bad_source = sorted({j for j, _ in layout.sim_placement if not 0 <= j < SMPL24_JOINTS})
    if bad_source:
        found.append(f'{layout.name}: simulator placements on SMPL-24 joints outside 0..23: '
                     f'{bad_source}')
    candidates = set(layout.contact) or set(range(k))
    stray = sorted(set(layout.sole_height_rel) - candidates)
    if stray:
        found.append(f'{layout.name}: sole heights for joints that are not contacts: {stray}')
    if any(not 0.0 <= h < 0.5 for h in layout.sole_height_rel.values()):
        found.append(f'{layout.name}: a sole height outside [0, 0.5) of the leg')
    if not layout.written_by:
        found.append(f'{layout.name}: written_by is empty (docs/inputs.md lists it)')
    return found


CUSTOM = 'custom'
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
        name=CUSTOM, joints_per_person=k, root=roles['root_joints'],
        axis_lower=roles['body_axis_lower_joints'], axis_upper=roles['body_axis_upper_joints'],
        feet=contact or tuple(range(k)), pelvis=roles['root_joints'],
        head=roles['body_axis_upper_joints'], contact=contact,
        edges=tuple(zip(edges[0::2], edges[1::2])),
        joint_names=tuple(f'joint_{i}' for i in range(k)), written_by='your own model')

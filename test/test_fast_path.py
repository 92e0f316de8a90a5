"""The fast ray query (depth window, k-d tree, thinning) against the literal method on every
scenario.

Tolerance (docs/method.md): the two differ only by map points outside the depth window — occluders
and far surfaces — so the sequence scale is the same to 0.1 % where the cones hold nothing but the
contact surface, within 2 % where stair steps do (``stairs``) and within 5 % where an occluder
sits in them (``occluded``).
"""
from __future__ import annotations

import numpy as np
import pytest

from hac_ros.core.basics.outputs import SampleOut
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.estimate.estimator import sequence_scale
from hac_ros.core.geometry.reference import MapIndex, literal_cone_median
from hac_ros.core.rules.params import HacParams
from hac_ros.simulate import SCENARIOS, feed_scenario, make_scenario
from hac_ros.simulate.scenarios import NOBODY_STANDS

TOLERANCE = {'occluded': 0.05, 'stairs': 0.02}
DEFAULT_TOLERANCE = 0.001


def sequence(sc, params: HacParams) -> float:
    outs = feed_scenario(Calibrator(params), sc)
    return sequence_scale(np.array([o.scale for o in outs if isinstance(o, SampleOut) and o.accepted]))


@pytest.mark.parametrize('name', sorted(set(SCENARIOS) - set(NOBODY_STANDS)))
def test_fast_path_gives_the_literal_scales(name):
    sc = make_scenario(name, seed=0, duration=6.0 if name != 'reset' else 10.0)
    fast = sequence(sc, HacParams())
    literal = sequence(sc, HacParams(ray_window_rel=0.0, index_max_points=10**9))
    assert np.isfinite(fast) and np.isfinite(literal)
    assert fast == pytest.approx(literal, rel=TOLERANCE.get(name, DEFAULT_TOLERANCE))


def test_thinning_a_dense_map_keeps_the_cone_median():
    """Maps above index_max_points are thinned at random: per ray the cone median moves by the
    noise of a median of fewer points (a few %); on average it does not move (no bias)."""
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(-6, 6, (600_000, 2)), rng.normal(0, 0.005, 600_000)]
    origin = np.array([0.0, -4.0, 1.5])
    full = MapIndex(floor)
    thin = MapIndex(floor, max_points=100_000)
    assert len(thin) < 110_000 and thin.received == 600_000
    cos_min = np.cos(np.radians(2.56))
    ratios = []
    for x in np.linspace(-3, 3, 41):
        d = np.array([x, 4.0, -1.5])
        d /= np.linalg.norm(d)
        literal = literal_cone_median(floor, origin, d, cos_min, 3)
        assert full.query(origin, d, mode='cone_median', cos_min=cos_min, min_points=3).distance == \
            pytest.approx(literal, rel=1e-12)
        ratios.append(thin.query(origin, d, mode='cone_median', cos_min=cos_min,
                                 min_points=3).distance / literal)
    ratios = np.array(ratios)
    assert np.max(np.abs(ratios - 1)) < 0.03
    assert abs(np.mean(ratios) - 1) < 0.003

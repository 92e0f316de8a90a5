"""The estimator's streaming median (hac_ros.core.estimate.sorted_window) equals numpy's median and MAD
exactly, through additions and removals, duplicates included; so does the core's median of a few
values (hac_ros.core.basics.numeric.median_of)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hac_ros.core.basics.numeric import median_of
from hac_ros.core.estimate.sorted_window import SortedWindow


def numpy_stats(values: list[float]) -> tuple[float, float]:
    a = np.array(values)
    median = float(np.median(a))
    return median, float(np.median(np.abs(a - median)))


def test_the_window_reads_as_numpy_through_every_change():
    rng = np.random.default_rng(7)
    window, values = SortedWindow(), []
    for step in range(3000):
        if values and rng.random() < 0.45:  # a value leaves (oldest or any)
            value = values.pop(0 if rng.random() < 0.7 else int(rng.integers(len(values))))
            window.remove(value)
        else:  # rounded: many duplicates, as repeated samples give
            value = float(np.round(rng.normal(1.2, 0.03 * (1 + step % 3)), int(rng.integers(2, 5))))
            values.append(value)
            window.add(value)
        assert len(window) == len(values)
        if values:
            assert (window.median(), window.mad()) == numpy_stats(values), values


def test_empty_and_missing():
    window = SortedWindow()
    assert math.isnan(window.median()) and math.isnan(window.mad())
    window.add(1.0)
    assert (window.median(), window.mad()) == (1.0, 0.0)
    with pytest.raises(ValueError):
        window.remove(2.0)


def test_median_of_equals_numpy_bit_for_bit():
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 17, 40, 41, 1000):
        for values in (rng.normal(size=n), np.round(rng.normal(size=n), 1),  # with duplicates
                       rng.normal(size=(n, 3)), [float(v) for v in rng.normal(size=n)]):
            assert median_of(values) == float(np.median(values))
    assert median_of(np.array([1.0, np.inf, 2.0])) == 2.0
    assert math.isnan(median_of([np.inf, -np.inf])) and math.isnan(np.median([np.inf, -np.inf]))
    for no_median in ([], np.array([1.0, np.nan, 2.0]), np.array([np.nan])):
        assert math.isnan(median_of(no_median)) and isinstance(median_of(no_median), float)

"""The estimator's streaming median (hac_ros.core.sorted_window) equals numpy's median and MAD
exactly, through additions and removals, duplicates included."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hac_ros.core.sorted_window import SortedWindow


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

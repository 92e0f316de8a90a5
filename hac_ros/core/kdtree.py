"""scipy's k-d tree for the map index, built without numpy's slow bounding-box reduction.

``cKDTree(points)`` starts by computing the points' bounding box with ``np.amax(data, axis=0)`` and
``np.amin(data, axis=0)``. numpy reduces an (N, 3) C-ordered array over axis 0 one row at a time
(its inner loop runs 3 elements long): 2.7 ms each for 100k points on this machine, against 0.04 ms
for the same maximum taken column by column. The two reductions were a third of the tree's build
(15.0 ms → 9.8 ms at 100k points), and building map indexes is what the replay's map threads spend
most of their time on (docs/benchmarks.md).

scipy's ``_ckdtree`` module looks ``np.amax`` / ``np.amin`` up in its own module globals each
time. :func:`install_column_extrema` gives that module (only it) a copy of the numpy namespace in
which ``amax``/``amin`` over axis 0 of a plain 2-D array reduce each column separately: the same
values (a maximum is exact, whatever the order), so the same tree. Any other call goes to numpy
unchanged. Where the module is not laid out this way (another scipy version), nothing changes and
the tree is built the ordinary way. test/test_fast_path.py checks that the trees are identical.

The tree is also built over the points sorted by cell of a coarse grid (:func:`cell_order`, 0.6 ms
at 100k points plus 0.25 ms to reorder): scipy partitions the points in place while it builds, and
points that lie near each other in memory make that ~2x faster (9.3 → 4.5 ms at 100k points in
random order, as ORB-SLAM's map points come). A query then reads nearby points from nearby memory
too. The order changes nothing a query returns but the order of the points in it.
"""
from __future__ import annotations

import threading
import types
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

LEAF_SIZE = 32  # k-d tree leaf size: builds ~20 % faster than scipy's 16 at the same query cost
CELL_KEYS = 1 << 16  # cells of the sorting grid: 16-bit keys, which numpy sorts with a radix sort
SORT_MIN_POINTS = 4096  # smaller maps are indexed in their own order

_lock = threading.Lock()
_installed: types.ModuleType | None = None  # the namespace given to scipy's _ckdtree


def _column_wise(reduce: Any) -> Any:
    """``reduce`` (np.amax or np.amin), one column at a time for axis 0 of a plain 2-D array."""
    def column_wise(a: Any, axis: Any = None, *args: Any, **kwargs: Any) -> Any:
        if (axis == 0 and not args and not kwargs and type(a) is np.ndarray and a.ndim == 2
                and a.shape[0] > 0 and a.shape[1] <= 8):  # few columns: numpy's slow case
            return np.array([reduce(a[:, j]) for j in range(a.shape[1])], dtype=a.dtype)
        return reduce(a, axis, *args, **kwargs)
    column_wise.__name__ = reduce.__name__
    column_wise.__doc__ = f'numpy.{reduce.__name__}, column by column over axis 0 (hac_ros)'
    return column_wise


def _numpy_with_column_extrema() -> types.ModuleType:
    """A module with numpy's namespace, except amax/amin (column-wise over axis 0)."""
    module = types.ModuleType('numpy', 'numpy as scipy._ckdtree sees it (hac_ros.core.kdtree)')
    module.__dict__.update(np.__dict__)
    module.__dict__['__getattr__'] = lambda name: getattr(np, name)  # numpy's lazy attributes
    module.__dict__['amax'] = _column_wise(np.amax)
    module.__dict__['amin'] = _column_wise(np.amin)
    return module


def install_column_extrema() -> bool:
    """Give scipy's ``_ckdtree`` module the column-wise amax/amin (idempotent, thread-safe).

    Returns whether its trees are now built with them."""
    global _installed
    try:
        from scipy.spatial import _ckdtree
    except ImportError:
        return False
    with _lock:
        current = getattr(_ckdtree, 'np', None)
        if _installed is not None and current is _installed:
            return True
        if current is not np:
            return False  # not the layout this was written for: leave it alone
        _installed = _numpy_with_column_extrema()
        _ckdtree.np = _installed
        return True


COLUMN_EXTREMA = install_column_extrema()


def build_tree(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> cKDTree:
    """A k-d tree of ``points``: (N, 3) float64, finite (any unit, one frame).

    lo, hi: (3,) the corners of the box the points mostly fill (points outside count as being at
    its border). The tree is built over the points sorted by :func:`cell_order` (from
    SORT_MIN_POINTS points on): ``tree.data`` holds them in that order, and the indices a query
    returns refer to ``tree.data``. balanced_tree=False builds ~2x faster with near-identical query
    cost on SLAM maps.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    if len(points) >= SORT_MIN_POINTS:
        points = np.take(points, cell_order(points, lo, hi), axis=0)
    return cKDTree(points, leafsize=LEAF_SIZE, balanced_tree=False, compact_nodes=False)


def cell_order(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The order of ``points`` (N, 3) by cell of a grid of at most CELL_KEYS near-cubic cells over
    the box [lo, hi] (points outside it in the border cells); a stable sort, so ties keep their
    order. An axis the box is thinner than one cell along is not divided."""
    extent = np.maximum(np.asarray(hi, dtype=np.float64) - lo, 0.0)
    dims = np.ones(3, dtype=np.int64)
    divided = extent > 0.0
    while divided.any():
        side = (np.prod(extent[divided]) / CELL_KEYS) ** (1.0 / np.count_nonzero(divided))
        thin = divided & (extent < side)
        if not thin.any():
            dims[divided] = np.floor(extent[divided] / side)  # the product stays <= CELL_KEYS
            break
        divided &= ~thin
    key = np.zeros(len(points), dtype=np.uint16)
    cell = np.empty(len(points))
    for axis in range(3):
        if dims[axis] < 2:
            continue
        np.subtract(points[:, axis], lo[axis], out=cell)
        cell *= dims[axis] / extent[axis]
        np.clip(cell, 0.0, dims[axis] - 1, out=cell)
        key *= np.uint16(dims[axis])
        key += cell.astype(np.uint16)
    return np.argsort(key, kind='stable')

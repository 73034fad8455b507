"""Bit-identity checks shared by the kill/resume tests (``test_restart.py``,
``test_restart_glider.py``): a resumed run against the uninterrupted one."""
from __future__ import annotations

import numpy as np


def assert_tree_equal(a, b, where: str) -> None:
    """Bit-identity of two nested state dicts (arrays with ``np.array_equal``)."""
    if isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            assert_tree_equal(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_tree_equal(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"), where
    elif isinstance(a, (bool, int, float, str, type(None), np.generic)):
        assert (a == b) or (a != a and b != b), (where, a, b)
    # other objects (boundary definitions) are inputs, not evolving state


def assert_results_identical(a, b, *, body: str, snapshots: int, min_samples: int) -> None:
    """Every raw and filtered channel (at least ``min_samples`` samples each), the energy
    ledger, the ``snapshots`` particle snapshots, the poses of ``body`` and the DEM step count
    of two open results are equal bit for bit."""
    assert a.channels() == b.channels()
    for name in a.channels():
        for filtered in (False, True):
            sa, sb = a.channel(name, filtered=filtered), b.channel(name, filtered=filtered)
            assert sa.t.size > min_samples, name
            assert np.array_equal(sa.t, sb.t), name
            assert np.array_equal(sa.data, sb.data, equal_nan=True), (name, filtered)
    ea, eb = a.energy(), b.energy()
    assert list(ea) == list(eb)
    for term in ea:
        assert np.array_equal(ea[term].t, eb[term].t), term
        assert np.array_equal(ea[term].data, eb[term].data), term
    ga, gb = a._f["snapshots"], b._f["snapshots"]
    assert ga["t"].shape[0] == snapshots
    assert np.array_equal(ga["t"][:], gb["t"][:])
    assert np.array_equal(ga["x"][:], gb["x"][:])
    for q in ("position", "rotation"):
        assert np.array_equal(ga[f"bodies/{body}"][q][:], gb[f"bodies/{body}"][q][:])
    assert a._f["run"].attrs["dem_steps"] == b._f["run"].attrs["dem_steps"]

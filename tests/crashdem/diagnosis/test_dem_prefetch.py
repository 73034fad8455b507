"""The full DEM of the DEM-truth diagnosis run in parallel (``generator_dem.prefetch``).

``DemFullSimulator.map`` runs a batch's uncached runs on worker processes first; each run is the
same deterministic single-threaded run wherever it executes, so the signals must be identical
bit for bit to the one-by-one runs of another cache. Oracle: the serial path itself.
"""
from __future__ import annotations

import numpy as np
import pytest

from crashdem.diagnosis import generator_dem as gd
from crashdem.diagnosis.parallel import default_workers
from crashdem.run import share_packings


def _cache(tmp_path, name):
    """A fresh run cache sharing the generator's deposited beds (no deposition is repeated)."""
    root = tmp_path / name
    share_packings(root, gd.packings_dir())
    return root


BATCH = [{"physics.contact_damping.enabled": True, "physics.contact_damping.restitution": 0.2},
         {"physics.initial_conditions.enabled": True,
          "physics.initial_conditions.velocity_offset": 1.5},
         {"physics.contact_damping.enabled": True, "physics.contact_damping.restitution": 0.2}]


def test_parallel_batch_equals_one_by_one(tmp_path):
    gd.dem_baseline()  # the baseline bed is deposited (in the shared packings) before timing
    serial = gd.DemFullSimulator(cache=_cache(tmp_path, "serial"), workers=1)
    one_by_one = [serial(ov) for ov in BATCH]
    par_cache = _cache(tmp_path, "parallel")
    par = gd.DemFullSimulator(cache=par_cache, workers=2)
    reqs = [(par._run_overrides(ov), True) for ov in BATCH]
    # two distinct runs (the third repeats the first): both go to the workers
    assert gd.prefetch(reqs, cache=par_cache, workers=2) == 2
    assert gd.prefetch(reqs, cache=par_cache, workers=2) == 0  # all cached now
    batch = par.map(BATCH)
    assert par.calls == len(BATCH) and serial.calls == len(BATCH)
    for a, b in zip(one_by_one, batch):
        assert set(a) == set(b) == {"accel_z", "velocity_z"}
        for k in a:
            assert a[k].unit == b[k].unit
            np.testing.assert_array_equal(a[k].t, b[k].t)
            np.testing.assert_array_equal(a[k].data, b[k].data)
    # the two effects did change the run (the comparison is not between baselines)
    base = gd.dem_baseline()["accel_z"].data
    assert not np.array_equal(batch[0]["accel_z"].data, base)
    assert not np.array_equal(batch[1]["accel_z"].data, batch[0]["accel_z"].data)


def test_a_run_that_fails_in_a_worker_fails_in_the_callers_process(tmp_path):
    """A run the DEM refuses raises in the caller as without workers (ValueError naming the
    field), whatever happened to it on the worker."""
    par = gd.DemFullSimulator(cache=_cache(tmp_path, "bad"), workers=2)
    bad = {"physics.contact_damping.enabled": True, "physics.contact_damping.restitution": 7.0}
    with pytest.raises(ValueError, match="restitution"):
        par.map([bad, BATCH[0]])


@pytest.mark.parametrize("text", ["0", "-2", "two"])
def test_worker_count_is_checked(monkeypatch, text):
    monkeypatch.setenv("CRASHDEM_DEM_WORKERS", text)
    with pytest.raises(ValueError, match="CRASHDEM_DEM_WORKERS"):
        default_workers()
    with pytest.raises(ValueError, match="workers"):
        gd.DemFullSimulator(workers=0)


def test_worker_count_default(monkeypatch):
    monkeypatch.setenv("CRASHDEM_DEM_WORKERS", "3")
    assert default_workers() == 3
    monkeypatch.delenv("CRASHDEM_DEM_WORKERS")
    assert default_workers() >= 1


def test_prefetched_truths_are_the_cases_truths(tmp_path):
    """``prefetch_cases`` runs the truths the cases then load: the same recordings as cases
    generated one by one in another cache, and nothing dispatched once they are cached."""
    cache = _cache(tmp_path, "cases")
    cases = [(21, None), (22, None)]
    assert gd.prefetch_cases(cases, cache=cache, workers=2) == 2
    assert gd.prefetch_cases(cases, cache=cache, workers=2) == 0
    for seed, effect in cases:
        a = gd.dem_concealed_case(seed, effect, cache=cache)
        b = gd.dem_concealed_case(seed, effect, cache=_cache(tmp_path, f"one_{seed}"))
        for k in ("accel_z", "velocity_z"):
            np.testing.assert_array_equal(a.recording[k].data, b.recording[k].data)
            np.testing.assert_array_equal(a.recording[k].t, b.recording[k].t)
        assert a.truth == b.truth


def test_workers_started_earlier_follow_the_callers_cache(tmp_path, monkeypatch):
    """Workers keep the environment they started with; the cache they write is the caller's
    of now (``$CRASHDEM_CACHE`` changed after they started)."""
    from crashdem.diagnosis import parallel

    parallel.map_processes(abs, [1, -2], 2)  # the pool of two is running
    new = _cache(tmp_path, "moved")
    monkeypatch.setenv("CRASHDEM_CACHE", str(new))
    sim = gd.DemFullSimulator(workers=2)
    reqs = [(sim._run_overrides(ov), True) for ov in BATCH[:2]]
    assert gd.prefetch(reqs, workers=2) == 2
    assert all(gd._cache_file(ov, f, None).exists() for ov, f in reqs)
    assert all(gd._cache_file(ov, f, None).parent.parent == new for ov, f in reqs)

"""Concealed-case diagnoses fanned out over worker processes (``crashdem.diagnosis.parallel``).

Oracle: the same diagnoses one by one in this process; the reports must agree in every field
except the diagnosis's own wall time.
"""
from __future__ import annotations

import json
import os

import pytest

from crashdem.diagnosis import generator, generator_planar, parallel


def _without_wall_time(rep) -> str:
    d = rep.to_dict()
    d["simulations"] = {k: v for k, v in d["simulations"].items() if k != "wall_time_s"}
    return json.dumps(d, sort_keys=True, default=str)


def test_parallel_reports_equal_serial_ones():
    cases = [(21, None), (11, "soil_layering")]
    par = generator.diagnose_cases(cases, workers=2)
    ser = generator.diagnose_cases(cases, workers=1)
    assert [c.seed for c, _, _ in par] == [21, 11]  # in the order asked
    for (cp, rp, _), (cs, rs, _) in zip(par, ser):
        assert cp.effect == cs.effect and cp.values == cs.values
        assert _without_wall_time(rp) == _without_wall_time(rs)
    assert par[1][1].missing_physics == "soil_layering"  # a real diagnosis, not two nulls
    assert par[0][1].missing_physics is None


def test_a_planar_report_pickles_with_its_catalogue():
    """The glider report carries the planar catalogue, whose scenario mappings are bound
    functions (``functools.partial``), so it returns from a worker whole."""
    import pickle

    from crashdem.diagnosis.catalogue import planar_catalogue

    cat = planar_catalogue(generator_planar.GLIDER_BASE,
                           {"impact_height": 1.0, "slope": 0.785, "wall_young": 1e9})
    back = pickle.loads(pickle.dumps(cat))
    wall = next(h for h in back.entries if h.name == "boundary_proximity")
    v = {"wall_distance": 2.0, "wall_stiffness": generator_planar.GLIDER_BASE.wall_stiffness}
    orig = next(h for h in cat.entries if h.name == "boundary_proximity")
    assert wall.scenario_overrides(v) == orig.scenario_overrides(v)
    assert wall.scenario_overrides(v)["container.wall_young"] == pytest.approx(1e9)


def _fails_on_odd(x: int) -> int:
    if x % 2:
        raise ValueError(f"x={x}: odd")
    return 10 * x


@pytest.mark.parametrize("workers", [1, 2])
def test_results_in_order_and_exceptions_raised_or_returned(workers):
    assert parallel.map_processes(_fails_on_odd, [0, 2, 4], workers) == [0, 20, 40]
    out = parallel.map_processes(_fails_on_odd, [2, 3, 4], workers, return_exceptions=True)
    assert out[0] == 20 and out[2] == 40 and isinstance(out[1], ValueError)
    with pytest.raises(ValueError, match="x=3: odd"):
        parallel.map_processes(_fails_on_odd, [2, 3, 4, 5], workers)


def test_worker_environment_is_restored():
    before = {k: os.environ.get(k) for k in parallel.WORKER_THREAD_ENV}
    parallel.map_processes(_fails_on_odd, [0, 2], 2)
    assert {k: os.environ.get(k) for k in parallel.WORKER_THREAD_ENV} == before


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_worker_count_is_checked(bad):
    with pytest.raises(ValueError, match="workers"):
        parallel.map_processes(_fails_on_odd, [0, 2], bad)

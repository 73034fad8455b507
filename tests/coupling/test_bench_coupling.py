"""Small mode of validation/bench_coupling.py (the 50,000-particle run is a validation run)."""

import importlib.util
import math
import pathlib

BENCH = pathlib.Path(__file__).resolve().parents[2] / "validation" / "bench_coupling.py"


def test_bench_small_mode_runs_and_checks_itself():
    """Oracle: the benchmark's own checks -- the body is in contact during the timed steps
    (non-zero contact force) and every timing is a finite positive number."""
    spec = importlib.util.spec_from_file_location("bench_coupling", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = mod.main(small=True)
    assert res["n_particles"] > 1000
    assert res["contact_force"] > 0.0
    for key in ("dem_only_step", "coupled_dem_step", "coupling_per_step", "ratio"):
        assert math.isfinite(res[key]) and res[key] > 0.0

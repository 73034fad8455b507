"""Small mode of validation/perf_soil_kernels.py: runs, produces a sane impact, fits the
memory budget."""

from __future__ import annotations

import importlib.util
from pathlib import Path

MEMORY_BUDGET = 1024.0  # [B/particle], task requirement (<= 1 kB per particle)


def test_perf_script_small_mode():
    """Oracle: reference numbers; memory per particle (counted from the engine's arrays) is
    below 1 kB, the sphere at 19 m/s meets the bed (non-zero force) and both thread counts give
    the same force (bit-identical for any thread count)."""
    path = Path(__file__).resolve().parents[2] / "validation" / "perf_soil_kernels.py"
    spec = importlib.util.spec_from_file_location("perf_soil_kernels", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = mod.main(["--small"])
    assert len(out) >= 1
    for res in out:
        assert res["bytes_per_particle"] < MEMORY_BUDGET
        assert res["sphere_force_N"] > 0.0
        assert res["particle_steps_per_s"] > 0.0
    assert len({r["sphere_force_N"] for r in out}) == 1

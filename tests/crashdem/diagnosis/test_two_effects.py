"""Two concealed effects at once (the thesis drop tests show both a compacted deep layer and
the floor reflection): greedy forward selection must name both and recover their parameters.
Oracle: the generator's hidden truth."""
from __future__ import annotations

import numpy as np

from crashdem.diagnosis import diagnose
from crashdem.diagnosis.generator import ACCEPT_PARAM_RTOL as PARAM_RTOL
from crashdem.diagnosis.generator import acquire
from crashdem.diagnosis.rom import RomParams, simulate

TRUTH = {"interface_depth": 0.18, "strength_ratio": 2.2, "floor_depth": 1.0}


def test_layering_and_floor_proximity_found_together():
    rec = acquire(RomParams(**TRUTH), np.random.default_rng(8))
    rep = diagnose(simulate(RomParams()), rec)
    assert rep.missing_physics is not None
    assert set(rep.missing_physics.split("+")) == {"soil_layering", "boundary_proximity"}
    h = next(h for h in rep.hypotheses if h["name"] == rep.missing_physics)
    for k, v in TRUTH.items():
        assert abs(h["parameters"][k] / v - 1.0) < PARAM_RTOL, (k, h["parameters"][k], v)
    assert h["effects"] == rep.missing_physics.split("+")
    assert rep.fit["after"]["overall"] >= 0.85
    assert rep.fit["after"]["overall"] - rep.fit["before"]["overall"] >= 0.1

"""``validation/realisation_fingerprint.py``: the digest of this machine's DEM realisation is
reproduced bit for bit by a second deposition and impact in a fresh cache, and changes when
the run does (a different packing seed)."""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from validation import realisation_fingerprint as rf  # noqa: E402


@pytest.fixture(scope="module")
def two_fingerprints():
    """Two fingerprints, each from its own fresh deposition and impact."""
    return rf.fingerprint(), rf.fingerprint()


def test_the_fingerprint_is_reproduced_by_a_fresh_run(two_fingerprints):
    a, b = two_fingerprints
    assert a == b
    for key in ("digest", "deposition_digest"):
        assert len(str(a[key])) == 16 and int(str(a[key]), 16) >= 0
    assert a["threads"] >= 1 and a["cpu"]


def test_the_digest_follows_the_packing(two_fingerprints):
    """The digest is of the run's bytes: another packing seed of the same bed gives another."""
    from crashdem.diagnosis.generator_dem import BASELINE_NUMERICS, run_dem

    def digest(overrides):
        with tempfile.TemporaryDirectory() as d:
            sig, _ = run_dem(overrides, filtered=True, cache=Path(d))
        return rf.digest(sig)

    base = digest(dict(BASELINE_NUMERICS))
    assert base == two_fingerprints[0]["digest"]
    assert digest({**BASELINE_NUMERICS, "scenario.seed": 2}) != base

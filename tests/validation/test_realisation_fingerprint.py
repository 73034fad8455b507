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


def test_the_realisation_does_not_follow_numpys_simd_dispatch(two_fingerprints):
    """Oracle: the same run in a process where NumPy's SIMD dispatch above its baseline is
    switched off (``NPY_DISABLE_CPU_FEATURES``), i.e. NumPy as on a CPU without AVX2 / AVX-512:
    the digests of the run and of its bed are the same. Before ``soil.portable`` the grain
    masses came from NumPy's AVX-512 ``r**3``, one bit off the C library's, and an AVX-512
    machine deposited another bed (``392b3e825dcd2bfb`` against ``bd6d0870cf204247`` on the same
    machine with the dispatch off; docs/diagnosis.md, "Another machine, another realisation")."""
    import json
    import os
    import subprocess

    targets = rf.numpy_simd()
    if not targets:
        pytest.skip("NumPy dispatches nothing above its baseline on this CPU")
    env = dict(os.environ, NPY_DISABLE_CPU_FEATURES=" ".join(targets))
    out = subprocess.run([sys.executable, str(ROOT / "validation" / "realisation_fingerprint.py")],
                         env=env, capture_output=True, text=True, check=True, timeout=900)
    other = json.loads(out.stdout.strip().splitlines()[-1])
    mine = two_fingerprints[0]
    assert other["deposition_digest"] == mine["deposition_digest"]
    assert other["digest"] == mine["digest"]


def test_the_command_prints_the_same_fingerprint(two_fingerprints, capsys, monkeypatch):
    """``crashdem fingerprint --json`` prints this process's fingerprint (a third fresh run);
    the readable form names the digest and NumPy's SIMD targets (printed from that same
    fingerprint, not from a fourth run)."""
    import json

    import crashdem.realisation
    from crashdem.cli import main

    assert main(["fingerprint", "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out == two_fingerprints[0]
    assert out["numpy_simd"] == rf.numpy_simd()
    monkeypatch.setattr(crashdem.realisation, "fingerprint", lambda: out)
    assert main(["fingerprint"]) == 0
    text = capsys.readouterr().out
    assert out["digest"] in text and out["deposition_digest"] in text

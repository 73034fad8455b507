"""Print a fingerprint of this machine's DEM realisation (the same as ``crashdem fingerprint
--json``; the code is ``crashdem.realisation``): the SHA-256 of the DEM-truth baseline run's
channels, its bed's, the CPU, the Python and the numerics libraries, and NumPy's SIMD targets.
Usage: ``python validation/realisation_fingerprint.py`` (a few seconds after the Numba kernels
are compiled).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crashdem.realisation import (  # noqa: E402,F401  (re-exported for the tests)
    _sha16, cpu_model, digest, fingerprint, numpy_simd, packing_digest)


def main() -> int:
    print(json.dumps(fingerprint()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The fingerprint of this machine's DEM realisation (``crashdem fingerprint``): the SHA-256 of
the DEM-truth baseline run's channels (``generator_dem.dem_baseline``: deposition and impact of
the small bed, run in a fresh cache) beside the CPU, the Python and the numerics libraries.

Two machines that print the same digest give the DEM-truth tests and the diagnosis validation
the same runs, bit for bit; ``deposition_digest`` is the deposited bed's alone (grain positions,
radii and materials), so when two digests differ it tells whether the deposition already does.
Since session 36 (``soil.portable``) every machine measured prints ``b991ab66708d66af`` (bed
``bd6d0870cf204247``) with this code; before, machines whose NumPy ran AVX-512 code deposited
another bed (docs/diagnosis.md, "Another machine, another realisation"). The digest changes
with the code whenever a run's bits do.
"""
from __future__ import annotations

import hashlib
import platform
import sys
import tempfile
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (``platform.processor()`` elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _sha16(arrays) -> str:
    """The first 16 hex digits of the SHA-256 of ``(name, array)`` pairs, names and bytes."""
    import numpy as np

    h = hashlib.sha256()
    for name, a in arrays:
        h.update(name.encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def digest(signals) -> str:
    """The digest of the channels' names and float64 samples."""
    import numpy as np

    return _sha16((n, np.asarray(signals[n].data, dtype=np.float64)) for n in sorted(signals))


def packing_digest(path: Path) -> str:
    """The digest of a cached packing's grain positions, radii and materials
    (``soil.packing.load_packing``): the deposition alone, before any impact."""
    from soil.packing import load_packing

    p = load_packing(path)
    return _sha16((n, getattr(p, n)) for n in ("x", "radius", "material"))


def numpy_simd() -> list[str]:
    """NumPy's SIMD dispatch targets above its baseline that this CPU runs (``X86_V3``,
    ``X86_V4``, ``AVX512_ICL``, ...); empty when NumPy does not say. Since ``soil.portable``
    they do not change a DEM run."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # pragma: no cover - another NumPy layout
        return []
    return [t for t in __cpu_dispatch__ if __cpu_features__.get(t)]


def fingerprint() -> dict[str, object]:
    """The digest of a fresh DEM-truth baseline run and what it ran on."""
    import numba
    import numpy as np
    import scipy

    from crashdem.diagnosis.generator_dem import dem_baseline

    with tempfile.TemporaryDirectory() as d:
        sig = dem_baseline(cache=Path(d))
        beds = sorted(Path(d).rglob("packing-*.h5"))
        bed = packing_digest(beds[0]) if len(beds) == 1 else None
    return {"digest": digest(sig), "deposition_digest": bed, "cpu": cpu_model(),
            "machine": platform.machine(), "python": sys.version.split()[0],
            "numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__,
            "threads": numba.config.NUMBA_NUM_THREADS, "numpy_simd": numpy_simd()}



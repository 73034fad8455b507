"""A cache of finished full runs, shared by the runs of several diagnoses.

A diagnosis of one scenario runs the same simulations whatever the recording: the baseline,
its replicate packings and every full-model search level (``crashdem.diagnosis.confirm``).
Only the confirmation runs depend on what the recording made the screening fit. A campaign
diagnosed recording by recording, or one recording diagnosed again with other options,
therefore repeats most of its runs; this cache keeps each finished result file once, under the
hash of what decides its signals, and gives it back instead of running it again.

Key (``run_key``)
    SHA-256 of the scenario's data (canonical JSON, sorted keys) without the fields that only
    name or place the output (``KEY_EXCLUDED``: the run's name and description, the output
    directory, whether PNG plots are drawn); the contents (SHA-256) of the files the scenario
    names (``soil.packing_file``, ``impactor.glider.mesh``); the Numba thread count the run
    uses (``scenario.threads``, 0 resolved to the threads Numba starts); and the fingerprint of
    the code (``code_fingerprint``: the sources of ``soil``, ``bodies``, ``coupling`` and the
    crashdem modules a run is built from, the numpy, numba, scipy and exudyn versions and the
    host CPU Numba compiles for). A scenario whose named file is missing has no key: it is run
    (and raises there as usual), never cached.
Entries
    ``<root>/<fingerprint>/<key>.h5``: a complete crashdem result, written by an atomic rename
    after its run finished (a killed run leaves no entry, only its own result in its output
    directory). An entry that cannot be opened or is not complete is removed and run again.
Hit
    The entry is copied to the requested output path and its stored scenario (``/scenario``)
    replaced by the requested one, so the file is the one the run would have written but for
    the provenance of the run that made it (start time, wall time) and the attributes
    ``run_cache_key`` / ``run_cache_entry``. Its channels are bit for bit the entry's, i.e. those
    of a run of that scenario with that code and thread count (``crashdem.run`` is
    deterministic: ``tests/crashdem/test_runcache.py``).

API
---
``run_key(scen) -> str | None``, ``code_fingerprint() -> str``, ``default_root() -> Path``
``RunCache(root)``: ``entry(scen)``, ``lookup(scen)``, ``run(scen, out_dir, ...)``,
``hits``, ``runs``, ``describe()``
``from_option(text) -> RunCache | None`` (``crashdem diagnose --run-cache``)
"""
from __future__ import annotations

import copy
import functools
import hashlib
import json
import os
import shutil
from pathlib import Path
from typing import Any

__all__ = ["RunCache", "run_key", "code_fingerprint", "default_root", "from_option",
           "KEY_EXCLUDED", "CODE", "OUTPUT_ONLY"]

#: scenario fields that do not shape a run's signals: they name or place its files
KEY_EXCLUDED: tuple[tuple[str, str], ...] = (
    ("scenario", "name"), ("scenario", "description"), ("output", "directory"),
    ("output", "plots"))
#: scenario fields naming files whose contents the run reads
FILE_FIELDS: tuple[str, ...] = ("soil.packing_file", "glider.mesh")

_ROOT = Path(__file__).resolve().parents[1]
#: sources whose change changes a run (the DEM, the body, the coupling, the run and the modules
#: of crashdem it builds a run from; ``beds`` places an imported bed and its layer)
CODE: tuple[str, ...] = (
    "soil", "bodies", "coupling", "crashdem/run.py", "crashdem/sensors.py",
    "crashdem/scenario.py", "crashdem/filters.py", "crashdem/beds.py", "crashdem/signal.py",
    "crashdem/glider.py")
#: modules of crashdem that the keyed ones import but that do not shape a run's signals: they
#: write, checkpoint, plot, export and report it, or check a channel's ISO code
#: (``tests/crashdem/diagnosis/test_concealed_dem.py``: every other module they import is in
#: ``CODE``)
OUTPUT_ONLY: tuple[str, ...] = ("checkpoint", "progress", "results", "plotting", "export",
                                "isomme")


@functools.lru_cache(maxsize=1)
def source_digest() -> bytes:
    """SHA-256 of the sources in ``CODE`` (read once per process: the imported code cannot
    change under a running process)."""
    h = hashlib.sha256()
    for rel in CODE:
        p = _ROOT / rel
        files = sorted(p.rglob("*.py")) if p.is_dir() else [p]
        for f in files:
            if f.exists():
                h.update(str(f.relative_to(_ROOT)).encode())
                h.update(f.read_bytes())
    return h.digest()


def _host_cpu() -> str:
    try:
        from llvmlite import binding as llvm

        return f"{llvm.get_host_cpu_name()}:{llvm.get_host_cpu_features().flatten()}"
    except Exception:  # noqa: BLE001 - no llvmlite binding: the platform's name instead
        import platform

        return platform.machine()


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """16 hex digits naming the code a run is made with: ``source_digest`` (the sources of
    ``CODE``), the versions of numpy, numba, scipy and exudyn and the host CPU Numba compiles
    for (its features decide the machine code, so a cache on a shared disk never mixes runs of
    two machine kinds)."""
    import numba
    import numpy as np
    import scipy

    try:
        import exudyn

        exu = str(getattr(exudyn, "__version__", "") or exudyn.GetVersionString())
    except Exception:  # noqa: BLE001 - the version string only
        exu = "?"
    h = hashlib.sha256(source_digest())
    h.update(json.dumps({"numpy": np.__version__, "numba": numba.__version__,
                         "scipy": scipy.__version__, "exudyn": exu, "cpu": _host_cpu(),
                         "format": 1}, sort_keys=True).encode())
    return h.hexdigest()[:16]


def _threads(scen: Any) -> int:
    n = scen["scenario.threads"]
    if n:
        return int(n)
    import numba

    return int(numba.config.NUMBA_NUM_THREADS)


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def run_key(scen: Any) -> str | None:
    """Cache key of a run of ``scen`` (see the module docstring), or None when a file the
    scenario names does not exist (such a run is not cached)."""
    data = copy.deepcopy(scen.data)
    for sect, key in KEY_EXCLUDED:
        if isinstance(data.get(sect), dict):
            data[sect].pop(key, None)
    files = {}
    for field in FILE_FIELDS:
        try:
            name = scen[field]
        except KeyError:
            continue
        if name:
            p = Path(name).expanduser()
            if not p.is_file():
                return None
            files[field] = _file_digest(p)
    text = json.dumps({"scenario": data, "files": files, "threads": _threads(scen)},
                      sort_keys=True, default=repr, allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:24]


def default_root() -> Path:
    """``$CRASHDEM_CACHE/runs``, else ``~/.cache/crashdem/runs`` (absolute)."""
    root = Path(os.environ.get("CRASHDEM_CACHE") or "~/.cache/crashdem") / "runs"
    return root.expanduser().absolute()


def from_option(text: str | None) -> RunCache | None:
    """The run cache of ``--run-cache``: None (the default) -> the user's (``default_root``),
    ``off`` -> no cache (every run is run), a directory -> that one."""
    if text is None:
        return RunCache(default_root())
    if text.strip().lower() in ("off", "none", ""):
        return None
    return RunCache(Path(text).expanduser().absolute())


def _rewrite_scenario(path: Path, scen: Any, key: str, entry: Path) -> None:
    """Give the copied result ``path`` the requested scenario and name the entry it came from."""
    import h5py

    from crashdem.results import write_scenario_group

    with h5py.File(path, "r+") as f:
        del f["scenario"]
        write_scenario_group(f, scen.to_toml(), getattr(scen, "text", "") or "", scen.data)
        f.attrs["run_cache_key"] = key
        f.attrs["run_cache_entry"] = str(entry)


class RunCache:
    """Finished runs under ``<root>/<code fingerprint>/<run key>.h5``.

    Parameters
    ----------
    root : directory of the cache (created on the first store)

    Attributes
    ----------
    directory : ``root / code_fingerprint()``
    hits : runs taken from the cache by this object
    runs : runs made (and stored) by this object
    """

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root).expanduser().absolute()
        self.directory = self.root / code_fingerprint()
        self.hits = 0
        self.runs = 0

    def __repr__(self) -> str:
        return f"RunCache({str(self.root)!r})"

    def __reduce__(self):  # a worker gets the root, not this process's counts
        return (RunCache, (str(self.root),))

    def entry(self, scen: Any) -> Path | None:
        """Where a run of ``scen`` is (or would be) kept; None when it has no key."""
        key = run_key(scen)
        return None if key is None else self.directory / f"{key}.h5"

    def lookup(self, scen: Any) -> Path | None:
        """The complete cached result of ``scen``, or None (a damaged entry is removed)."""
        e = self.entry(scen)
        if e is None or not e.is_file():
            return None
        try:
            from crashdem.results import open_result

            with open_result(e) as res:
                if res.complete:
                    return e
        except Exception:  # noqa: BLE001 - unreadable: not an entry
            pass
        try:
            e.unlink()
        except OSError:
            pass
        return None

    def run(self, scen: Any, out_dir: str | os.PathLike | None = None, *,
            progress: bool = False, plots: bool | None = None, keep: bool = True) -> Path:
        """``crashdem.run.run_scenario(scen, out_dir, ...)`` or its cached result.

        With ``keep`` (default) the result is at ``run_scenario``'s path, as a run would have
        written it (a hit is copied there; a run is copied into the cache). With
        ``keep=False`` the path returned may be the cache entry itself (read it, do not write
        it) and a fresh run is moved into the cache.
        """
        from crashdem.run import default_output, output_lock, run_scenario

        e = self.lookup(scen)
        if e is not None:
            self.hits += 1
            if not keep:
                return e
            path = default_output(scen, out_dir)
            path.parent.mkdir(parents=True, exist_ok=True)
            with output_lock(path):
                tmp = path.with_name(f".{path.name}.pid{os.getpid()}.tmp")
                shutil.copyfile(e, tmp)
                _rewrite_scenario(tmp, scen, e.stem, e)
                os.replace(tmp, path)
            if plots if plots is not None else scen["output.plots"]:
                from crashdem.plotting import plot_result

                plot_result(path, path.with_suffix(""))
            return path
        path = run_scenario(scen, out_dir=out_dir, progress=progress, plots=plots)
        self.runs += 1
        e = self.entry(scen)
        if e is None:
            return path
        e.parent.mkdir(parents=True, exist_ok=True)
        tmp = e.with_name(f".{e.name}.pid{os.getpid()}.tmp")
        if keep:
            shutil.copyfile(path, tmp)
            os.replace(tmp, e)
            return path
        if path.parent.stat().st_dev == e.parent.stat().st_dev:
            os.replace(path, e)
        else:  # another file system: copied next to the entry first, then renamed
            shutil.move(str(path), tmp)
            os.replace(tmp, e)
        return e

    def describe(self) -> dict[str, Any]:
        """What a report records: the directory, the runs taken from it and those made."""
        return {"directory": str(self.directory), "hits": self.hits, "runs": self.runs}

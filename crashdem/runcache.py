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

Size and eviction
    Nothing is evicted unless asked. ``crashdem cache prune`` (``prune``) removes entries of
    other code versions (``stale``), entries not used for some days (``older_than_s``) or the
    least recently used entries until the cache fits a size (``max_bytes``; other code
    versions' entries go first). With ``$CRASHDEM_RUN_CACHE_MAX`` set (e.g. ``20G``) every
    store prunes to that size. A hit refreshes its entry's modification time, which is the
    "last used" time. Entries used within ``GRACE_S`` (one hour) are never evicted: a
    diagnosis in progress reads the runs it made again (the DEM-truth runs are read from
    their entries), and a run another process is copying stays. A hit whose entry vanished
    between the lookup and the copy is run instead.

API
---
``run_key(scen) -> str | None``, ``code_fingerprint() -> str``, ``default_root() -> Path``
``RunCache(root, max_bytes=None)``: ``entry(scen)``, ``lookup(scen)``,
``run(scen, out_dir, ...)``, ``hits``, ``runs``, ``evicted``, ``describe()``
``from_option(text) -> RunCache | None`` (``crashdem diagnose --run-cache``)
``parse_size(text, field) -> int``, ``usage(root) -> dict``, ``prune(root, ...) -> dict``
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import json
import os
import re
import shutil
import time
from pathlib import Path
from typing import Any

__all__ = ["RunCache", "run_key", "code_fingerprint", "default_root", "from_option",
           "KEY_EXCLUDED", "CODE", "OUTPUT_ONLY", "MAX_ENV", "GRACE_S", "parse_size",
           "usage", "prune"]

#: environment variable holding the run cache's size cap (``parse_size``); unset: no cap
MAX_ENV = "CRASHDEM_RUN_CACHE_MAX"
#: an entry used (stored or hit) this recently [s] is never evicted
GRACE_S = 3600.0

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


_UNITS = {"": 1, "b": 1, "k": 10**3, "kb": 10**3, "kib": 2**10, "m": 10**6, "mb": 10**6,
          "mib": 2**20, "g": 10**9, "gb": 10**9, "gib": 2**30, "t": 10**12, "tb": 10**12,
          "tib": 2**40}


def parse_size(text: str | int | float, field: str = "size") -> int:
    """Bytes of a size such as ``500M``, ``20G``, ``1.5GiB`` or ``1000000`` (k, M, G, T:
    powers of 1000; KiB, MiB, GiB, TiB: of 1024). A value that is not a size of at least one
    byte raises ``ValueError`` naming ``field``."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value, unit = float(text), ""
    else:
        m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([A-Za-z]*)\s*",
                         str(text))
        if m is None or m.group(2).lower() not in _UNITS:
            raise ValueError(f"{field}: {text!r} is not a size; give bytes or a number with "
                             "k, M, G, T (x1000) or KiB, MiB, GiB, TiB (x1024), e.g. 20G")
        value, unit = float(m.group(1)), m.group(2).lower()
    size = value * _UNITS[unit]
    if not (size >= 1 and size < 2**63):
        raise ValueError(f"{field}: {text!r} is out of range; allowed: 1 byte to 8 EiB")
    return int(size)


def _max_from_env() -> int | None:
    text = os.environ.get(MAX_ENV, "").strip()
    return parse_size(text, f"${MAX_ENV}") if text else None


@dataclasses.dataclass(frozen=True)
class Tree:
    """A cache laid out as ``<root>/<code fingerprint>/<entry>``: the run cache
    (:func:`run_tree`) and the shared packing cache of the diagnoses (:func:`packing_tree`).

    ``current``: the fingerprint of this code's entries; ``pattern``: the entries' file names;
    ``temporary``: left-overs of killed writes; ``companions``: suffixes of files that belong
    to an entry (removed with it: a bed's build lock)."""

    root: Path
    current: str
    pattern: str = "*.h5"
    temporary: tuple[str, ...] = (".*.tmp",)
    companions: tuple[str, ...] = ()


def run_tree(root: str | os.PathLike) -> Tree:
    """The run cache under ``root`` (``<root>/<code_fingerprint()>/<run key>.h5``)."""
    return Tree(Path(root).expanduser().absolute(), code_fingerprint())


def packing_tree(root: str | os.PathLike) -> Tree:
    """The packing cache under ``root`` (``<root>/<soil.packing.code_fingerprint()>/
    packing-<spec hash>.h5``, ``crashdem.run.packing_cache``), with each bed's build lock."""
    from soil.packing import code_fingerprint as soil_fingerprint

    return Tree(Path(root).expanduser().absolute(), soil_fingerprint(), "packing-*.h5",
                ("packing-*.h5.tmp*",), (".lock",))


def _entries(root: Path, pattern: str = "*.h5") -> list[tuple[Path, int, float]]:
    """Every ``<root>/<fingerprint>/<pattern>``: (path, bytes, last use), vanished ones left
    out."""
    out = []
    if not root.is_dir():
        return out
    for d in root.iterdir():
        if not d.is_dir():
            continue
        for f in d.glob(pattern):
            try:
                st = f.stat()
            except OSError:
                continue
            out.append((f, st.st_size, st.st_mtime))
    return out


def usage(root: str | os.PathLike | Tree) -> dict[str, Any]:
    """What the cache under ``root`` (a run cache, or any :class:`Tree`) holds, per code
    version: entries, bytes, the newest and oldest use (Unix time), and which version is this
    code's (``current``)."""
    tree = root if isinstance(root, Tree) else run_tree(root)
    current = tree.current
    versions: dict[str, dict[str, Any]] = {}
    for f, size, used in _entries(tree.root, tree.pattern):
        v = versions.setdefault(f.parent.name, {"entries": 0, "bytes": 0, "newest_use": used,
                                                "oldest_use": used,
                                                "current": f.parent.name == current})
        v["entries"] += 1
        v["bytes"] += size
        v["newest_use"] = max(v["newest_use"], used)
        v["oldest_use"] = min(v["oldest_use"], used)
    return {"root": str(tree.root), "current": current, "versions": versions,
            "entries": sum(v["entries"] for v in versions.values()),
            "bytes": sum(v["bytes"] for v in versions.values())}


def prune(root: str | os.PathLike | Tree | list[Tree], *, max_bytes: int | None = None,
          stale: bool = False, older_than_s: float | None = None, grace_s: float = GRACE_S,
          protect: tuple[Path, ...] = (), dry_run: bool = False,
          now: float | None = None) -> dict[str, Any]:
    """Evict cache entries under ``root``: a run cache's directory, a :class:`Tree`, or a list
    of them pruned as one (``max_bytes`` then caps their total).

    ``stale``: every entry of another code version; ``older_than_s``: every entry not used for
    that long; ``max_bytes``: then the least recently used entries, other code versions' first,
    until the rest fits. An entry used within ``grace_s`` or named in ``protect`` stays
    whatever the criteria, so the cache can stay above ``max_bytes`` (``over_bytes``).
    Left-over temporary files of killed writes older than ``grace_s`` are removed, and code
    version directories left empty. ``dry_run`` removes nothing and reports the same.
    Returns ``{"removed": [paths], "freed_bytes", "kept_entries", "kept_bytes",
    "over_bytes"}``."""
    if max_bytes is not None and max_bytes < 0:
        raise ValueError(f"max_bytes: {max_bytes} is out of range; allowed: >= 0")
    if older_than_s is not None and older_than_s < 0:
        raise ValueError(f"older_than_s: {older_than_s} is out of range; allowed: >= 0")
    if isinstance(root, list):
        trees = root
    else:
        trees = [root if isinstance(root, Tree) else run_tree(root)]
    now = time.time() if now is None else now
    keep = {Path(p).absolute() for p in protect}
    items = []  # (path, bytes, last use, of this code, tree)
    for tree in trees:
        items += [(f, size, used, f.parent.name == tree.current, tree)
                  for f, size, used in _entries(tree.root, tree.pattern)]
    items.sort(key=lambda e: (e[3], e[2], str(e[0])))
    removed: list[tuple[Path, int, Tree]] = []
    kept: list[tuple[Path, int, float, Tree]] = []

    def evictable(f: Path, used: float) -> bool:
        return f.absolute() not in keep and now - used >= grace_s

    total = sum(e[1] for e in items)
    for f, size, used, current, tree in items:  # first the criteria of their own
        if evictable(f, used) and ((stale and not current)
                                   or (older_than_s is not None and now - used >= older_than_s)):
            removed.append((f, size, tree))
            total -= size
        else:
            kept.append((f, size, used, tree))
    if max_bytes is not None:  # then the least recently used, other versions first
        rest = []
        for f, size, used, tree in kept:
            if total > max_bytes and evictable(f, used):
                removed.append((f, size, tree))
                total -= size
            else:
                rest.append((f, size, used, tree))
        kept = rest
    if not dry_run:
        for f, _, tree in removed:
            for g in (f, *(f.with_suffix(c) for c in tree.companions)):
                try:
                    g.unlink()
                except FileNotFoundError:
                    pass
        for tree in trees:
            if not tree.root.is_dir():
                continue
            for d in tree.root.iterdir():
                if not d.is_dir():
                    continue
                for t in (t for pat in tree.temporary for t in d.glob(pat)):
                    try:
                        if now - t.stat().st_mtime >= grace_s:
                            t.unlink()
                    except OSError:
                        pass
                try:
                    d.rmdir()  # only when empty
                except OSError:
                    pass
    return {"removed": [str(f) for f, _, _ in removed],
            "freed_bytes": sum(size for _, size, _ in removed),
            "kept_entries": len(kept), "kept_bytes": total,
            "over_bytes": max(0, total - max_bytes) if max_bytes is not None else 0}


class RunCache:
    """Finished runs under ``<root>/<code fingerprint>/<run key>.h5``.

    Parameters
    ----------
    root : directory of the cache (created on the first store)
    max_bytes : size cap: every store then evicts the least recently used entries beyond it
        (``prune``); None (default) reads ``$CRASHDEM_RUN_CACHE_MAX`` (``parse_size``; unset:
        no cap)

    Attributes
    ----------
    directory : ``root / code_fingerprint()``
    hits : runs taken from the cache by this object
    runs : runs made (and stored) by this object
    evicted : entries this object's stores evicted
    """

    def __init__(self, root: str | os.PathLike, max_bytes: int | None = None) -> None:
        self.root = Path(root).expanduser().absolute()
        self.directory = self.root / code_fingerprint()
        self.max_bytes = _max_from_env() if max_bytes is None else parse_size(max_bytes,
                                                                               "max_bytes")
        self.hits = 0
        self.runs = 0
        self.evicted = 0

    def __repr__(self) -> str:
        return f"RunCache({str(self.root)!r})"

    def __reduce__(self):  # a worker gets the root and the cap, not this process's counts
        return (RunCache, (str(self.root), self.max_bytes))

    def _stored(self, e: Path) -> None:
        if self.max_bytes is not None:
            self.evicted += len(prune(self.root, max_bytes=self.max_bytes,
                                      protect=(e,))["removed"])

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
            try:
                try:
                    os.utime(e)  # its last use, the order of eviction
                except FileNotFoundError:
                    raise
                except OSError:  # a cache this user may read but not write
                    pass
                if not keep:
                    self.hits += 1
                    return e
                path = default_output(scen, out_dir)
                path.parent.mkdir(parents=True, exist_ok=True)
                with output_lock(path):
                    tmp = path.with_name(f".{path.name}.pid{os.getpid()}.tmp")
                    try:
                        shutil.copyfile(e, tmp)
                    except FileNotFoundError:
                        tmp.unlink(missing_ok=True)
                        raise
                    _rewrite_scenario(tmp, scen, e.stem, e)
                    os.replace(tmp, path)
            except FileNotFoundError:  # evicted by another process meanwhile: run it
                e = None
        if e is not None:
            self.hits += 1
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
            self._stored(e)
            return path
        if path.parent.stat().st_dev == e.parent.stat().st_dev:
            os.replace(path, e)
        else:  # another file system: copied next to the entry first, then renamed
            shutil.move(str(path), tmp)
            os.replace(tmp, e)
        self._stored(e)
        return e

    def describe(self) -> dict[str, Any]:
        """What a report records: the directory, the runs taken from it and those made (and,
        with a size cap, the cap and the entries evicted)."""
        d = {"directory": str(self.directory), "hits": self.hits, "runs": self.runs}
        if self.max_bytes is not None:
            d.update(max_bytes=self.max_bytes, evicted=self.evicted)
        return d

"""HDF5 results: incremental, flushed writer and the post-processing reader.

API
---
Writing (``ResultWriter``; the layout is documented in ``docs/results_schema.md``)::

    with ResultWriter(path, scenario_toml=text, parameters=scen_dict, seed=1, threads=2,
                      default_cfc=60.0) as w:          # status "running", provenance written
        w.declare_sensors(sensor_set)                  # or w.declare_channel(name, unit, fs, ...)
        w.declare_energy(["kinetic_translational", ...])    # optional (first append also declares)
        w.declare_snapshots(radius, velocities=False)  # optional, before the run starts
    ...
    w = ResultWriter.resume(path, t_checkpoint, sensor_set=restored_set)   # after a crash
        loop:
            w.append_sensors(sensor_set)               # = w.append_samples(sensor_set.drain())
            w.append_energy(t, sim.energy())
            w.write_snapshot(t, x, v=None)
            w.flush()                                  # optional; automatic every flush_every
    # on leaving the block: filtered channels written, status "complete" (or "failed" + error)

Declare before the run where possible: the first flush switches the file to HDF5 SWMR mode
(single writer, multiple readers), in which HDF5's crash-consistency guarantee covers appends to
existing datasets. Later declarations (e.g. an energy ledger auto-declared by its first row
after a flush) are still accepted: the HDF5 2.0 library used here creates objects in SWMR mode,
and the SIGKILL test covers such a late dataset; ``strict_swmr=True`` refuses them. Appends are
buffered and written + flushed when ``flush_every`` samples are buffered, when
``flush_seconds`` of wall time have passed since the last flush, or on ``flush()``; everything
flushed survives a SIGKILL of the writer (the file is reopened with ``swmr=True`` by
``open_result`` when the writer died). ``close(error=None)`` writes the filtered channels, the
end time and wall time and sets ``attrs["complete"]`` / ``attrs["status"]``.

Reading::

    res = open_result(path)           # -> Result (context manager)
    res.channels()                    # channel names, in declaration order
    res["rear_accel_x"]               # Signal, filtered if a CFC applies (= res.channel(name))
    res.channel(name, filtered=False) # raw Signal
    res.signals(filtered=True)        # dict name -> Signal
    res.filter(name, cfc=180)         # Signal filtered now (crashdem.filters.cfc_filter)
    res.resample(name, fs=1000)       # Signal on the grid t0 + k/fs
    res.energy()                      # dict term -> Signal [J]
    res.snapshot_times(); res.snapshot(i)   # particle snapshots
    res.parameters; res.scenario_toml; res.provenance; res.status; res.complete
    res.summary()                     # text for ``crashdem info``
    res.plot(out_dir=None)            # PNGs (crashdem.plotting.plot_result)
    compare(res_a, res_b, channels=None)    # dict name -> ChannelComparison

Notes
-----
HDF5 SWMR: The HDF Group, "Single-Writer/Multiple-Reader (SWMR) User's Guide" (h5py
``File.swmr_mode``). Filtering: SAE J211-1 Appendix C via ``crashdem.filters``. ISO-MME filter
letters (last character of the channel code): ISO/TS 13499 (anchors.md section 3).
"""
from __future__ import annotations

import datetime as _dt
import importlib.metadata
import json
import math
import os
import platform
import socket
import subprocess
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import h5py
import numpy as np

from crashdem.signal import Signal

__all__ = [
    "ChannelComparison",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "Result",
    "ResultWriter",
    "compare",
    "iso_code_for_cfc",
    "open_result",
    "provenance",
]

FORMAT_NAME = "crashdem-result"
FORMAT_VERSION = 1
STATUSES = ("running", "complete", "failed")
#: ISO/TS 13499 filter-class letter (16th character of a channel code) by CFC
#: (anchors.md section 3: A CFC1000, B CFC600, C CFC180, D CFC60, L CFC20, 0 unfiltered)
ISO_FILTER_LETTER = {1000.0: "A", 600.0: "B", 180.0: "C", 60.0: "D", 20.0: "L"}
_SNAPSHOT_DTYPES = ("float32", "float64")


# --------------------------------------------------------------------------------------------
# provenance
# --------------------------------------------------------------------------------------------
def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def _git_hash() -> str:
    """Commit hash of the checkout holding the crashdem sources, or 'unknown'."""
    src = Path(__file__).resolve().parent
    # read-only queries; --no-optional-locks keeps `git status` from refreshing (writing) the
    # index, so a run never contends with a concurrent commit in the same checkout
    env = dict(os.environ, GIT_OPTIONAL_LOCKS="0")
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=src, capture_output=True,
                             text=True, timeout=10, check=False, env=env)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    h = out.stdout.strip()
    if out.returncode != 0 or not h:
        return "unknown"
    try:
        dirty = subprocess.run(["git", "--no-optional-locks", "status", "--porcelain",
                                "--untracked-files=no"], cwd=src, capture_output=True,
                               text=True, timeout=10, check=False, env=env).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        dirty = ""
    return h + ("-dirty" if dirty else "")


def _utc_now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def provenance(seed: int | None = None, threads: int | None = None) -> dict[str, Any]:
    """Software and machine provenance stored at the file root.

    Returns crashdem, python, numpy, scipy, numba, exudyn, h5py and HDF5 versions, the git hash
    (``'unknown'`` outside a git checkout, ``-dirty`` suffix for uncommitted changes), hostname,
    platform, seed (-1 = none) and thread count (numba's current setting when not given).
    """
    import crashdem
    import numba

    if threads is None:
        threads = int(numba.get_num_threads())
    return {
        "crashdem_version": getattr(crashdem, "__version__", None) or _version("crashdem"),
        "git_hash": _git_hash(),
        "python_version": platform.python_version(),
        "numpy_version": np.__version__,
        "scipy_version": _version("scipy"),
        "numba_version": numba.__version__,
        "exudyn_version": _version("exudyn"),
        "h5py_version": h5py.version.version,
        "hdf5_version": h5py.version.hdf5_version,
        "hostname": socket.gethostname(),
        "platform": platform.platform(),
        "seed": -1 if seed is None else int(seed),
        "threads": int(threads),
    }


# --------------------------------------------------------------------------------------------
# parameters <-> nested groups
# --------------------------------------------------------------------------------------------
def _write_params(group: h5py.Group, params: Mapping[str, Any]) -> None:
    for key, value in params.items():
        if isinstance(value, Mapping):
            _write_params(group.create_group(str(key)), value)
        elif value is None:
            group.attrs[str(key)] = h5py.Empty("f8")
        elif isinstance(value, str):
            group.attrs[str(key)] = value
        elif isinstance(value, (list, tuple)):
            if all(isinstance(v, str) for v in value):
                group.attrs[str(key)] = np.array(value, dtype=h5py.string_dtype())
                group.attrs.create(f"{key}.__list__", True)
            else:
                group.attrs[str(key)] = np.asarray(value, dtype=float)
                group.attrs.create(f"{key}.__list__", True)
        elif isinstance(value, (bool, np.bool_)):
            group.attrs[str(key)] = np.bool_(value)
        elif isinstance(value, (int, float, np.integer, np.floating)):
            group.attrs[str(key)] = value
        else:
            group.attrs[str(key)] = json.dumps(value, default=str)


def _attr_value(v: Any) -> Any:
    if isinstance(v, h5py.Empty):
        return None
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    if isinstance(v, np.ndarray):
        return [_attr_value(x) for x in v.tolist()] if v.dtype.kind in "OSU" else v.tolist()
    return v


def write_scenario_group(f: h5py.File, scenario_toml: str | None, source_toml: str,
                         parameters: Mapping[str, Any] | None) -> None:
    """Write ``/scenario`` of a result: the full scenario text (``config_toml``), the text it
    was loaded from (``source_toml``) and the parsed scenario (``parameters``)."""
    sc = f.create_group("scenario")
    sc.create_dataset("config_toml", data=scenario_toml or "", dtype=h5py.string_dtype())
    sc["config_toml"].attrs["unit"] = "1"
    sc.create_dataset("source_toml", data=source_toml, dtype=h5py.string_dtype())
    sc["source_toml"].attrs["unit"] = "1"
    _write_params(sc.create_group("parameters"), parameters or {})


def _read_params(group: h5py.Group) -> dict[str, Any]:
    out: dict[str, Any] = {}
    lists = {k[: -len(".__list__")] for k in group.attrs if k.endswith(".__list__")}
    for key, value in group.attrs.items():
        if key.endswith(".__list__"):
            continue
        v = _attr_value(value)
        if key in lists and not isinstance(v, list):
            v = [v]
        out[key] = v
    for key, sub in group.items():
        if isinstance(sub, h5py.Group):
            out[key] = _read_params(sub)
    return out


def iso_code_for_cfc(code: str, cfc: float | None) -> str:
    """ISO-MME channel code with its 16th character set to the filter class of ``cfc``.

    ``None`` -> '0' (unfiltered); 1000/600/180/60/20 -> A/B/C/D/L; any other class -> 'S'
    (special). Notes: ISO/TS 13499 filter-class field (anchors.md section 3).
    """
    if len(code) != 16:
        raise ValueError(f"iso code {code!r}: must have 16 characters")
    try:
        from crashdem.isomme import cfc_to_letter
    except ImportError:  # pragma: no cover - isomme is part of the package
        return code[:15] + ("0" if cfc is None else ISO_FILTER_LETTER.get(float(cfc), "S"))
    return code[:15] + cfc_to_letter(cfc)


def _default_iso_code(name: str) -> str:
    """ISO code of a well-known crashdem channel name (``crashdem.isomme.CRASHDEM_CODES``)."""
    try:
        from crashdem.isomme import CRASHDEM_CODES
    except ImportError:  # pragma: no cover
        return ""
    return CRASHDEM_CODES.get(name, "")


def _j211_sign(code: str, meta: Mapping[str, Any]) -> int:
    """+1 / -1 when the channel's body-frame direction is the J211 axis named by the ISO code's
    direction letter (X, Y, Z) / its opposite; 0 when unknown (no code, other letter, world
    frame, oblique axis). A -1 channel must be negated for an ISO-MME (J211-signed) export.

    Notes
    -----
    J211 axes in crashdem body axes: x forward, y = -y_crashdem (right), z = -z_crashdem (down)
    (``crashdem.sensors.j211_axis``).
    """
    direction = meta.get("direction")
    if not code or len(code) != 16 or code[14] not in "XYZ" or direction is None \
            or meta.get("frame") != "body":
        return 0
    from crashdem.sensors import j211_axis

    dot = float(np.dot(np.asarray(direction, dtype=float), j211_axis(code[14])))
    return int(round(dot)) if abs(abs(dot) - 1.0) < 1e-9 else 0


def _decode(v: Any) -> Any:
    return v.decode() if isinstance(v, bytes) else v


# --------------------------------------------------------------------------------------------
# writer
# --------------------------------------------------------------------------------------------
class ResultWriter:
    """Incremental HDF5 writer of one run (see module docstring and docs/results_schema.md).

    Parameters
    ----------
    path : output file (overwritten)
    scenario : a ``crashdem.scenario.Scenario``; sets ``scenario_toml`` (its ``to_toml()``, every
        field with defaults and overrides applied), ``parameters`` (its ``data``) and the
        source text (``/scenario/source_toml``) unless those are given explicitly
    scenario_toml : full scenario text (stored verbatim in ``/scenario/config_toml``)
    parameters : parsed scenario (nested dict; stored as nested groups with attributes)
    seed : random seed of the run (None -> -1)
    threads : thread count (None -> numba's current setting)
    title : free title
    default_cfc : CFC [Hz] for channels that declare none (None: such channels stay raw)
    flush_every : buffered samples per channel that trigger a write + flush (> 0)
    flush_seconds : wall time [s] after which an append triggers a write + flush (> 0)
    snapshot_dtype : "float32" (default; 7 significant digits, ~0.1 um on a 1 m bed) or
        "float64" (bit-exact restart-quality positions)
    compression : gzip level for snapshots, 0-9
    swmr : switch to HDF5 SWMR mode at the first flush (crash-consistent appends)
    strict_swmr : refuse declarations after the first flush (RuntimeError)
    """

    def __init__(self, path: str | os.PathLike, *, scenario: Any = None,
                 scenario_toml: str | None = None,
                 parameters: Mapping[str, Any] | None = None, seed: int | None = None,
                 threads: int | None = None, title: str = "", default_cfc: float | None = None,
                 flush_every: int = 1250, flush_seconds: float = 5.0,
                 snapshot_dtype: str = "float32", compression: int = 4,
                 swmr: bool = True, strict_swmr: bool = False) -> None:
        if not (isinstance(flush_every, int) and flush_every > 0):
            raise ValueError(f"ResultWriter.flush_every={flush_every!r}: must be an int > 0 "
                             "[samples]")
        if not (flush_seconds > 0):
            raise ValueError(f"ResultWriter.flush_seconds={flush_seconds!r}: must be > 0 [s]")
        if snapshot_dtype not in _SNAPSHOT_DTYPES:
            raise ValueError(f"ResultWriter.snapshot_dtype={snapshot_dtype!r}: must be one of "
                             f"{_SNAPSHOT_DTYPES}")
        if not (isinstance(compression, int) and 0 <= compression <= 9):
            raise ValueError(f"ResultWriter.compression={compression!r}: must be an int in "
                             "[0, 9]")
        if default_cfc is not None and not (default_cfc > 0):
            raise ValueError(f"ResultWriter.default_cfc={default_cfc!r}: must be > 0 [Hz] or None")
        source_toml = ""
        if scenario is not None:
            if scenario_toml is None:
                scenario_toml = scenario.to_toml()
            if parameters is None:
                parameters = scenario.data
            source_toml = getattr(scenario, "text", "") or ""
        self.path = Path(path)
        self.default_cfc = default_cfc
        self.flush_every = flush_every
        self.flush_seconds = float(flush_seconds)
        self.snapshot_dtype = snapshot_dtype
        self.compression = compression
        self.swmr = swmr
        self.strict_swmr = strict_swmr
        self._t_wall0 = time.perf_counter()
        self._last_flush = time.monotonic()
        self._started = False
        self._closed = False
        self._chan_buf: dict[str, tuple[list[np.ndarray], list[np.ndarray]]] = {}
        self._chan_last: dict[str, float] = {}
        self._energy_last = -math.inf
        self._energy_terms: list[str] | None = None
        self._energy_buf: list[tuple[float, dict[str, float]]] = []
        self._snap_declared = False
        self._snap_velocities = False
        self._sensor_sets: list[Any] = []
        self._f = h5py.File(self.path, "w", libver="latest", track_order=True)
        f = self._f
        f.attrs["format"] = FORMAT_NAME
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["title"] = title
        f.attrs["status"] = "running"
        f.attrs["complete"] = False
        f.attrs["error"] = ""
        f.attrs["start_time"] = _utc_now()
        f.attrs["end_time"] = ""
        f.attrs["wall_time"] = np.nan
        f.attrs["wall_time.unit"] = "s"
        for k, v in provenance(seed, threads).items():
            f.attrs[k] = v
        write_scenario_group(f, scenario_toml, source_toml, parameters)
        f.create_group("channels", track_order=True)
        f.flush()

    # ------------------------------------------------------------------ resume
    @classmethod
    def resume(cls, path: str | os.PathLike, t_resume: float, sensor_set: Any = None,
               **kwargs: Any) -> "ResultWriter":
        """Continue a run that stopped (killed, failed) from a checkpoint at ``t_resume``.

        The readable content of ``path`` (also a killed SWMR file) is copied into a fresh file
        that then replaces ``path``: scenario, declarations, channel samples up to the cut,
        energy rows and snapshots with ``t <= t_resume``. The returned writer is ready for
        appends (SWMR mode); the root keeps the original ``start_time`` as
        ``first_start_time`` and lists the restarts in ``resumed_at`` [s].

        Parameters
        ----------
        path : the result file of the interrupted run
        t_resume : simulation time of the checkpoint [s]
        sensor_set : the ``SensorSet`` restored from the same checkpoint; when given, channel
            samples are kept up to its last drained sample (its undrained samples will be
            appended by the resumed loop), otherwise up to ``t_resume``
        **kwargs : ResultWriter options (flush_every, default_cfc, ...; ``seed``/``threads``
            default to the original run's)
        """
        path = Path(path)
        old = open_result(path)
        try:
            prov = old.provenance
            tmp = path.with_name(path.name + ".resume.tmp")
            kwargs.setdefault("seed", None if prov.get("seed", -1) == -1 else prov["seed"])
            kwargs.setdefault("threads", prov.get("threads"))
            kwargs.setdefault("title", prov.get("title", ""))
            f_old = old._f
            if "snapshots" in f_old:
                kwargs.setdefault("snapshot_dtype",
                                  _decode(f_old["snapshots"].attrs["position_dtype"]))
            w = cls(tmp, scenario_toml=old.scenario_toml, parameters=old.parameters, **kwargs)
            src = f_old["scenario"].get("source_toml")
            if src is not None:
                w._f["scenario/source_toml"][()] = _decode(src[()])
            w._f.attrs["first_start_time"] = prov.get("first_start_time", prov["start_time"])
            w._f.attrs["resumed_at"] = np.append(
                np.asarray(prov.get("resumed_at", []), dtype=float), float(t_resume))
            t_cut = float(t_resume)
            if sensor_set is not None:
                n_done = int(getattr(sensor_set, "_drained", 0))
                t_cut = float(sensor_set._t_samples[n_done - 1]) if n_done else -math.inf
            for name in old.channels():
                g = f_old["channels"][name]
                meta = json.loads(g.attrs["meta"])
                meta["cfc_class"] = _attr_value(g.attrs["cfc_class"])
                meta["iso_code"] = _decode(g.attrs["iso_code"])
                w.declare_channel(name, _decode(g.attrs["unit"]), float(g.attrs["sample_rate"]),
                                  float(g.attrs["t0"]), **meta)
                raw = _raw_signal(name, g)
                keep = raw.t <= t_cut
                w.append_channel(name, raw.t[keep], raw.data[keep])
            if sensor_set is not None:
                w._sensor_sets.append(sensor_set)
            ledger = old.energy()
            if ledger:
                w.declare_energy(list(ledger))
                t_e = next(iter(ledger.values())).t
                for i in np.flatnonzero(t_e <= t_resume):
                    w.append_energy(t_e[i], {k: sig.data[i] for k, sig in ledger.items()})
            if "snapshots" in f_old:
                gs = f_old["snapshots"]
                w.declare_snapshots(gs["radius"][:], velocities="v" in gs)
                for i, ts in enumerate(old.snapshot_times()):
                    if ts <= t_resume:
                        w.write_snapshot(ts, gs["x"][i], gs["v"][i] if "v" in gs else None)
        finally:
            old.close()
        w.flush()
        os.replace(tmp, path)  # the open file descriptor follows the rename (POSIX)
        w.path = path
        return w

    # ------------------------------------------------------------------ declarations
    def _check_declarable(self, what: str) -> None:
        if self._closed:
            raise RuntimeError(f"ResultWriter: cannot declare {what}: file already closed")
        if self._started and self.swmr and self.strict_swmr:
            raise RuntimeError(f"ResultWriter: cannot declare {what} after the first flush "
                               "(SWMR mode allows appends only); declare it before the run")

    def declare_channel(self, name: str, unit: str, sample_rate: float, t0: float = 0.0,
                        **meta: Any) -> None:
        """Create the datasets of one channel.

        Parameters
        ----------
        name : channel name (no '/')
        unit : SI unit string of the raw data
        sample_rate : acquisition rate [Hz]
        t0 : time origin of the sample grid [s]
        **meta : iso_code, position (3, m), direction (3), cfc_class (Hz), kind, body, ... any
            JSON-serialisable metadata (all of it is kept in ``attrs["meta"]`` as JSON)
        """
        self._check_declarable(f"channel {name!r}")
        if not name or "/" in name:
            raise ValueError(f"channel name {name!r}: must be non-empty without '/'")
        if name in self._f["channels"]:
            raise ValueError(f"channel {name!r}: already declared")
        if not (sample_rate > 0):
            raise ValueError(f"channel {name!r}: sample_rate={sample_rate!r} must be > 0 [Hz]")
        g = self._f["channels"].create_group(name)
        g.attrs["unit"] = unit
        g.attrs["sample_rate"] = float(sample_rate)
        g.attrs["t0"] = float(t0)
        g.attrs["kind"] = str(meta.get("kind", ""))
        g.attrs["iso_code"] = str(meta.get("iso_code") or _default_iso_code(name))
        g.attrs["position"] = np.asarray(meta.get("position", [np.nan] * 3), dtype=float)
        g.attrs["direction"] = np.asarray(meta.get("direction", [np.nan] * 3), dtype=float)
        cfc = meta.get("cfc_class", self.default_cfc)
        g.attrs["cfc_class"] = h5py.Empty("f8") if cfc is None else float(cfc)
        g.attrs["j211_sign"] = _j211_sign(g.attrs["iso_code"], meta)
        g.attrs["meta"] = json.dumps(meta, default=str)
        chunk = max(256, min(self.flush_every, 65536))
        dt = g.create_dataset("t", shape=(0,), maxshape=(None,), chunks=(chunk,), dtype="f8")
        dt.attrs["unit"] = "s"
        raw = g.create_dataset("raw", shape=(0,), maxshape=(None,), chunks=(chunk,), dtype="f8")
        raw.attrs["unit"] = unit
        raw.attrs["cfc"] = 0.0
        raw.attrs["iso_code"] = iso_code_for_cfc(g.attrs["iso_code"], None) \
            if g.attrs["iso_code"] else ""
        self._chan_buf[name] = ([], [])
        self._chan_last[name] = -math.inf

    def declare_sensors(self, sensor_set: Any) -> None:
        """Declare every channel of a ``crashdem.sensors.SensorSet`` (its ``channel_info()``)."""
        self._sensor_sets.append(sensor_set)
        for name, info in sensor_set.channel_info().items():
            meta = dict(info)
            unit = meta.pop("unit")
            fs = meta.pop("sample_rate")
            t0 = meta.pop("t0", 0.0)
            self.declare_channel(name, unit, fs, t0, **meta)

    def declare_energy(self, terms: Iterable[str]) -> None:
        """Create the energy-ledger datasets (one per term, unit J, plus ``t``)."""
        self._check_declarable("the energy ledger")
        if self._energy_terms is not None:
            raise ValueError("energy ledger already declared")
        terms = [str(t) for t in terms]
        g = self._f.create_group("energy", track_order=True)
        g.attrs["unit"] = "J"
        d = g.create_dataset("t", shape=(0,), maxshape=(None,), chunks=(1024,), dtype="f8")
        d.attrs["unit"] = "s"
        for term in terms:
            d = g.create_dataset(term, shape=(0,), maxshape=(None,), chunks=(1024,), dtype="f8")
            d.attrs["unit"] = "J"
        self._energy_terms = terms

    def declare_snapshots(self, radius: np.ndarray, velocities: bool = False) -> None:
        """Create the particle-snapshot datasets (radii stored once).

        Parameters
        ----------
        radius : (N,) particle radii [m]
        velocities : also store particle velocities with each snapshot
        """
        self._check_declarable("particle snapshots")
        if self._snap_declared:
            raise ValueError("snapshots already declared")
        radius = np.asarray(radius, dtype=float)
        if radius.ndim != 1 or radius.size == 0:
            raise ValueError(f"declare_snapshots: radius shape {radius.shape}, must be (N,), N>0")
        n = radius.size
        g = self._f.create_group("snapshots")
        g.attrs["n_particles"] = n
        g.attrs["position_dtype"] = self.snapshot_dtype
        g.attrs["compression"] = f"gzip{self.compression}+shuffle"
        d = g.create_dataset("radius", data=radius)
        d.attrs["unit"] = "m"
        d = g.create_dataset("t", shape=(0,), maxshape=(None,), chunks=(64,), dtype="f8")
        d.attrs["unit"] = "s"
        comp = dict(compression="gzip", compression_opts=self.compression, shuffle=True) \
            if self.compression else {}
        d = g.create_dataset("x", shape=(0, n, 3), maxshape=(None, n, 3), chunks=(1, n, 3),
                             dtype=self.snapshot_dtype, **comp)
        d.attrs["unit"] = "m"
        if velocities:
            d = g.create_dataset("v", shape=(0, n, 3), maxshape=(None, n, 3), chunks=(1, n, 3),
                                 dtype=self.snapshot_dtype, **comp)
            d.attrs["unit"] = "m/s"
        self._snap_declared = True
        self._snap_velocities = velocities

    # ------------------------------------------------------------------ appends
    def append_channel(self, name: str, t: np.ndarray, data: np.ndarray) -> None:
        """Buffer samples of one declared channel (t [s], data [unit], equal length)."""
        if name not in self._chan_buf:
            raise KeyError(f"channel {name!r} not declared; declared: {list(self._chan_buf)}")
        t = np.atleast_1d(np.asarray(t, dtype=float))
        data = np.atleast_1d(np.asarray(data, dtype=float))
        if t.shape != data.shape or t.ndim != 1:
            raise ValueError(f"channel {name!r}: t {t.shape} and data {data.shape} must be 1-D "
                             "of equal length")
        if t.size:
            last = self._chan_last.get(name, -math.inf)
            if not (t[0] > last and np.all(np.diff(t) > 0)):
                raise ValueError(f"channel {name!r}: time must increase strictly across appends "
                                 f"(last written t={last!r} s, new t[0]={t[0]!r} s)")
            self._chan_last[name] = float(t[-1])
            bt, bd = self._chan_buf[name]
            bt.append(t)
            bd.append(data)
        self._maybe_flush()

    def append_samples(self, samples: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> None:
        """Buffer ``name -> (t, data)`` samples (the output of ``SensorSet.drain()``)."""
        for name, (t, data) in samples.items():
            self.append_channel(name, t, data)

    def append_sensors(self, sensor_set: Any) -> None:
        """Buffer the samples a ``SensorSet`` produced since the last call."""
        self.append_samples(sensor_set.drain())

    def append_energy(self, t: float, terms: Mapping[str, float]) -> None:
        """Buffer one energy-ledger row (t [s], term -> value [J]); the first call declares
        the terms if ``declare_energy`` was not called. A row at the same time as the previous
        one replaces it (e.g. a final row written after a periodic one at the last step); an
        earlier time raises ``ValueError``."""
        if self._energy_terms is None:
            self.declare_energy(list(terms))
        missing = [k for k in self._energy_terms if k not in terms]
        extra = [k for k in terms if k not in self._energy_terms]
        if missing or extra:
            raise ValueError(f"append_energy: terms differ from the declared ledger "
                             f"(missing {missing}, undeclared {extra})")
        t = float(t)
        row = (t, {k: float(terms[k]) for k in self._energy_terms})
        if t < self._energy_last:
            raise ValueError(f"append_energy: t={t!r} s is before the previous row "
                             f"(t={self._energy_last!r} s)")
        if t == self._energy_last:
            if self._energy_buf:
                self._energy_buf[-1] = row
            else:  # already on disk: overwrite the last row in place
                g = self._f["energy"]
                for k, v in row[1].items():
                    g[k][-1] = v
            return
        self._energy_last = t
        self._energy_buf.append(row)
        self._maybe_flush()

    def write_snapshot(self, t: float, x: np.ndarray, v: np.ndarray | None = None) -> None:
        """Write (and flush) one particle snapshot: positions x (N, 3) [m], velocities v."""
        if not self._snap_declared:
            raise RuntimeError("write_snapshot: call declare_snapshots(radius) first")
        g = self._f["snapshots"]
        n = int(g.attrs["n_particles"])
        x = np.asarray(x, dtype=float)
        if x.shape != (n, 3):
            raise ValueError(f"write_snapshot: x shape {x.shape}, must be ({n}, 3)")
        if self._snap_velocities:
            if v is None:
                raise ValueError("write_snapshot: velocities were declared; give v")
            v = np.asarray(v, dtype=float)
            if v.shape != (n, 3):
                raise ValueError(f"write_snapshot: v shape {v.shape}, must be ({n}, 3)")
        self.flush()  # enters SWMR mode and writes buffers first
        k = g["x"].shape[0]
        g["x"].resize((k + 1, n, 3))
        g["x"][k] = x
        if self._snap_velocities:
            g["v"].resize((k + 1, n, 3))
            g["v"][k] = v
        g["t"].resize((k + 1,))
        g["t"][k] = float(t)
        self._f.flush()

    # ------------------------------------------------------------------ flushing
    def _maybe_flush(self) -> None:
        n_buf = max((sum(a.size for a in bt) for bt, _ in self._chan_buf.values()), default=0)
        if (n_buf >= self.flush_every or len(self._energy_buf) >= self.flush_every
                or time.monotonic() - self._last_flush >= self.flush_seconds):
            self.flush()

    def _start(self) -> None:
        if not self._started:
            self._started = True
            if self.swmr:
                self._f.swmr_mode = True

    def flush(self) -> None:
        """Write the buffered samples and flush the file to disk."""
        if self._closed:
            raise RuntimeError("ResultWriter.flush: file already closed")
        self._start()
        chans = self._f["channels"]
        for name, (bt, bd) in self._chan_buf.items():
            if not bt:
                continue
            t = np.concatenate(bt)
            d = np.concatenate(bd)
            bt.clear()
            bd.clear()
            g = chans[name]
            k = g["t"].shape[0]
            # data first, time last: a reader trusts min(len(t), len(raw))
            g["raw"].resize((k + t.size,))
            g["raw"][k:] = d
            g["t"].resize((k + t.size,))
            g["t"][k:] = t
        if self._energy_buf:
            g = self._f["energy"]
            rows = self._energy_buf
            self._energy_buf = []
            k = g["t"].shape[0]
            for term in self._energy_terms:
                g[term].resize((k + len(rows),))
                g[term][k:] = [r[1][term] for r in rows]
            g["t"].resize((k + len(rows),))
            g["t"][k:] = [r[0] for r in rows]
        self._f.flush()
        self._last_flush = time.monotonic()

    # ------------------------------------------------------------------ closing
    def close(self, error: BaseException | str | None = None) -> Path:
        """Flush, write filtered channels and end-of-run provenance, mark complete or failed.

        Parameters
        ----------
        error : the exception (or message) the run failed with; None marks it complete

        Returns
        -------
        path of the file
        """
        if self._closed:
            return self.path
        try:
            self.flush()
        finally:
            self._f.close()
            self._closed = True
        with h5py.File(self.path, "r+") as f:
            # metadata learnt during the run (sensor failure times)
            for ss in self._sensor_sets:
                for name, info in ss.channel_info().items():
                    g = f["channels"][name]
                    meta = json.loads(g.attrs["meta"])
                    meta.update({k: v for k, v in info.items()
                                 if k not in ("unit", "sample_rate", "t0")})
                    g.attrs["meta"] = json.dumps(meta, default=str)
            if error is None:
                self._write_filtered(f)
            f.attrs["end_time"] = _utc_now()
            f.attrs["wall_time"] = time.perf_counter() - self._t_wall0
            if error is None:
                f.attrs["status"] = "complete"
                f.attrs["complete"] = True
                f.attrs["error"] = ""
            else:
                f.attrs["status"] = "failed"
                f.attrs["complete"] = False
                f.attrs["error"] = (error if isinstance(error, str)
                                    else f"{type(error).__name__}: {error}")
        return self.path

    def _write_filtered(self, f: h5py.File) -> None:
        for name, g in f["channels"].items():
            cfc = _attr_value(g.attrs["cfc_class"])
            if cfc is None:
                continue
            raw = _raw_signal(name, g)
            try:
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    filt = _filter_valid(raw, cfc)
            except (ValueError, ImportError) as exc:
                g.attrs["filter_error"] = f"{type(exc).__name__}: {exc}"
                continue
            if caught:
                g.attrs["filter_warning"] = "; ".join(str(w.message) for w in caught)
            d = g.create_dataset("filtered", data=filt.data, chunks=True)
            d.attrs["unit"] = filt.unit
            d.attrs["cfc"] = float(cfc)
            d.attrs["filter"] = json.dumps(filt.meta.get("filter", {}), default=str)
            code = g.attrs["iso_code"]
            d.attrs["iso_code"] = iso_code_for_cfc(code, cfc) if code else ""

    def __enter__(self) -> "ResultWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(error=exc)


# --------------------------------------------------------------------------------------------
# reader
# --------------------------------------------------------------------------------------------
def _raw_signal(name: str, g: h5py.Group) -> Signal:
    n = min(g["t"].shape[0], g["raw"].shape[0])
    meta = json.loads(g.attrs["meta"]) if "meta" in g.attrs else {}
    meta["iso_code"] = _decode(g["raw"].attrs.get("iso_code", "")) or meta.get("iso_code", "")
    meta["j211_sign"] = int(g.attrs.get("j211_sign", 0))
    meta.setdefault("sample_rate", float(g.attrs["sample_rate"]))
    return Signal(name, g["t"][:n], g["raw"][:n], _decode(g.attrs["unit"]), None, meta)


def _filter_valid(sig: Signal, cfc: float, **kwargs: Any) -> Signal:
    """CFC-filter the finite prefix of a channel (a failed sensor's NaN tail stays NaN)."""
    from crashdem.filters import cfc_filter

    finite = np.isfinite(sig.data)
    n_ok = sig.data.size if finite.all() else int(np.argmin(finite))
    if finite[n_ok:].any():
        raise ValueError(f"channel {sig.name!r}: NaN samples inside the record (not only a "
                         "failed tail); cannot filter")
    head = cfc_filter(Signal(sig.name, sig.t[:n_ok], sig.data[:n_ok], sig.unit, sig.cfc,
                             dict(sig.meta)), cfc=cfc, **kwargs)
    data = np.full_like(sig.data, np.nan)
    data[:n_ok] = head.data
    meta = dict(head.meta)
    if n_ok < sig.data.size:
        meta["filter"] = dict(meta.get("filter", {}), valid_samples=n_ok)
    if meta.get("iso_code"):
        meta["iso_code"] = iso_code_for_cfc(meta["iso_code"], cfc)
    return Signal(sig.name, sig.t.copy(), data, sig.unit, float(cfc), meta)


class Result:
    """Read access to one crashdem HDF5 result (see module docstring)."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        try:
            self._f = h5py.File(self.path, "r")
            self.opened_swmr = False
        except OSError as exc:
            # a writer killed in SWMR mode leaves the 'open for write' flag set; an SWMR reader
            # ignores it and sees everything up to the last flush
            try:
                self._f = h5py.File(self.path, "r", libver="latest", swmr=True)
            except OSError:
                raise OSError(f"{self.path}: cannot open as HDF5 ({exc})") from exc
            self.opened_swmr = True
        fmt = _decode(self._f.attrs.get("format", ""))
        if fmt != FORMAT_NAME:
            self._f.close()
            raise ValueError(f"{self.path}: attrs['format']={fmt!r}, expected {FORMAT_NAME!r}")

    # ------------------------------------------------------------------ metadata
    @property
    def status(self) -> str:
        """"running" (or killed), "complete" or "failed"."""
        return _decode(self._f.attrs["status"])

    @property
    def complete(self) -> bool:
        return bool(self._f.attrs["complete"])

    @property
    def error(self) -> str:
        return _decode(self._f.attrs.get("error", ""))

    @property
    def provenance(self) -> dict[str, Any]:
        """All root attributes (versions, git hash, seed, threads, times, status)."""
        return {k: _attr_value(v) for k, v in self._f.attrs.items()}

    @property
    def scenario_toml(self) -> str:
        return _decode(self._f["scenario/config_toml"][()])

    @property
    def parameters(self) -> dict[str, Any]:
        """The parsed scenario, as a nested dict."""
        return _read_params(self._f["scenario/parameters"])

    # ------------------------------------------------------------------ channels
    def channels(self) -> list[str]:
        """Channel names in declaration order."""
        return list(self._f["channels"].keys())

    def _group(self, name: str) -> h5py.Group:
        try:
            return self._f["channels"][name]
        except KeyError:
            raise KeyError(f"{self.path.name}: no channel {name!r}; channels: "
                           f"{self.channels()}") from None

    def cfc_class(self, name: str) -> float | None:
        """The CFC the channel is meant to be filtered with (None: shown raw)."""
        return _attr_value(self._group(name).attrs["cfc_class"])

    def channel(self, name: str, filtered: bool = True) -> Signal:
        """One channel as a ``Signal`` (SI units).

        ``filtered=True``: the stored filtered data if present, else filtered now with the
        channel's CFC class (a killed run has no stored filtered data), else raw when the
        channel has no CFC class or cannot be filtered (then ``Signal.cfc`` is None and
        ``meta["filter_error"]`` says why). ``filtered=False``: raw.
        """
        g = self._group(name)
        raw = _raw_signal(name, g)
        if not filtered:
            return raw
        if "filtered" in g:
            d = g["filtered"]
            n = min(raw.t.size, d.shape[0])
            meta = dict(raw.meta)
            meta["filter"] = json.loads(_decode(d.attrs["filter"]))
            meta["iso_code"] = _decode(d.attrs.get("iso_code", ""))
            return Signal(name, raw.t[:n], d[:n], _decode(d.attrs["unit"]),
                          float(d.attrs["cfc"]), meta)
        cfc = self.cfc_class(name)
        if cfc is None:
            return raw
        try:
            return _filter_valid(raw, cfc)
        except ValueError as exc:  # too few valid samples, fs too low for the class, ...
            raw.meta["filter_error"] = str(exc)
            return raw  # Signal.cfc stays None: visibly unfiltered

    def __getitem__(self, name: str) -> Signal:
        return self.channel(name, filtered=True)

    def signals(self, filtered: bool = True, channels: Sequence[str] | None = None
                ) -> dict[str, Signal]:
        """Several channels at once: name -> Signal (default: all channels)."""
        names = self.channels() if channels is None else list(channels)
        return {n: self.channel(n, filtered) for n in names}

    def __contains__(self, name: str) -> bool:
        return name in self._f["channels"]

    def filter(self, name: str, cfc: float, **kwargs: Any) -> Signal:
        """The raw channel filtered now with SAE J211 CFC ``cfc`` (kwargs to ``cfc_filter``)."""
        return _filter_valid(self.channel(name, filtered=False), cfc, **kwargs)

    def resample(self, name: str, fs: float, filtered: bool = True) -> Signal:
        """Channel linearly interpolated on ``t0 + k/fs`` inside its time range.

        Down-sampling a raw channel aliases; filter first (``filtered=True``, the default).
        """
        if not (fs > 0):
            raise ValueError(f"resample: fs={fs!r} must be > 0 [Hz]")
        s = self.channel(name, filtered=filtered)
        if s.t.size == 0:
            return s
        t0 = float(self._group(name).attrs["t0"])
        k0 = math.ceil((s.t[0] - t0) * fs - 1e-9)
        k1 = math.floor((s.t[-1] - t0) * fs + 1e-9)
        t_new = t0 + np.arange(k0, k1 + 1) / fs
        t_new = t_new[(t_new >= s.t[0]) & (t_new <= s.t[-1])]
        out = s.resample(t_new)
        out.meta["resampled_fs"] = float(fs)
        return out

    # ------------------------------------------------------------------ energy, snapshots
    def energy(self) -> dict[str, Signal]:
        """Energy-ledger terms as Signals [J] (empty dict when no ledger was written)."""
        if "energy" not in self._f:
            return {}
        g = self._f["energy"]
        n = min(d.shape[0] for d in g.values())
        t = g["t"][:n]
        return {k: Signal(k, t, d[:n], _decode(d.attrs["unit"]), None, {"kind": "energy"})
                for k, d in g.items() if k != "t"}

    def snapshot_times(self) -> np.ndarray:
        """Times of the stored particle snapshots [s]."""
        if "snapshots" not in self._f:
            return np.zeros(0)
        g = self._f["snapshots"]
        n = min(g[k].shape[0] for k in ("t", "x", "v") if k in g)  # a kill may split a write
        return g["t"][:n]

    def snapshot(self, i: int) -> dict[str, Any]:
        """Snapshot ``i``: dict with t [s], x (N, 3) [m], radius (N,) [m], v (N, 3) or None."""
        times = self.snapshot_times()
        if not -times.size <= i < times.size:
            raise IndexError(f"snapshot {i}: {times.size} snapshots stored")
        g = self._f["snapshots"]
        return {"t": float(times[i]), "x": g["x"][i].astype(float), "radius": g["radius"][:],
                "v": g["v"][i].astype(float) if "v" in g else None}

    def plot(self, out_dir: str | os.PathLike | None = None, **kwargs: Any) -> list[Path]:
        """PNG plots of this result (``crashdem.plotting.plot_result``); default directory:
        the file path without its suffix."""
        from crashdem.plotting import plot_result

        return plot_result(self, self.path.with_suffix("") if out_dir is None else out_dir,
                           **kwargs)

    # ------------------------------------------------------------------ text
    def summary(self) -> str:
        """Human-readable summary (used by ``crashdem info``)."""
        p = self.provenance
        lines = [f"{self.path}",
                 f"  status: {self.status}" + (f" ({self.error})" if self.error else "")
                 + (" [SWMR read: the writer is running, or died without closing the file]"
                    if self.opened_swmr else ""),
                 f"  crashdem {p.get('crashdem_version')} (git {p.get('git_hash')}), "
                 f"numpy {p.get('numpy_version')}, numba {p.get('numba_version')}, "
                 f"exudyn {p.get('exudyn_version')}",
                 f"  host {p.get('hostname')}, threads {p.get('threads')}, seed {p.get('seed')}",
                 f"  start {p.get('start_time')}, end {p.get('end_time') or '-'}, "
                 f"wall {p.get('wall_time', float('nan')):.1f} s"]
        if "run" in self._f:  # run facts written by crashdem.run (particles, dt, ...)
            facts = {k: _attr_value(v) for k, v in self._f["run"].attrs.items()}
            lines.append("  run: " + ", ".join(
                f"{k} {v:.6g}" if isinstance(v, float) else f"{k} {v}" for k, v in facts.items()))
        names = self.channels()
        lines.append(f"  channels ({len(names)}):")
        for name in names:
            g = self._group(name)
            raw = _raw_signal(name, g)
            unit = raw.unit
            if raw.t.size:
                finite = raw.data[np.isfinite(raw.data)]
                peak = finite[np.argmax(np.abs(finite))] if finite.size else float("nan")
                rng = f"{raw.t[0]:.5f}..{raw.t[-1]:.5f} s, {raw.t.size} samples"
            else:
                peak, rng = float("nan"), "no samples"
            cfc = self.cfc_class(name)
            flag = " FAILED" if "failed_at" in raw.meta else ""
            code = raw.meta.get("iso_code") or "-"
            lines.append(f"    {name:<24s} [{unit}] {rng}, fs {g.attrs['sample_rate']:g} Hz, "
                         f"raw peak {peak:.6g}, CFC {cfc if cfc is not None else '-'}, "
                         f"ISO {code}{flag}")
        en = self.energy()
        if en:
            first = next(iter(en.values()))
            lines.append(f"  energy ledger ({first.t.size} rows"
                         + (f", last at t = {first.t[-1]:.5f} s" if first.t.size else "")
                         + "):")
            for k, sig in en.items():
                last = f"{sig.data[-1]:.6g} J" if sig.data.size else "-"
                lines.append(f"    {k:<24s} final {last}")
        ts = self.snapshot_times()
        if ts.size:
            lines.append(f"  snapshots: {ts.size} at t = "
                         + ", ".join(f"{x:.4g}" for x in ts[:8]) + (" ..." if ts.size > 8
                                                                   else "") + " s")
        return "\n".join(lines)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> "Result":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"Result({str(self.path)!r}, status={self.status!r}, "
                f"channels={len(self.channels())})")


def open_result(path: str | os.PathLike) -> Result:
    """Open a crashdem HDF5 result for reading (also a file whose writer was killed)."""
    return Result(path)


# --------------------------------------------------------------------------------------------
# comparison
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ChannelComparison:
    """Differences of one channel between two results (b relative to a).

    Attributes: unit; peak_a, peak_b (signed value at max |x|) [unit]; t_peak_a, t_peak_b [s];
    peak_difference = peak_b - peak_a [unit]; peak_ratio = peak_b / peak_a [1];
    time_of_peak_difference = t_peak_b - t_peak_a [s]; rms_difference (RMS of b - a on the
    common time range) [unit]; relative_rms = rms_difference / RMS(a) [1]; n (common samples);
    iso18571: ISO/TS 18571 numbers (``crashdem.metrics.iso18571(a, b).as_dict()``: overall,
    corridor, phase, magnitude, slope, ...) when the module exists and the channel is rateable
    (>= 10 samples on its 10 kHz grid, non-zero reference), else None.
    """

    name: str
    unit: str
    peak_a: float
    peak_b: float
    t_peak_a: float
    t_peak_b: float
    peak_difference: float
    peak_ratio: float
    time_of_peak_difference: float
    rms_difference: float
    relative_rms: float
    n: int
    iso18571: dict[str, float] | None = None


def _peak(s: Signal) -> tuple[float, float]:
    ok = np.isfinite(s.data)
    if not ok.any():
        return float("nan"), float("nan")
    i = int(np.argmax(np.where(ok, np.abs(s.data), -1.0)))
    return float(s.data[i]), float(s.t[i])


def _iso18571(a: Signal, b: Signal) -> dict[str, float] | None:
    try:
        from crashdem import metrics  # noqa: PLC0415 - optional module (another engineer's)
    except ImportError:
        return None
    fn = getattr(metrics, "iso18571", None)
    if fn is None:
        return None
    try:
        rating = fn(a, b)
    except ValueError:  # too short, zero reference, ...: no rating for this channel
        return None
    if hasattr(rating, "as_dict"):
        rating = rating.as_dict()
    if isinstance(rating, Mapping):
        return {str(k): float(v) for k, v in rating.items()
                if isinstance(v, (int, float, np.integer, np.floating))}
    if hasattr(rating, "__dataclass_fields__"):
        return {k: float(getattr(rating, k)) for k in rating.__dataclass_fields__
                if isinstance(getattr(rating, k), (int, float))}
    return {"overall": float(rating)}


def compare(result_a: Result, result_b: Result, channels: Sequence[str] | None = None,
            filtered: bool = True, t_window: tuple[float, float] | None = None
            ) -> dict[str, ChannelComparison]:
    """Per-channel differences between two results (b is interpolated onto a's samples).

    Parameters
    ----------
    result_a, result_b : results (a = reference)
    channels : names to compare (default: channels present in both)
    filtered : compare filtered channels (``Result.channel(name, filtered)``)
    t_window : (t0, t1) [s] restricting peaks, RMS and rating to that interval

    Returns
    -------
    dict name -> ChannelComparison. Units are converted to SI before comparing.

    Notes
    -----
    Peak = signed value at the maximum of |x|; RMS over the common time range (linear
    interpolation of b on a's sample times). ISO/TS 18571 rating from ``crashdem.metrics`` if
    that module exists.
    """
    if channels is None:
        names_b = set(result_b.channels())
        channels = [c for c in result_a.channels() if c in names_b]
    out: dict[str, ChannelComparison] = {}
    for name in channels:
        a = result_a.channel(name, filtered).to_si()
        b = result_b.channel(name, filtered).to_si()
        if t_window is not None:
            a, b = a.window(*t_window), b.window(*t_window)
        if a.unit != b.unit:
            raise ValueError(f"compare {name!r}: units differ ({a.unit!r} vs {b.unit!r})")
        pa, tpa = _peak(a)
        pb, tpb = _peak(b)
        lo = max(a.t[0], b.t[0]) if a.t.size and b.t.size else 0.0
        hi = min(a.t[-1], b.t[-1]) if a.t.size and b.t.size else -1.0
        m = (a.t >= lo) & (a.t <= hi)
        if m.sum() >= 1:
            ta = a.t[m]
            da = a.data[m]
            db = np.interp(ta, b.t, b.data)
            ok = np.isfinite(da) & np.isfinite(db)
            diff = db[ok] - da[ok]
            rms = float(np.sqrt(np.mean(diff ** 2))) if diff.size else float("nan")
            rms_a = float(np.sqrt(np.mean(da[ok] ** 2))) if diff.size else float("nan")
            n = int(ok.sum())
            a_c = Signal(name, ta[ok], da[ok], a.unit)
            b_c = Signal(name, ta[ok], db[ok], a.unit)
        else:
            rms, rms_a, n, a_c, b_c = float("nan"), float("nan"), 0, None, None
        iso = _iso18571(a_c, b_c) if n >= 3 else None
        out[name] = ChannelComparison(
            name=name, unit=a.unit, peak_a=pa, peak_b=pb, t_peak_a=tpa, t_peak_b=tpb,
            peak_difference=pb - pa, peak_ratio=pb / pa if pa != 0 else float("nan"),
            time_of_peak_difference=tpb - tpa, rms_difference=rms,
            relative_rms=rms / rms_a if rms_a and np.isfinite(rms_a) else float("nan"),
            n=n, iso18571=iso)
    return out

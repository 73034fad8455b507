"""Ensembles on Dask distributed: parameter sweeps, calibration, and any fan-out of members.

An ensemble is a list of *members*, each a set of scenario overrides. Every member is one Dask
task that writes its own crashdem result file (``crashdem.results`` schema) into a work
directory, under a name keyed by a hash of (base scenario, overrides); the client gathers the
finished members, as they finish, into ONE ensemble HDF5 file (layout below), so a killed
ensemble keeps every member finished before the kill and can be resumed (``resume=True``).

API
---
``ClusterSettings(scheduler=None, n_workers=None, ...)`` and ``dask_client(settings)``
    LocalCluster (processes, one thread per worker, ``n_workers`` = cores) or an existing
    scheduler (``scheduler="tcp://host:8786"``).
``SweepSpec(vary={"soil.material.young": [1e7, 2e7]}, mode="grid"|"zip", fixed={})``
``sweep(scenario, spec, out, member_fn=None, cluster=ClusterSettings(), ...) -> Path``
``calibrate(scenario, params, objective_fn, out, member_fn=None, ...) -> CalibrationResult``
``map_overrides(scenario, [overrides, ...], out, member_fn, ...)``: one member per overrides
    dict (the fan-out behind ``sweep`` and the diagnosis confirmation runs,
    ``crashdem.diagnosis.distributed``);
``run_members(members, member_fn, writer, client, ...)``: the lower-level fan-out used by all.
``RunMember(threads=1)``: the default member function (``crashdem.run.run_scenario``).
``ChannelObjective(reference, channel, metric="iso18571"|"rms")``: a finished member ->
    objective value (to minimise).
``open_ensemble(path) -> EnsembleResult``: reader.
CLI hooks (wired by ``crashdem/cli.py``): ``add_sweep_arguments(parser)``,
``sweep_command(args)``, ``add_calibrate_arguments(parser)``, ``calibrate_command(args)``,
``add_cluster_arguments(parser, set_option)`` (also used by ``crashdem diagnose``).

Member function protocol: ``member_fn(member: Member, path: Path) -> None`` writes a crashdem
result at ``path`` (a fresh temporary name; the task renames it atomically when the function
returns). It must be picklable (module-level function or instance of a module-level class).
An exception inside it marks the member ``failed`` (with the error text) and is not retried:
a physics failure is deterministic. Losing the worker process (SIGKILL, OOM, node lost) makes
the scheduler rerun the task elsewhere (``ClusterSettings.allowed_failures``); exceptions
escaping the task wrapper itself (I/O) are retried ``ClusterSettings.retries`` times.

Ensemble file layout (format ``crashdem-ensemble``, version 1)::

    /                    attrs: format, format_version, kind ("sweep"|"calibration"|"members"),
                         status ("running"|"complete"|"failed"), complete, start_time, end_time,
                         spec (JSON), spec_hash, n_planned, dask_version, distributed_version,
                         scheduler, n_workers + crashdem provenance (versions, git hash, host)
    /scenario/config_toml, /scenario/source_toml     the base scenario (str datasets, unit "1")
    /spec/planned        (P,) str: JSON overrides of each planned member (sweeps)
    /members/<k>         attrs: index, key, status, error, attempts, worker, wall_time
                         (unit s), overrides (JSON), generation (calibration)
        overrides        attrs: one per override, dotted name -> value
        scalars          attrs: scalar outputs (peak/t_peak/min/max per channel, objective, ...)
        channels/...     copied from the member's result file (same schema as a result)
        energy/..., run  copied when present
    /summary             rewritten after each member: index (M,), status (M,) str,
                         objective (M,), one (M,) dataset per override key and per scalar
    /calibration         (calibrate only) attrs: parameters, best_* ; datasets history_*

Notes
-----
Dask: ``distributed.Client.submit(..., retries=)`` reruns a task whose function raised;
a task whose worker died is rescheduled by the scheduler up to
``distributed.scheduler.allowed-failures`` times (Dask distributed documentation, "Resilience").
Optimiser: parallel compass (generalised pattern) search with complete polling, Torczon (1997)
"On the convergence of pattern search algorithms", SIAM J. Optim. 7(1); Kolda, Lewis & Torczon
(2003) "Optimization by direct search", SIAM Review 45(3), section 3 and 8 (parallel polling).
Initial design: Latin hypercube (McKay, Beckman & Conover 1979), ``scipy.stats.qmc``.
"""
from __future__ import annotations

import argparse
import contextlib
import datetime as _dt
import hashlib
import itertools
import json
import logging
import math
import os
import shutil
import socket
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, Iterator, Mapping, Sequence

import h5py
import numpy as np

from crashdem.scenario import Scenario, ScenarioError, parse_override
from crashdem.signal import Signal
from crashdem.results import _attr_value

__all__ = [
    "CalibrationResult",
    "ChannelObjective",
    "ClusterSettings",
    "ENSEMBLE_FORMAT",
    "EnsembleResult",
    "EnsembleWriter",
    "FitParameter",
    "Member",
    "MemberOutcome",
    "PatternSearch",
    "RunMember",
    "SweepSpec",
    "add_calibrate_arguments",
    "add_cluster_arguments",
    "add_sweep_arguments",
    "calibrate",
    "calibrate_command",
    "dask_client",
    "default_scalars",
    "map_overrides",
    "open_ensemble",
    "parse_fit_parameter",
    "parse_vary",
    "run_members",
    "sweep",
    "sweep_command",
]

log = logging.getLogger("crashdem.ensemble")

ENSEMBLE_FORMAT = "crashdem-ensemble"
ENSEMBLE_FORMAT_VERSION = 1
MEMBER_STATUSES = ("complete", "failed")


def _utc_now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def _describe(obj: Any) -> str:
    """Stable text naming a callable (no memory address), for the ensemble spec."""
    if obj is None:
        return "None"
    import inspect

    if inspect.isfunction(obj) or inspect.isbuiltin(obj) or inspect.ismethod(obj):
        target = obj
    elif type(obj).__repr__ is not object.__repr__:
        return repr(obj)
    else:
        target = type(obj)
    return f"{getattr(target, '__module__', '?')}.{getattr(target, '__qualname__', '?')}"


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


# --------------------------------------------------------------------------------------------
# cluster
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ClusterSettings:
    """Where the members run.

    Parameters
    ----------
    scheduler : address of an existing Dask scheduler (``tcp://host:8786``); None starts a
        LocalCluster for the duration of the ensemble
    n_workers : LocalCluster worker processes (None: ``os.cpu_count()``), >= 1
    threads_per_worker : threads per worker process (1: one member per process), >= 1
    processes : LocalCluster workers as processes (True) or threads of this process
    retries : reruns of a member task whose wrapper raised (I/O errors), >= 0
    allowed_failures : worker deaths a task may witness before it is declared lost
        (``distributed.scheduler.allowed-failures``; applied to a LocalCluster only, an
        external scheduler keeps its own configuration), >= 0
    memory_limit : per-worker memory limit passed to LocalCluster ("auto", "4GiB", 0 = none)
    """

    scheduler: str | None = None
    n_workers: int | None = None
    threads_per_worker: int = 1
    processes: bool = True
    retries: int = 2
    allowed_failures: int = 3
    memory_limit: str | int = "auto"

    def __post_init__(self) -> None:
        if self.n_workers is not None and not (isinstance(self.n_workers, int)
                                               and self.n_workers >= 1):
            raise ValueError(f"ClusterSettings.n_workers={self.n_workers!r}: must be an int >= 1 "
                             "or None (= cores)")
        for name in ("threads_per_worker",):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"ClusterSettings.{name}={v!r}: must be an int >= 1")
        for name in ("retries", "allowed_failures"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 0):
                raise ValueError(f"ClusterSettings.{name}={v!r}: must be an int >= 0")
        if self.scheduler is not None and not (isinstance(self.scheduler, str)
                                               and self.scheduler.strip()):
            raise ValueError(f"ClusterSettings.scheduler={self.scheduler!r}: must be an address "
                             "such as 'tcp://host:8786' or None")

    def workers(self) -> int:
        return self.n_workers if self.n_workers is not None else max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def dask_client(settings: ClusterSettings = ClusterSettings()) -> Iterator[Any]:
    """A ``distributed.Client`` on a LocalCluster (closed on exit) or on ``settings.scheduler``."""
    import dask
    from distributed import Client, LocalCluster

    if settings.scheduler is not None:
        with Client(settings.scheduler) as client:
            yield client
        return
    with dask.config.set({"distributed.scheduler.allowed-failures": settings.allowed_failures}):
        cluster = LocalCluster(n_workers=settings.workers(),
                               threads_per_worker=settings.threads_per_worker,
                               # any free port: a fixed 8787 clashes with other clusters
                               processes=settings.processes, dashboard_address=":0",
                               memory_limit=settings.memory_limit)
    try:
        with Client(cluster) as client:
            try:
                yield client
            finally:
                _quiet_shutdown(client)
    finally:
        cluster.close()


#: loggers of a LocalCluster's worker processes that report the scheduler going away while
#: they close (``Failed to communicate with scheduler during heartbeat``, dask/distributed
#: #7192): silenced on the workers when this process closes the cluster itself
SHUTDOWN_LOGGERS = ("distributed.worker", "distributed.core", "distributed.nanny",
                    "distributed.comm", "distributed.batched")


def _silence_shutdown_loggers() -> None:
    """On a worker: raise ``SHUTDOWN_LOGGERS`` to CRITICAL."""
    import logging

    for name in SHUTDOWN_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _quiet_shutdown(client: Any) -> None:
    """Before a LocalCluster this process made is closed: its workers stop logging the
    scheduler's going away (a finished run used to end with heartbeat tracebacks on stderr
    when the machine was loaded). Anything a worker reported before is unaffected; a worker
    that is gone already is skipped."""
    try:
        client.run(_silence_shutdown_loggers)
    except Exception:  # noqa: BLE001 - closing anyway: nothing to report
        pass


# --------------------------------------------------------------------------------------------
# members
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Member:
    """One ensemble member: the base scenario with ``overrides`` applied.

    Attributes
    ----------
    index : position in the ensemble (0-based)
    overrides : dotted scenario field -> value
    scenario : the checked scenario with the overrides applied (None for member functions
        that do not use scenarios, e.g. synthetic test members)
    base : text identifying the base (the scenario's full TOML); part of the hash key
    generation : calibration generation (-1 for sweeps)
    """

    index: int
    overrides: Mapping[str, Any]
    scenario: Scenario | None = None
    base: str = ""
    generation: int = -1

    @property
    def key(self) -> str:
        """Hash of (base, overrides): the member's file name in the work directory."""
        text = _json({"base": self.base, "overrides": dict(self.overrides)})
        return hashlib.sha256(text.encode()).hexdigest()[:20]


@dataclass
class MemberOutcome:
    """What a member task returns to the gatherer (plain data; pickled through Dask)."""

    index: int
    key: str
    status: str  # "complete" | "failed"
    error: str
    path: str  # the member's result file on the worker's file system ("" if failed)
    scalars: dict[str, float]
    attempts: int
    worker: str
    wall_time: float  # [s]
    reused: bool = False
    content: bytes | None = None  # the result file, when transferred by value


def default_scalars(result: Any) -> dict[str, float]:
    """Scalar outputs of a finished member: per channel ``<name>.peak`` (signed value at max |x|,
    filtered channel when a CFC applies), ``<name>.t_peak`` [s], ``<name>.min``, ``<name>.max``
    [channel unit]; and the numeric ``/run`` facts as ``run.<fact>``."""
    out: dict[str, float] = {}
    for name in result.channels():
        s = result.channel(name, filtered=True)
        ok = np.isfinite(s.data)
        if not ok.any():
            continue
        d, t = s.data[ok], s.t[ok]
        i = int(np.argmax(np.abs(d)))
        out[f"{name}.peak"] = float(d[i])
        out[f"{name}.t_peak"] = float(t[i])
        out[f"{name}.min"] = float(d.min())
        out[f"{name}.max"] = float(d.max())
    f = result._f
    if "run" in f:
        for k, v in f["run"].attrs.items():
            if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
                out[f"run.{k}"] = float(v)
    return out


def _count_attempt(work_dir: Path, key: str) -> int:
    """Record the start of one attempt of member ``key``; return how many have started."""
    d = work_dir / f"{key}.attempts"
    d.mkdir(parents=True, exist_ok=True)
    (d / f"{socket.gethostname()}-{os.getpid()}-{uuid.uuid4().hex[:8]}").touch()
    return sum(1 for _ in d.iterdir())


def _is_complete_result(path: Path) -> bool:
    try:
        with h5py.File(path, "r") as f:
            return bool(f.attrs.get("complete", False))
    except OSError:
        return False


def _member_task(member: Member, member_fn: Callable[[Member, Path], None], work_dir: str,
                 scalars_fn: Callable[[Any], dict[str, float]] | None,
                 objective_fn: Callable[[Any], float] | None, transfer: bool) -> MemberOutcome:
    """Run one member on a worker (idempotent: a finished member file is reused)."""
    from crashdem.results import open_result

    t0 = time.perf_counter()
    wd = Path(work_dir)
    wd.mkdir(parents=True, exist_ok=True)
    key = member.key
    attempts = _count_attempt(wd, key)
    final = wd / f"{key}.h5"
    worker = f"{socket.gethostname()}:{os.getpid()}"
    reused = final.exists() and _is_complete_result(final)
    status, error = "complete", ""
    if not reused:
        tmp = wd / f"{key}.{uuid.uuid4().hex[:8]}.partial.h5"
        try:
            member_fn(member, tmp)
            if not tmp.exists():
                raise RuntimeError(f"member function {member_fn!r} wrote no file at {tmp}")
            os.replace(tmp, final)  # atomic: a rerun never sees a half-written member file
        except Exception as exc:  # noqa: BLE001 - a member's failure is data, not a crash
            status, error = "failed", f"{type(exc).__name__}: {exc}"
            tmp.unlink(missing_ok=True)
    scalars: dict[str, float] = {}
    if status == "complete":
        try:
            with open_result(final) as res:
                if res.status != "complete":
                    status, error = "failed", f"member result status {res.status!r}: {res.error}"
                scalars = dict((scalars_fn or default_scalars)(res))
                if objective_fn is not None and status == "complete":
                    scalars["objective"] = float(objective_fn(res))
        except Exception as exc:  # noqa: BLE001
            status, error = "failed", f"{type(exc).__name__}: {exc}"
    content = final.read_bytes() if (transfer and status == "complete") else None
    return MemberOutcome(member.index, key, status, error, str(final) if final.exists() else "",
                         scalars, attempts, worker, time.perf_counter() - t0, reused, content)


@dataclass(frozen=True)
class RunMember:
    """Default member function: a full crashdem run of the member's scenario.

    Parameters
    ----------
    threads : Numba threads per member (``scenario.threads``, >= 0, 0 = all cores); 1 matches
        one member per single-threaded worker process; None keeps the scenario's value
    snapshots : keep the scenario's particle snapshots (False sets ``output.snapshots = 0``)
    run_cache : a ``crashdem.runcache.RunCache`` the runs are taken from when made before and
        kept in (None: every member is run)

    Notes
    -----
    The deposited packing is shared by members in ``<work_dir>/packings``; it is built under a
    file lock so that two workers needing the same packing do not deposit it twice or write
    the cache file concurrently.
    """

    threads: int | None = 1
    snapshots: bool = False
    run_cache: Any = None

    def __post_init__(self) -> None:
        if self.threads is not None and not (isinstance(self.threads, int)
                                             and self.threads >= 0):
            raise ValueError(f"RunMember.threads={self.threads!r}: must be an int >= 0 or None")

    def __call__(self, member: Member, path: Path) -> None:
        from crashdem.run import run_scenario

        if member.scenario is None:
            raise ValueError(f"member {member.index}: RunMember needs a scenario")
        scen = self.member_scenario(member.scenario, f"member-{member.key}")
        path = Path(path)
        # the run takes its bed from ``path.parent/packings``; members sharing it deposit each
        # bed once (``soil.packing.cached`` holds a lock while it deposits)
        if self.run_cache is not None:
            out = self.run_cache.run(scen, path.parent, plots=False)
        else:
            out = run_scenario(scen, out_dir=path.parent, progress=False, plots=False)
        os.replace(out, path)

    def member_scenario(self, scenario: Scenario, name: str = "member") -> Scenario:
        """The scenario this function runs for a member of ``scenario`` (named ``name``)."""
        ov: dict[str, Any] = {"scenario.name": name, "output.plots": False}
        if self.threads is not None:
            ov["scenario.threads"] = self.threads
        if not self.snapshots:
            ov["output.snapshots"] = 0
        return scenario.with_overrides(ov)


@dataclass(frozen=True, repr=False)
class ChannelObjective:
    """Objective value (to minimise) of a finished member against a reference channel.

    Parameters
    ----------
    reference : the recorded channel (Signal, any unit convertible to SI)
    channel : name of the simulated channel in the member's result
    metric : "iso18571" -> 1 - R (R: ISO/TS 18571 overall rating in [0, 1]);
        "rms" -> RMS of (simulated - recorded) divided by the RMS of the recording
    t_window : (t0, t1) evaluation interval [s] (None: the common time range)
    filtered : compare the member's filtered channel (its CFC class)

    Notes
    -----
    ISO/TS 18571 via ``crashdem.metrics.iso18571``; RMS via ``crashdem.metrics.rms_error``
    (relative, on a common 0.1 ms grid).
    """

    METRICS: ClassVar[tuple[str, ...]] = ("iso18571", "rms")

    reference: Signal
    channel: str
    metric: str = "iso18571"
    t_window: tuple[float, float] | None = None
    filtered: bool = True

    def __post_init__(self) -> None:
        if self.metric not in self.METRICS:
            raise ValueError(f"ChannelObjective.metric={self.metric!r}: must be one of "
                             f"{self.METRICS}")
        if self.t_window is not None and not (self.t_window[1] > self.t_window[0]):
            raise ValueError(f"ChannelObjective.t_window={self.t_window!r}: must be (t0, t1) "
                             "[s] with t1 > t0")

    def __repr__(self) -> str:
        return (f"ChannelObjective({self.reference.name!r} vs {self.channel!r}, "
                f"metric={self.metric!r}, t_window={self.t_window!r})")

    def __call__(self, result: Any) -> float:
        from crashdem import metrics

        sim = result.channel(self.channel, filtered=self.filtered)
        if self.metric == "iso18571":
            return 1.0 - float(metrics.iso18571(self.reference, sim, self.t_window).overall)
        return float(metrics.rms_error(self.reference, sim, self.t_window, relative=True))


# --------------------------------------------------------------------------------------------
# sweep specification
# --------------------------------------------------------------------------------------------
def _split_values(raw: str) -> list[str]:
    """Split ``a,b,[1,2],"x,y"`` at top-level commas (brackets and quotes kept together)."""
    parts, depth, quote, cur = [], 0, "", []
    for ch in raw:
        if quote:
            cur.append(ch)
            if ch == quote:
                quote = ""
            continue
        if ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
            continue
        cur.append(ch)
    parts.append("".join(cur))
    return [p.strip() for p in parts]


def parse_vary(text: str) -> tuple[str, list[Any]]:
    """Parse ``--vary key=v1,v2,...`` (each value read as a TOML value, like ``--set``)."""
    if "=" not in text:
        raise ScenarioError(f"--vary {text!r}: expected key=v1,v2,..., e.g. "
                            "soil.material.young=1e7,2e7,4e7")
    key, raw = text.split("=", 1)
    items = _split_values(raw)
    if not raw.strip() or any(not v for v in items):
        raise ScenarioError(f"--vary {text!r}: empty value in the list")
    return key.strip(), [parse_override(f"{key}={v}")[1] for v in items]


@dataclass(frozen=True)
class SweepSpec:
    """A parameter sweep.

    Parameters
    ----------
    vary : dotted scenario field -> values (in order)
    mode : "grid" (Cartesian product, last field fastest) or "zip" (i-th values together;
        every list the same length)
    fixed : overrides applied to every member
    """

    vary: Mapping[str, Sequence[Any]]
    mode: str = "grid"
    fixed: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in ("grid", "zip"):
            raise ValueError(f"SweepSpec.mode={self.mode!r}: must be 'grid' or 'zip'")
        if not self.vary:
            raise ValueError("SweepSpec.vary={}: must name at least one field")
        for k, vals in self.vary.items():
            if isinstance(vals, (str, bytes)) or len(vals) == 0:
                raise ValueError(f"SweepSpec.vary[{k!r}]={vals!r}: must be a non-empty list")
            if k in self.fixed:
                raise ValueError(f"SweepSpec: {k!r} is both varied and fixed")
        if self.mode == "zip":
            lens = {k: len(v) for k, v in self.vary.items()}
            if len(set(lens.values())) != 1:
                raise ValueError(f"SweepSpec.vary lengths {lens}: 'zip' needs equal lengths")

    def overrides(self) -> list[dict[str, Any]]:
        """The members' overrides, in order."""
        keys = list(self.vary)
        lists = [list(self.vary[k]) for k in keys]
        combos = itertools.product(*lists) if self.mode == "grid" else zip(*lists)
        return [{**dict(self.fixed), **dict(zip(keys, c))} for c in combos]

    def as_dict(self) -> dict[str, Any]:
        return {"vary": {k: list(v) for k, v in self.vary.items()}, "mode": self.mode,
                "fixed": dict(self.fixed)}


def _validate_members(base: Scenario | None, overrides: Sequence[Mapping[str, Any]],
                      preflight: Callable[[Scenario], Any] | None) -> list[Scenario | None]:
    """Apply every member's overrides to the base scenario (schema check) before any submission.

    Raises ``ScenarioError`` naming the member, the field and the value."""
    out: list[Scenario | None] = []
    for k, ov in enumerate(overrides):
        if base is None:
            out.append(None)
            continue
        try:
            scen = base.with_overrides(dict(ov))
            if preflight is not None:
                preflight(scen)
        except ScenarioError as exc:
            raise ScenarioError(f"member {k} ({_fmt_overrides(ov)}): {exc}") from None
        out.append(scen)
    return out


def _fmt_overrides(ov: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in ov.items())


def _run_preflight(scen: Scenario) -> None:
    """Checks of ``crashdem.run`` that do not need a run (packing spec: layering depth, ...)."""
    from crashdem.run import packing_spec

    packing_spec(scen)


# --------------------------------------------------------------------------------------------
# ensemble file
# --------------------------------------------------------------------------------------------
def _attr(group: h5py.Group | h5py.AttributeManager, key: str, value: Any) -> None:
    attrs = group if isinstance(group, h5py.AttributeManager) else group.attrs
    if value is None:
        attrs[key] = h5py.Empty("f8")
    elif isinstance(value, (bool, np.bool_)):
        attrs[key] = np.bool_(value)
    elif isinstance(value, (int, float, str, np.integer, np.floating)):
        attrs[key] = value
    elif isinstance(value, (list, tuple)) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        attrs[key] = np.asarray(value, dtype=float)
    else:
        attrs[key] = _json(value)


class EnsembleWriter:
    """Gathers member results into one ensemble HDF5 file (opened and closed per member, so
    the file on disk is complete and readable between members).

    Parameters
    ----------
    path : ensemble file
    kind : "sweep", "calibration" or "members"
    spec : JSON-serialisable description of the ensemble (stored as ``attrs["spec"]``)
    base : the base scenario (None for synthetic members)
    planned : the planned members' overrides (sweeps), stored in ``/spec/planned``
    resume : keep an existing file with the same spec hash and append to it (its complete
        members are then skipped by ``run_members``); otherwise the file is overwritten
    copy_groups : groups of each member result copied under ``/members/<k>/``
    extra_attrs : more root attributes (scheduler, workers, ...)
    """

    def __init__(self, path: str | os.PathLike, kind: str, spec: Mapping[str, Any],
                 base: Scenario | None = None, planned: Sequence[Mapping[str, Any]] = (),
                 resume: bool = False, copy_groups: Sequence[str] = ("channels", "energy", "run"),
                 extra_attrs: Mapping[str, Any] | None = None) -> None:
        from crashdem.results import provenance

        if kind not in ("sweep", "calibration", "members"):
            raise ValueError(f"EnsembleWriter.kind={kind!r}: must be 'sweep', 'calibration' or "
                             "'members'")
        self.path = Path(path)
        self.kind = kind
        self.copy_groups = tuple(copy_groups)
        spec_text = _json(spec)
        base_text = base.to_toml() if base is not None else ""
        self.spec_hash = hashlib.sha256((spec_text + base_text).encode()).hexdigest()[:20]
        self.done: dict[str, int] = {}  # key -> member index, complete members in the file
        self._records: list[dict[str, Any]] = []
        if resume and self.path.exists():
            with h5py.File(self.path, "r") as f:
                if _attr_value(f.attrs.get("spec_hash")) != self.spec_hash:
                    raise ValueError(f"{self.path}: resume: the file holds another ensemble "
                                     f"(spec hash {_attr_value(f.attrs.get('spec_hash'))!r}, "
                                     f"this one {self.spec_hash!r}); use another --out")
                for g in f["members"].values():
                    rec = _member_record(g)
                    self._records.append(rec)
                    if rec["status"] == "complete":
                        self.done[rec["key"]] = rec["index"]
            with h5py.File(self.path, "a") as f:
                f.attrs["status"] = "running"
                f.attrs["complete"] = False
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with h5py.File(self.path, "w", track_order=True) as f:
            f.attrs["format"] = ENSEMBLE_FORMAT
            f.attrs["format_version"] = ENSEMBLE_FORMAT_VERSION
            f.attrs["kind"] = kind
            f.attrs["status"] = "running"
            f.attrs["complete"] = False
            f.attrs["error"] = ""
            f.attrs["start_time"] = _utc_now()
            f.attrs["end_time"] = ""
            f.attrs["spec"] = spec_text
            f.attrs["spec_hash"] = self.spec_hash
            f.attrs["n_planned"] = len(planned)
            for k, v in provenance().items():
                f.attrs[k] = v
            f.attrs["dask_version"] = _version("dask")
            f.attrs["distributed_version"] = _version("distributed")
            for k, v in (extra_attrs or {}).items():
                _attr(f, k, v)
            sc = f.create_group("scenario")
            for name, text in (("config_toml", base_text),
                               ("source_toml", getattr(base, "text", "") if base else "")):
                d = sc.create_dataset(name, data=text, dtype=h5py.string_dtype())
                d.attrs["unit"] = "1"
            sp = f.create_group("spec")
            planned_json = np.array([_json(dict(p)) for p in planned], dtype=object)
            d = sp.create_dataset("planned", data=planned_json,
                                  dtype=h5py.string_dtype())
            d.attrs["unit"] = "1"
            f.create_group("members", track_order=True)

    def set_attrs(self, **attrs: Any) -> None:
        """Root attributes (e.g. the scheduler address once the client is up)."""
        with h5py.File(self.path, "a") as f:
            for k, v in attrs.items():
                _attr(f, k, v)

    def add_member(self, member: Member, outcome: MemberOutcome,
                   local_path: Path | None = None) -> None:
        """Copy one finished member into ``/members/<index>`` and rewrite ``/summary``."""
        src_path = local_path if local_path is not None else (
            Path(outcome.path) if outcome.path else None)
        with h5py.File(self.path, "a") as f:
            members = f["members"]
            name = str(member.index)
            if name in members:  # a resumed ensemble re-adding a failed member
                del members[name]
            g = members.create_group(name)
            g.attrs["index"] = member.index
            g.attrs["key"] = outcome.key
            g.attrs["status"] = outcome.status
            g.attrs["error"] = outcome.error
            g.attrs["attempts"] = outcome.attempts
            g.attrs["worker"] = outcome.worker
            g.attrs["wall_time"] = outcome.wall_time
            g.attrs["wall_time.unit"] = "s"
            g.attrs["reused"] = outcome.reused
            g.attrs["generation"] = member.generation
            g.attrs["overrides"] = _json(dict(member.overrides))
            go = g.create_group("overrides")
            for k, v in member.overrides.items():
                _attr(go, k, v)
            gs = g.create_group("scalars")
            for k, v in outcome.scalars.items():
                gs.attrs[k] = float(v)
            copied = outcome.status == "complete" and src_path is not None \
                and src_path.exists()
            g.attrs["copied"] = copied
            if outcome.status == "complete" and not copied:
                log.warning("member %d: result file %r not visible from the gatherer (no shared "
                            "file system? use transfer=True); only its scalars are stored",
                            member.index, outcome.path)
            if copied:
                with h5py.File(src_path, "r") as src:
                    for grp in self.copy_groups:
                        if grp in src:
                            src.copy(src[grp], g, name=grp)
                    g.attrs["member_status"] = _attr_value(src.attrs.get("status", ""))
                    g.attrs["member_git_hash"] = _attr_value(src.attrs.get("git_hash", ""))
            self._records = [r for r in self._records if r["index"] != member.index]
            self._records.append(_member_record(g))
            self._write_summary(f)
        if outcome.status == "complete":
            self.done[outcome.key] = member.index

    def _write_summary(self, f: h5py.File) -> None:
        if "summary" in f:
            del f["summary"]
        s = f.create_group("summary")
        recs = sorted(self._records, key=lambda r: r["index"])
        s.create_dataset("index", data=np.array([r["index"] for r in recs], dtype=np.int64))
        s.create_dataset("status", data=[r["status"] for r in recs], dtype=h5py.string_dtype())
        ov_keys = list(dict.fromkeys(k for r in recs for k in r["overrides"]))
        sc_keys = list(dict.fromkeys(k for r in recs for k in r["scalars"]))
        for k in ov_keys:
            vals = [r["overrides"].get(k) for r in recs]
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
                d = s.create_dataset(f"override:{k}", data=np.asarray(vals, dtype=float))
            else:
                d = s.create_dataset(f"override:{k}", data=[_json(v) for v in vals],
                                     dtype=h5py.string_dtype())
        for k in sc_keys:
            d = s.create_dataset(f"scalar:{k}", data=np.asarray(
                [r["scalars"].get(k, np.nan) for r in recs], dtype=float))
            d.attrs["unit"] = "see member channel" if "." in k else "1"
        d = s.create_dataset("objective", data=np.asarray(
            [r["scalars"].get("objective", np.nan) for r in recs], dtype=float))
        d.attrs["unit"] = "1"

    def write_calibration(self, info: Mapping[str, Any],
                          history: Mapping[str, np.ndarray]) -> None:
        """The ``/calibration`` group: attributes and history datasets (rewritten each time)."""
        with h5py.File(self.path, "a") as f:
            if "calibration" in f:
                del f["calibration"]
            g = f.create_group("calibration")
            for k, v in info.items():
                _attr(g, k, v)
            for k, arr in history.items():
                g.create_dataset(k, data=np.asarray(arr))

    def close(self, error: BaseException | str | None = None) -> Path:
        with h5py.File(self.path, "a") as f:
            f.attrs["end_time"] = _utc_now()
            if error is None:
                n_failed = sum(1 for r in self._records if r["status"] != "complete")
                f.attrs["status"] = "complete"
                f.attrs["complete"] = True
                f.attrs["n_failed"] = n_failed
            else:
                f.attrs["status"] = "failed"
                f.attrs["complete"] = False
                f.attrs["error"] = error if isinstance(error, str) else \
                    f"{type(error).__name__}: {error}"
        return self.path


def _version(dist: str) -> str:
    import importlib.metadata

    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def _member_record(g: h5py.Group) -> dict[str, Any]:
    return {"index": int(g.attrs["index"]), "key": _attr_value(g.attrs["key"]),
            "status": _attr_value(g.attrs["status"]), "error": _attr_value(g.attrs["error"]),
            "attempts": int(g.attrs["attempts"]), "worker": _attr_value(g.attrs["worker"]),
            "wall_time": float(g.attrs["wall_time"]),
            "generation": int(g.attrs.get("generation", -1)),
            "overrides": json.loads(_attr_value(g.attrs["overrides"])),
            "scalars": {k: float(v) for k, v in g["scalars"].attrs.items()}}


# --------------------------------------------------------------------------------------------
# fan-out
# --------------------------------------------------------------------------------------------
def run_members(members: Sequence[Member], member_fn: Callable[[Member, Path], None],
                writer: EnsembleWriter, client: Any, work_dir: str | os.PathLike, *,
                retries: int = 2, scalars_fn: Callable[[Any], dict[str, float]] | None = None,
                objective_fn: Callable[[Any], float] | None = None, transfer: bool = False,
                on_member: Callable[[Member, MemberOutcome], None] | None = None
                ) -> list[MemberOutcome]:
    """Submit every member as one Dask task and gather each into ``writer`` as it finishes.

    Members whose key is already complete in the ensemble file (resumed ensemble) are skipped;
    their stored record is returned instead (``reused=True``).

    Parameters
    ----------
    members : the members (their ``index`` is their group name in the file)
    member_fn : ``member_fn(member, path)`` writes the member's crashdem result at ``path``
    writer : the ensemble file
    client : a ``distributed.Client``
    work_dir : directory of the member files; must be visible to the workers and to this
        process (same machine or shared file system), unless ``transfer=True``
    retries : Dask retries of a task whose wrapper raised (worker loss is handled by the
        scheduler's allowed-failures)
    scalars_fn : finished member (``Result``) -> scalar outputs (default: ``default_scalars``)
    objective_fn : finished member (``Result``) -> objective value, stored as scalar
        ``objective``
    transfer : return each member file's bytes through Dask (workers without a shared file
        system); the gatherer writes them into ``work_dir`` before copying
    on_member : callback after each member is written

    Returns
    -------
    outcomes, in the order of ``members``
    """
    from distributed import as_completed

    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    outcomes: dict[int, MemberOutcome] = {}
    futures = {}
    for m in members:
        if m.key in writer.done:
            rec = next(r for r in writer._records if r["key"] == m.key)
            outcomes[m.index] = MemberOutcome(m.index, m.key, "complete", "", "",
                                              rec["scalars"], rec["attempts"], rec["worker"],
                                              rec["wall_time"], reused=True)
            continue
        fut = client.submit(_member_task, m, member_fn, str(work_dir), scalars_fn,
                            objective_fn, transfer, retries=retries, pure=False,
                            key=f"crashdem-member-{m.key}-{uuid.uuid4().hex[:6]}")
        futures[fut] = m
    n_total = len(members)
    for fut in as_completed(list(futures)):
        m = futures[fut]
        try:
            out: MemberOutcome = fut.result()
        except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker: the member killed every
            # worker it ran on (out of memory, segfault) more than allowed_failures times
            att = work_dir / f"{m.key}.attempts"
            n_att = sum(1 for _ in att.iterdir()) if att.is_dir() else 0
            out = MemberOutcome(m.index, m.key, "failed", f"{type(exc).__name__}: {exc}", "",
                                {}, n_att, "", math.nan)
        local = None
        if out.content is not None:
            local = work_dir / f"{out.key}.h5"
            tmp = work_dir / f"{out.key}.{uuid.uuid4().hex[:8]}.recv.h5"
            tmp.write_bytes(out.content)
            os.replace(tmp, local)
            out.content = None
        writer.add_member(m, out, local)
        outcomes[m.index] = out
        log.info("member %d (%d/%d) %s in %.2f s (attempts %d)%s", m.index, len(outcomes),
                 n_total, out.status, out.wall_time, out.attempts,
                 f": {out.error}" if out.error else "")
        if on_member is not None:
            on_member(m, out)
    return [outcomes[m.index] for m in members]


def _default_work_dir(out: Path) -> Path:
    return out.with_name(out.name + ".members")


def map_overrides(scenario: Scenario | None, overrides: Sequence[Mapping[str, Any]],
                  out: str | os.PathLike,
                  member_fn: Callable[[Member, Path], None] | None = None,
                  cluster: ClusterSettings = ClusterSettings(), *, client: Any = None,
                  kind: str = "members", spec: Mapping[str, Any] | None = None,
                  work_dir: str | os.PathLike | None = None, resume: bool = False,
                  keep_members: bool = False, preflight: bool = True,
                  scalars_fn: Callable[[Any], dict[str, float]] | None = None,
                  objective_fn: Callable[[Any], float] | None = None,
                  transfer: bool = False) -> tuple[Path, list[MemberOutcome]]:
    """Run one member per overrides dict and gather them into one ensemble file.

    The general fan-out behind ``sweep`` (and usable by the diagnosis for its confirmation
    runs). Every member's overrides are checked against the scenario schema (and, for the
    default member function, the run's pre-flight checks) before anything is submitted.

    Parameters
    ----------
    scenario : base scenario (None only for member functions that ignore scenarios)
    overrides : one dict of dotted field -> value per member
    out : ensemble HDF5 file
    member_fn : ``member_fn(member, path)``; default ``RunMember()`` (a full run)
    cluster : LocalCluster / scheduler settings (``retries`` is used with ``client`` too)
    client : an existing ``distributed.Client`` to use
    kind : ensemble kind stored in the file ("members", "sweep")
    spec : description stored as the ensemble spec (default: the overrides list)
    work_dir : member files (default ``<out>.members/``), removed after a fully successful
        ensemble unless ``keep_members``
    resume : continue an interrupted ensemble in ``out`` (complete members are kept)
    preflight, scalars_fn, objective_fn, transfer : see ``run_members``

    Returns
    -------
    (path of the ensemble file, member outcomes in order)
    """
    out = Path(out)
    overrides = [dict(o) for o in overrides]
    if not overrides:
        raise ValueError("map_overrides: overrides is empty")
    if member_fn is None:
        member_fn = RunMember()
    check = _run_preflight if (preflight and isinstance(member_fn, RunMember)) else None
    scens = _validate_members(scenario, overrides, check)
    base = scenario.to_toml() if scenario is not None else ""
    members = [Member(k, ov, s, base) for k, (ov, s) in enumerate(zip(overrides, scens))]
    wd = Path(work_dir) if work_dir is not None else _default_work_dir(out)
    full_spec = {"kind": kind, **(dict(spec) if spec is not None else {"overrides": overrides}),
                 "member_fn": _describe(member_fn), "objective_fn": _describe(objective_fn),
                 "scalars_fn": _describe(scalars_fn)}
    writer = EnsembleWriter(out, kind, full_spec, scenario, planned=overrides, resume=resume)
    with _client_or(client, cluster) as cl:
        writer.set_attrs(scheduler=str(cl.scheduler.address),
                         n_workers=len(cl.nthreads()))
        try:
            outcomes = run_members(members, member_fn, writer, cl, wd, retries=cluster.retries,
                                   scalars_fn=scalars_fn, objective_fn=objective_fn,
                                   transfer=transfer)
        except BaseException as exc:
            writer.close(error=exc)
            raise
    writer.close()
    if not keep_members and all(o.status == "complete" for o in outcomes):
        shutil.rmtree(wd, ignore_errors=True)
    return out, outcomes


def sweep(scenario: Scenario | None, spec: SweepSpec, out: str | os.PathLike,
          member_fn: Callable[[Member, Path], None] | None = None,
          cluster: ClusterSettings = ClusterSettings(), **kwargs: Any) -> Path:
    """Run a parameter sweep (``SweepSpec``) and gather it into one ensemble file.

    Parameters
    ----------
    scenario, out, member_fn, cluster : see ``map_overrides``
    spec : the sweep (fields, values, grid/zip, fixed overrides)
    **kwargs : ``map_overrides`` options (client, work_dir, resume, keep_members, preflight,
        scalars_fn, objective_fn, transfer)

    Returns
    -------
    path of the ensemble file
    """
    path, _ = map_overrides(scenario, spec.overrides(), out, member_fn, cluster, kind="sweep",
                            spec=spec.as_dict(), **kwargs)
    return path


@contextlib.contextmanager
def _client_or(client: Any, cluster: ClusterSettings) -> Iterator[Any]:
    if client is not None:
        yield client
    else:
        with dask_client(cluster) as cl:
            yield cl


# --------------------------------------------------------------------------------------------
# calibration
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FitParameter:
    """A scenario field fitted by ``calibrate``.

    Parameters
    ----------
    name : dotted scenario field (e.g. ``soil.material.young``)
    lower, upper : bounds [field unit], lower < upper
    log : search in log space (both bounds > 0); natural for moduli and stiffnesses
    initial : starting value (None: centre of the range, geometric centre if ``log``)
    """

    name: str
    lower: float
    upper: float
    log: bool = False
    initial: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lower) and math.isfinite(self.upper)
                and self.lower < self.upper):
            raise ValueError(f"FitParameter({self.name!r}).lower={self.lower!r}, "
                             f"upper={self.upper!r}: must be finite with lower < upper")
        if self.log and self.lower <= 0:
            raise ValueError(f"FitParameter({self.name!r}).lower={self.lower!r}: must be > 0 "
                             "with log=True")
        if self.initial is not None and not (self.lower <= self.initial <= self.upper):
            raise ValueError(f"FitParameter({self.name!r}).initial={self.initial!r}: must be in "
                             f"[{self.lower!r}, {self.upper!r}]")

    def to_unit(self, value: float) -> float:
        """Field value -> position in [0, 1] (log-scaled when ``log``)."""
        if self.log:
            return math.log(value / self.lower) / math.log(self.upper / self.lower)
        return (value - self.lower) / (self.upper - self.lower)

    def from_unit(self, u: float) -> float:
        """Position in [0, 1] -> field value (exactly ``lower``/``upper`` at 0/1)."""
        u = min(1.0, max(0.0, float(u)))
        if u == 0.0:
            return float(self.lower)
        if u == 1.0:
            return float(self.upper)
        if self.log:
            return float(self.lower * (self.upper / self.lower) ** u)
        return float(self.lower + u * (self.upper - self.lower))


def parse_fit_parameter(text: str) -> FitParameter:
    """``name=lower:upper[:log]`` or ``name=lower:upper:initial[:log]``."""
    if "=" not in text:
        raise ScenarioError(f"--param {text!r}: expected name=lower:upper[:log], e.g. "
                            "soil.material.young=1e7:8e7:log")
    name, raw = text.split("=", 1)
    parts = [p.strip() for p in raw.split(":")]
    log_scale = bool(parts) and parts[-1].lower() == "log"
    if log_scale:
        parts = parts[:-1]
    if len(parts) not in (2, 3):
        raise ScenarioError(f"--param {text!r}: expected name=lower:upper[:initial][:log]")
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        raise ScenarioError(f"--param {text!r}: bounds must be numbers") from None
    try:
        return FitParameter(name.strip(), nums[0], nums[1], log_scale,
                            nums[2] if len(nums) == 3 else None)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None


class PatternSearch:
    """Batched derivative-free minimiser on the unit box [0, 1]^n.

    Generation 0 evaluates an initial design (the start point plus a Latin hypercube); every
    later generation polls the 2n compass points ``x_best +- h e_i`` (clipped to the box) in
    parallel; the best improving point becomes the new centre, otherwise ``h`` is halved.
    The search stops when ``h < tol`` or the evaluation budget is spent. Points already
    evaluated are never re-evaluated.

    Parameters
    ----------
    n : number of parameters (>= 1)
    x0 : start point in [0, 1]^n
    n_init : size of the initial design (>= 1, includes x0)
    h0 : initial poll step (in (0, 1])
    tol : final step (in (0, h0))
    max_evals : evaluation budget (>= n_init)
    seed : Latin-hypercube seed

    Notes
    -----
    Compass search with complete polling converges to a stationary point of a continuously
    differentiable objective, with h the measure of stationarity (Kolda, Lewis & Torczon 2003,
    SIAM Review 45(3), theorem 3.3); polling all 2n points at once makes each generation one
    parallel batch (ibid., section 8).
    """

    def __init__(self, n: int, x0: Sequence[float], n_init: int, h0: float = 0.25,
                 tol: float = 1e-3, max_evals: int = 200, seed: int = 1) -> None:
        from scipy.stats import qmc

        if not (isinstance(n, int) and n >= 1):
            raise ValueError(f"PatternSearch.n={n!r}: must be an int >= 1")
        x0 = np.clip(np.asarray(x0, dtype=float), 0.0, 1.0)
        if x0.shape != (n,):
            raise ValueError(f"PatternSearch.x0 shape {x0.shape}: must be ({n},)")
        if not (isinstance(n_init, int) and n_init >= 1):
            raise ValueError(f"PatternSearch.n_init={n_init!r}: must be an int >= 1")
        if not (0 < h0 <= 1):
            raise ValueError(f"PatternSearch.h0={h0!r}: must be in (0, 1]")
        if not (0 < tol < h0):
            raise ValueError(f"PatternSearch.tol={tol!r}: must be in (0, h0={h0!r})")
        if not (isinstance(max_evals, int) and max_evals >= n_init):
            raise ValueError(f"PatternSearch.max_evals={max_evals!r}: must be an int >= "
                             f"n_init={n_init}")
        self.n, self.h, self.tol, self.max_evals = n, float(h0), float(tol), max_evals
        design = [x0]
        if n_init > 1:
            lhs = qmc.LatinHypercube(d=n, seed=seed).random(n_init - 1)
            design += list(lhs)
        self._pending = [np.asarray(p, dtype=float) for p in design]
        self.x_best: np.ndarray | None = None
        self.f_best = math.inf
        self.evaluated: dict[tuple[float, ...], float] = {}
        self.generation = 0
        self.stop_reason = ""

    @staticmethod
    def _key(x: np.ndarray) -> tuple[float, ...]:
        return tuple(np.round(x, 12).tolist())

    def ask(self) -> list[np.ndarray]:
        """The next batch of points to evaluate (empty list when the search has stopped)."""
        if self.stop_reason:
            return []
        while True:
            if self._pending:
                batch, self._pending = self._pending, []
            else:
                batch = []
                for i in range(self.n):
                    for s in (1.0, -1.0):
                        p = self.x_best.copy()
                        p[i] = min(1.0, max(0.0, p[i] + s * self.h))
                        batch.append(p)
            uniq: dict[tuple[float, ...], np.ndarray] = {}
            for p in batch:
                k = self._key(p)
                if k not in self.evaluated and k not in uniq:
                    uniq[k] = p
            room = self.max_evals - len(self.evaluated)
            if room <= 0:
                self.stop_reason = f"max_evals={self.max_evals} reached"
                return []
            pts = list(uniq.values())[:room]
            if pts:
                return pts
            # every poll point already known (clipped at the box): shrink and poll again
            if not self._shrink():
                return []

    def _shrink(self) -> bool:
        self.h *= 0.5
        if self.h < self.tol:
            self.stop_reason = f"step {self.h:.3g} < tol {self.tol:.3g}"
            return False
        return True

    def tell(self, points: Sequence[np.ndarray], values: Sequence[float]) -> None:
        """Report the objective values of the last batch (NaN/inf = failed member)."""
        improved = False
        for p, f in zip(points, values):
            f = float(f) if np.isfinite(f) else math.inf
            self.evaluated[self._key(p)] = f
            if f < self.f_best:
                self.f_best, self.x_best = f, np.asarray(p, dtype=float).copy()
                improved = True
        if self.x_best is None:
            self.stop_reason = "every point of the initial design failed"
            return
        if self.generation > 0 and not improved:
            self._shrink()
        self.generation += 1
        if len(self.evaluated) >= self.max_evals and not self.stop_reason:
            self.stop_reason = f"max_evals={self.max_evals} reached"


@dataclass(frozen=True)
class CalibrationResult:
    """Outcome of ``calibrate``.

    Attributes
    ----------
    best : fitted field -> value
    objective : objective value at ``best``
    n_evals : members evaluated (failed ones included)
    generations : batches submitted
    stop_reason : why the search stopped
    final_step : last poll step in the unit box (a resolution of the fitted values)
    path : the ensemble file
    """

    best: dict[str, float]
    objective: float
    n_evals: int
    generations: int
    stop_reason: str
    final_step: float
    path: Path


def calibrate(scenario: Scenario | None, params: Sequence[FitParameter],
              objective_fn: Callable[[Any], float], out: str | os.PathLike,
              member_fn: Callable[[Member, Path], None] | None = None,
              cluster: ClusterSettings = ClusterSettings(), *, client: Any = None,
              n_init: int | None = None, h0: float = 0.25, tol: float = 1e-3,
              max_evals: int = 200, seed: int = 1, fixed: Mapping[str, Any] | None = None,
              work_dir: str | os.PathLike | None = None, keep_members: bool = False,
              scalars_fn: Callable[[Any], dict[str, float]] | None = None,
              transfer: bool = False) -> CalibrationResult:
    """Fit scenario fields so that a finished member minimises ``objective_fn``.

    Each generation of the batched pattern search (``PatternSearch``) is one batch of members
    run in parallel on Dask; every member is gathered into the ensemble file as it finishes,
    and ``/calibration`` holds the parameters, the best point and the history.

    Parameters
    ----------
    scenario : base scenario (None for synthetic member functions)
    params : the fitted fields with bounds
    objective_fn : finished member (``crashdem.results.Result``) -> value to minimise, e.g.
        ``ChannelObjective(recorded_signal, "drop_mass_accel_z", metric="iso18571")``;
        evaluated on the worker
    out : ensemble file
    member_fn : default ``RunMember()``
    cluster, client : where to run
    n_init : initial-design size (default: max(2 n + 1, workers))
    h0, tol, max_evals, seed : see ``PatternSearch``
    fixed : overrides applied to every member
    work_dir, keep_members, scalars_fn, transfer : see ``sweep`` / ``run_members``

    Returns
    -------
    CalibrationResult
    """
    if not params:
        raise ValueError("calibrate: params is empty; name at least one FitParameter")
    names = [p.name for p in params]
    if len(set(names)) != len(names):
        raise ValueError(f"calibrate: parameter names repeat: {names}")
    fixed = dict(fixed or {})
    out = Path(out)
    if member_fn is None:
        member_fn = RunMember()
    check = _run_preflight if isinstance(member_fn, RunMember) else None
    # the whole box must be valid: check both bounds of every parameter before submitting
    corners = [{**fixed, p.name: b} for p in params for b in (p.lower, p.upper)]
    _validate_members(scenario, corners, check)
    base = scenario.to_toml() if scenario is not None else ""
    x0 = [p.to_unit(p.initial) if p.initial is not None else 0.5 for p in params]
    wd = Path(work_dir) if work_dir is not None else _default_work_dir(out)
    spec = {"kind": "calibration",
            "parameters": [{"name": p.name, "lower": p.lower, "upper": p.upper, "log": p.log,
                            "initial": p.initial} for p in params],
            "fixed": fixed, "objective_fn": _describe(objective_fn),
            "member_fn": _describe(member_fn),
            "optimiser": {"method": "parallel compass search", "h0": h0, "tol": tol,
                          "max_evals": max_evals, "seed": seed, "n_init": n_init}}
    writer = EnsembleWriter(out, "calibration", spec, scenario)
    hist_x: list[list[float]] = []
    hist_f: list[float] = []
    hist_gen: list[int] = []
    hist_best: list[float] = []
    with _client_or(client, cluster) as cl:
        n_workers = len(cl.nthreads()) or cluster.workers()
        writer.set_attrs(scheduler=str(cl.scheduler.address), n_workers=n_workers)
        opt = PatternSearch(len(params), x0, n_init or max(2 * len(params) + 1, n_workers),
                            h0=h0, tol=tol, max_evals=max_evals, seed=seed)
        index = 0
        try:
            while True:
                pts = opt.ask()
                if not pts:
                    break
                members = []
                for u in pts:
                    ov = {**fixed, **{p.name: p.from_unit(ui) for p, ui in zip(params, u)}}
                    scen = _validate_members(scenario, [ov], None)[0]
                    members.append(Member(index, ov, scen, base, generation=opt.generation))
                    index += 1
                outs = run_members(members, member_fn, writer, cl, wd, retries=cluster.retries,
                                   scalars_fn=scalars_fn, objective_fn=objective_fn,
                                   transfer=transfer)
                vals = [o.scalars.get("objective", math.nan) if o.status == "complete"
                        else math.nan for o in outs]
                gen = opt.generation
                opt.tell(pts, vals)
                for m, f in zip(members, vals):
                    hist_x.append([float(m.overrides[n]) for n in names])
                    hist_f.append(f)
                    hist_gen.append(gen)
                hist_best.append(opt.f_best)
                log.info("calibration generation %d: %d members, best objective %.6g, step %.3g",
                         gen, len(pts), opt.f_best, opt.h)
                _write_calibration(writer, params, opt, hist_x, hist_f, hist_gen, hist_best)
        except BaseException as exc:
            writer.close(error=exc)
            raise
    _write_calibration(writer, params, opt, hist_x, hist_f, hist_gen, hist_best)
    writer.close()
    if opt.x_best is None:
        raise RuntimeError(f"calibrate: no member finished ({opt.stop_reason}); see {out}")
    if not keep_members:
        shutil.rmtree(wd, ignore_errors=True)
    best = {p.name: p.from_unit(u) for p, u in zip(params, opt.x_best)}
    return CalibrationResult(best, opt.f_best, len(opt.evaluated), opt.generation,
                             opt.stop_reason, opt.h, out)


def _write_calibration(writer: EnsembleWriter, params: Sequence[FitParameter],
                       opt: PatternSearch, hist_x, hist_f, hist_gen, hist_best) -> None:
    info: dict[str, Any] = {"parameters": [p.name for p in params],
                            "best_objective": opt.f_best if math.isfinite(opt.f_best) else None,
                            "step": opt.h, "stop_reason": opt.stop_reason,
                            "n_evals": len(opt.evaluated), "generations": opt.generation}
    if opt.x_best is not None:
        for p, u in zip(params, opt.x_best):
            info[f"best:{p.name}"] = p.from_unit(u)
    n = len(params)
    writer.write_calibration(info, {
        "history_x": np.asarray(hist_x, dtype=float).reshape(-1, n),
        "history_objective": np.asarray(hist_f, dtype=float),
        "history_generation": np.asarray(hist_gen, dtype=np.int64),
        "best_objective_by_generation": np.asarray(hist_best, dtype=float)})


# --------------------------------------------------------------------------------------------
# reader
# --------------------------------------------------------------------------------------------
class EnsembleResult:
    """Read access to an ensemble file (also one whose gatherer was killed)."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._f = h5py.File(self.path, "r")
        fmt = _attr_value(self._f.attrs.get("format", ""))
        if fmt != ENSEMBLE_FORMAT:
            self._f.close()
            raise ValueError(f"{self.path}: attrs['format']={fmt!r}, expected "
                             f"{ENSEMBLE_FORMAT!r}")

    @property
    def status(self) -> str:
        return _attr_value(self._f.attrs["status"])

    @property
    def kind(self) -> str:
        return _attr_value(self._f.attrs["kind"])

    @property
    def spec(self) -> dict[str, Any]:
        return json.loads(_attr_value(self._f.attrs["spec"]))

    @property
    def provenance(self) -> dict[str, Any]:
        return {k: _attr_value(v) for k, v in self._f.attrs.items()}

    def planned(self) -> list[dict[str, Any]]:
        return [json.loads(_attr_value(s)) for s in self._f["spec/planned"][()]]

    def members(self) -> list[dict[str, Any]]:
        """Member records (index, key, status, error, attempts, worker, wall_time, generation,
        overrides, scalars), sorted by index."""
        recs = [_member_record(g) for g in self._f["members"].values()]
        return sorted(recs, key=lambda r: r["index"])

    def channels(self, index: int) -> list[str]:
        g = self._f["members"][str(index)]
        return list(g["channels"].keys()) if "channels" in g else []

    def channel(self, index: int, name: str, filtered: bool = True) -> Signal:
        """Channel ``name`` of member ``index`` (filtered data when stored, else raw)."""
        from crashdem.results import _raw_signal

        g = self._f["members"][str(index)]["channels"][name]
        raw = _raw_signal(name, g)
        if filtered and "filtered" in g:
            d = g["filtered"]
            n = min(raw.t.size, d.shape[0])
            return Signal(name, raw.t[:n], d[:n], _attr_value(d.attrs["unit"]),
                          float(d.attrs["cfc"]), dict(raw.meta))
        return raw

    def summary(self) -> str:
        """Human-readable summary: provenance line, then one line per member."""
        p = self.provenance
        recs = self.members()
        n_ok = sum(r["status"] == "complete" for r in recs)
        lines = [f"{self.path}",
                 f"  {self.kind} ensemble, status {self.status}: {n_ok}/{len(recs)} members "
                 f"complete" + (f" ({p.get('n_planned')} planned)" if p.get("n_planned")
                                else ""),
                 f"  crashdem {p.get('crashdem_version')} (git {p.get('git_hash')}), dask "
                 f"{p.get('dask_version')}, scheduler {p.get('scheduler', '-')}, "
                 f"{p.get('n_workers', '-')} workers",
                 f"  start {p.get('start_time')}, end {p.get('end_time') or '-'}"]
        for r in recs:
            ov = _fmt_overrides(r["overrides"])
            obj = r["scalars"].get("objective")
            lines.append(f"    [{r['index']}] {r['status']:<8s} {ov}"
                         + (f", objective {obj:.6g}" if obj is not None else "")
                         + (f", attempts {r['attempts']}" if r["attempts"] > 1 else "")
                         + (f": {r['error']}" if r["error"] else ""))
        cal = self.calibration()
        if cal:
            best = ", ".join(f"{k[5:]}={v:.6g}" for k, v in cal.items() if k.startswith("best:"))
            lines.append(f"  calibration: best {best}, objective {cal.get('best_objective')}, "
                         f"{cal.get('n_evals')} members, {cal.get('stop_reason')}")
        return "\n".join(lines)

    def calibration(self) -> dict[str, Any]:
        if "calibration" not in self._f:
            return {}
        g = self._f["calibration"]
        out = {k: _attr_value(v) for k, v in g.attrs.items()}
        out.update({k: g[k][()] for k in g})
        return out

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> "EnsembleResult":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def open_ensemble(path: str | os.PathLike) -> EnsembleResult:
    """Open an ensemble file for reading."""
    return EnsembleResult(path)


# --------------------------------------------------------------------------------------------
# CLI hooks (wired by crashdem/cli.py)
# --------------------------------------------------------------------------------------------
def add_cluster_arguments(p: argparse.ArgumentParser, set_option: bool = True) -> None:
    """The cluster options shared by ``sweep``, ``calibrate`` and ``diagnose --full-confirm``:
    ``--scheduler``, ``--workers``, ``--member-threads``, ``--retries``, ``--work-dir``,
    ``--keep-members`` (and ``--set`` unless ``set_option=False``, for a parser that has its
    own)."""
    _add_cluster_arguments(p, set_option)


def _add_cluster_arguments(p: argparse.ArgumentParser, set_option: bool = True) -> None:
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="existing Dask scheduler (default: a LocalCluster on this machine)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="LocalCluster worker processes (default: number of cores)")
    p.add_argument("--member-threads", type=int, default=1, metavar="N",
                   help="Numba threads per member run (default 1: one member per core)")
    p.add_argument("--retries", type=int, default=2, help="reruns of a member task that raised")
    p.add_argument("--work-dir", default=None,
                   help="member result files (default: OUT.members/; must be visible to the "
                        "workers)")
    p.add_argument("--keep-members", action="store_true",
                   help="keep the member result files after a successful ensemble")
    if set_option:
        p.add_argument("--set", action="append", metavar="KEY=VALUE",
                       help="override a scenario field for every member")


def add_sweep_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``crashdem sweep SCENARIO.toml --vary k=v1,v2 ... --out ENSEMBLE.h5``."""
    parser.add_argument("scenario")
    parser.add_argument("--vary", action="append", required=True, metavar="KEY=V1,V2,...",
                        help="a scenario field and its values (repeat for several fields)")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--grid", dest="mode", action="store_const", const="grid",
                      help="Cartesian product of the --vary lists (default)")
    mode.add_argument("--zip", dest="mode", action="store_const", const="zip",
                      help="i-th values of every --vary list together")
    parser.set_defaults(mode="grid")
    parser.add_argument("--out", required=True, help="ensemble HDF5 file")
    parser.add_argument("--resume", action="store_true",
                        help="continue an interrupted sweep in --out (keeps finished members)")
    _add_cluster_arguments(parser)


def add_calibrate_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``crashdem calibrate SCENARIO.toml --recording R --channel C --param ...``."""
    parser.add_argument("scenario")
    parser.add_argument("--recording", required=True, help="recording file (CSV, HDF5, ISO-MME)")
    parser.add_argument("--channel", required=True, help="recorded channel to fit")
    parser.add_argument("--sim-channel", default=None,
                        help="simulated channel compared with it (default: same name)")
    parser.add_argument("--param", action="append", required=True,
                        metavar="KEY=LOWER:UPPER[:INITIAL][:log]", help="a fitted field")
    parser.add_argument("--metric", choices=ChannelObjective.METRICS, default="iso18571")
    parser.add_argument("--t-window", default=None, metavar="T0,T1",
                        help="evaluation interval [s]")
    parser.add_argument("--max-evals", type=int, default=60)
    parser.add_argument("--n-init", type=int, default=None,
                        help="initial-design size (default max(2n+1, workers))")
    parser.add_argument("--tol", type=float, default=1e-2,
                        help="final poll step as a fraction of each range")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", required=True, help="ensemble HDF5 file")
    _add_cluster_arguments(parser)


def _cluster_from_args(args: argparse.Namespace) -> ClusterSettings:
    return ClusterSettings(scheduler=args.scheduler, n_workers=args.workers,
                           retries=args.retries)


def _base_from_args(args: argparse.Namespace) -> tuple[Scenario, dict[str, Any]]:
    from crashdem import scenario as sc

    fixed = dict(sc.parse_override(s) for s in (args.set or []))
    return sc.load(args.scenario), fixed


def sweep_command(args: argparse.Namespace) -> int:
    """``crashdem sweep``: prints the ensemble path; exit code 1 if some member failed."""
    base, fixed = _base_from_args(args)
    vary = dict(parse_vary(v) for v in args.vary)
    spec = SweepSpec(vary, mode=args.mode or "grid", fixed=fixed)
    path = sweep(base, spec, args.out, RunMember(threads=args.member_threads),
                 _cluster_from_args(args), work_dir=args.work_dir, resume=args.resume,
                 keep_members=args.keep_members)
    with open_ensemble(path) as ens:
        recs = ens.members()
    failed = [r for r in recs if r["status"] != "complete"]
    for r in failed:
        print(f"member {r['index']} ({_fmt_overrides(r['overrides'])}) failed: {r['error']}")
    print(path)
    return 1 if failed else 0


def calibrate_command(args: argparse.Namespace) -> int:
    """``crashdem calibrate``: prints the fitted values and the ensemble path."""
    from crashdem.recordings import read_recording

    base, fixed = _base_from_args(args)
    params = [parse_fit_parameter(p) for p in args.param]
    ref = next(iter(read_recording(args.recording, channels=[args.channel]).values()))
    tw = None
    if args.t_window:
        try:
            a, b = (float(x) for x in args.t_window.split(","))
        except ValueError:
            raise ValueError(f"--t-window {args.t_window!r}: expected T0,T1 in s") from None
        tw = (a, b)
    obj = ChannelObjective(ref, args.sim_channel or args.channel, args.metric, tw)
    res = calibrate(base, params, obj, args.out, RunMember(threads=args.member_threads),
                    _cluster_from_args(args), n_init=args.n_init, tol=args.tol,
                    max_evals=args.max_evals, seed=args.seed, fixed=fixed,
                    work_dir=args.work_dir, keep_members=args.keep_members)
    for k, v in res.best.items():
        print(f"{k} = {v:.6g}")
    print(f"objective ({args.metric}) = {res.objective:.6g} after {res.n_evals} members, "
          f"{res.generations} generations ({res.stop_reason})")
    print(res.path)
    return 0

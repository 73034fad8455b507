"""The diagnosis fanned out over Dask: the full-DEM confirmation runs as one ensemble.

The expensive part of a diagnosis is the confirmation (the last step of
``crashdem.diagnosis.screen_then_confirm``): one full simulation for the recalibration and one
per top-k hypothesis, all independent. :class:`DaskFullSimulator` is a full simulator with a
``map`` method, so ``screen_then_confirm`` requests the 1 + k runs in one batch; the batch goes through the
ensemble runner (``crashdem.ensemble.map_overrides``): a LocalCluster by default or an
existing scheduler, one Dask task per run, a worker lost mid-run rerun elsewhere, and the runs
gathered into ONE ensemble HDF5 file (``kind = "members"``, its spec naming the diagnosis).
The scores and the decision are computed by the same code as the serial confirmation, from
the same channels, so the answer is the same (tested).

API
---
``scenario_overrides(scenario, overrides) -> dict``
    a confirmation run's overrides (``physics.*`` keys and ``calibration.*_scale`` factors) as
    scenario fields (the factors applied to the scenario's soil values), as the serial
    ``crashdem diagnose --full-confirm`` does.
``DaskFullSimulator(scenario, out, channel_map=None, member_fn=None, cluster=..., client=None)``
    ``map([overrides, ...]) -> [signals, ...]`` (one ensemble file per call), ``__call__``.
``distributed_confirm(baseline, recording, scenario, out, top_k=2, ...) -> Report``
    ``screen_then_confirm`` with the confirmation on Dask.
``full_simulator_from_args(args, scenario, channel_map)``: the CLI hook
    (``crashdem diagnose --full-confirm N [--scheduler ADDRESS | --workers N]``).

The screening fits (ROM, ``crashdem.diagnosis.fit``) stay in the client process: on the drop
test they take a few seconds for the whole catalogue (measured 5 s for 9 hypotheses), well
below one full DEM run, so a fan-out would mostly add task overhead.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from crashdem.signal import Signal

__all__ = ["DaskFullSimulator", "distributed_confirm", "full_simulator_from_args",
           "scenario_overrides", "RADIUS_SCALE_KEY"]

#: override key of a run with the scenario's grain radius times this factor (not a scenario
#: field: ``scenario_overrides`` makes it ``soil.radius``)
RADIUS_SCALE_KEY = "numerics.radius_scale"
#: allowed range of that factor
RADIUS_SCALE_RANGE = (0.5, 2.0)


def scenario_overrides(scenario: Any, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Scenario-field overrides of one confirmation run.

    ``calibration.stiffness_scale`` / ``strength_scale`` / ``drag_scale`` factors become
    absolute ``soil.material.young`` / ``friction_angle_deg`` / ``density`` values of
    ``scenario`` (``crashdem.diagnosis.cli._apply_scales``); every other key is a scenario
    field and is kept. A hypothesis's rigid floor at or above the scenario's own layer
    interface (``boundary_proximity`` in a layered bed: the reference drop scenarios have the
    compacted layer at 1 m) ends the soil column before the interface, so the lower layer is
    not there: the run gets ``physics.soil_layering.enabled = false`` unless the overrides set
    the layering themselves (before, such a floor was refused by the scenario check and every
    floor above 1 m went unsearched). ``numerics.radius_scale`` (``RADIUS_SCALE_KEY``: the
    numerics check of a named value) multiplies the scenario's grain radius.
    """
    from crashdem.diagnosis.cli import _apply_scales

    scales = {k: v for k, v in overrides.items() if k.startswith("calibration.")}
    keys = {k: v for k, v in overrides.items()
            if not k.startswith("calibration.") and k != RADIUS_SCALE_KEY}
    if RADIUS_SCALE_KEY in overrides:
        f = float(overrides[RADIUS_SCALE_KEY])
        lo, hi = RADIUS_SCALE_RANGE
        if not lo <= f <= hi:
            raise ValueError(f"{RADIUS_SCALE_KEY}={f!r}: must be in [{lo:g}, {hi:g}] (a factor "
                             f"on the scenario's grain radius)")
        keys["soil.radius"] = float(keys.get("soil.radius", scenario.get("soil.radius"))) * f

    def get(key: str) -> Any:
        return keys[key] if key in keys else scenario.get(key)

    floor = get("physics.boundary_proximity.floor_depth")
    if (get("physics.boundary_proximity.enabled") and floor is not None
            and "physics.soil_layering.enabled" not in keys
            and get("physics.soil_layering.enabled")
            and float(floor) <= float(get("physics.soil_layering.depth"))):
        keys["physics.soil_layering.enabled"] = False
    return _apply_scales(scenario, scales) | keys


class DaskFullSimulator:
    """Full simulator of the diagnosis confirmation whose runs fan out over Dask.

    Parameters
    ----------
    scenario : crashdem.scenario.Scenario
        The diagnosed scenario (every run is this scenario with a hypothesis's overrides).
    out : path
        Ensemble HDF5 file of the first batch; a later batch writes ``<stem>-<k>.h5`` (k = 1, 2...).
    channel_map : dict or None
        result channel name -> name returned (e.g. ``{"drop_mass_accel_z": "accel_z"}``);
        None returns every channel under its own name.
    member_fn : ``member_fn(member, path)`` writing one crashdem result (default
        ``crashdem.ensemble.RunMember(threads=member_threads)``: a full ``crashdem.run`` run)
    member_threads : Numba threads per run of the default member function, >= 0
    run_cache : ``crashdem.runcache.RunCache`` of the default member function (runs made
        before are taken from it, new ones kept there; its ``hits`` / ``runs`` count them)
    cluster : crashdem.ensemble.ClusterSettings
        LocalCluster (default) or ``scheduler`` address; ``retries``.
    client : an existing ``distributed.Client`` (then ``cluster`` only gives ``retries``)
    work_dir, keep_members, transfer : see ``crashdem.ensemble.map_overrides``
    filtered : read the runs' filtered channels (their CFC class), as ``read_recording`` does

    Attributes
    ----------
    ensembles : list of Path, one per ``map`` call
    outcomes : list of the member outcomes of every call
    calls : number of full simulations run
    """

    def __init__(self, scenario: Any, out: str | os.PathLike,
                 channel_map: Mapping[str, str] | None = None,
                 member_fn: Callable[[Any, Path], None] | None = None, member_threads: int = 1,
                 cluster: Any = None, client: Any = None,
                 work_dir: str | os.PathLike | None = None, keep_members: bool = False,
                 transfer: bool = False, filtered: bool = True, run_cache: Any = None) -> None:
        from crashdem import ensemble as en

        if scenario is None:
            raise ValueError("DaskFullSimulator.scenario=None: the confirmation runs need the "
                             "diagnosed scenario")
        self.scenario = scenario
        self.out = Path(out)
        if self.out.suffix != ".h5":
            raise ValueError(f"DaskFullSimulator.out={str(out)!r}: must be an .h5 file")
        self.channel_map = dict(channel_map) if channel_map is not None else None
        self.member_fn = member_fn if member_fn is not None else en.RunMember(
            threads=member_threads, run_cache=run_cache)
        # the cache the members use, when they say which scenario they run (to count its hits)
        self.run_cache = (getattr(self.member_fn, "run_cache", None)
                          if hasattr(self.member_fn, "member_scenario") else None)
        self.cluster = cluster if cluster is not None else en.ClusterSettings()
        self.client = client
        self.work_dir = work_dir
        self.keep_members = keep_members
        self.transfer = transfer
        self.filtered = filtered
        self.ensembles: list[Path] = []
        self.outcomes: list[Any] = []
        self.calls = 0

    def _next_path(self) -> Path:
        k = len(self.ensembles)
        return self.out if k == 0 else self.out.with_name(f"{self.out.stem}-{k}.h5")

    def map(self, overrides: Sequence[Mapping[str, Any]]) -> list[dict[str, Signal]]:
        """Run one full simulation per overrides dict (in parallel) and return their channels,
        in order.

        Raises
        ------
        RuntimeError
            If a run failed (diverged, killed every worker it ran on): its error is named,
            since a confirmation cannot be scored without it; the ensemble file keeps the runs.
        """
        from crashdem import ensemble as en

        overrides = [dict(o) for o in overrides]
        fields = [scenario_overrides(self.scenario, o) for o in overrides]
        path = self._next_path()
        cached = sum(self._cached(f) for f in fields)  # runs the members take from the cache
        spec = {"purpose": "diagnosis full-simulation confirmation",
                "hypothesis_overrides": overrides, "overrides": fields}
        wd = self.work_dir
        if wd is not None and self.ensembles:
            wd = Path(wd) / f"batch-{len(self.ensembles)}"
        path, outcomes = en.map_overrides(
            self.scenario, fields, path, self.member_fn, self.cluster, client=self.client,
            kind="members", spec=spec, work_dir=wd, keep_members=self.keep_members,
            transfer=self.transfer)
        self.ensembles.append(path)
        self.outcomes.extend(outcomes)
        self.calls += len(outcomes)
        if self.run_cache is not None:
            self.run_cache.hits += cached
            self.run_cache.runs += len(outcomes) - cached
        failed = [o for o in outcomes if o.status != "complete"]
        if failed:
            lines = "; ".join(f"member {o.index} ({en._fmt_overrides(fields[o.index])}): "
                              f"{o.error}" for o in failed)
            raise RuntimeError(f"full-simulation confirmation: {len(failed)} of {len(outcomes)} "
                               f"runs failed ({path}): {lines}")
        from crashdem.diagnosis.cli import sim_channel

        out: list[dict[str, Signal]] = []
        with en.open_ensemble(path) as ens:
            for o in outcomes:
                names = ens.channels(o.index)
                cmap = self.channel_map if self.channel_map is not None else {n: n for n in names}
                got = {}
                for name, new in cmap.items():
                    # the recorded name, else the impactor channel standing for the model one
                    src = name if name in names else sim_channel(names, new)
                    if src in names:
                        got[new] = _renamed(ens.channel(o.index, src, filtered=self.filtered), new)
                out.append(got)
        return out

    def _cached(self, fields: Mapping[str, Any]) -> bool:
        """Whether the member of scenario fields ``fields`` is in the run cache (False without
        one, or for fields the scenario refuses: ``map_overrides`` then names them)."""
        if self.run_cache is None:
            return False
        try:
            scen = self.member_fn.member_scenario(self.scenario.with_overrides(dict(fields)))
        except Exception:  # noqa: BLE001 - refused later, with the member named
            return False
        return self.run_cache.lookup(scen) is not None

    def __call__(self, overrides: Mapping[str, Any]) -> dict[str, Signal]:
        return self.map([overrides])[0]

    def describe(self) -> dict[str, Any]:
        """What the report records under ``simulations`` (ensemble files, scheduler)."""
        import h5py

        info: dict[str, Any] = {"ensembles": [str(p) for p in self.ensembles],
                                "full_simulation_wall_s": [o.wall_time for o in self.outcomes],
                                "attempts": [o.attempts for o in self.outcomes]}
        if self.ensembles:
            with h5py.File(self.ensembles[0], "r") as f:
                for k in ("scheduler", "n_workers"):
                    v = f.attrs.get(k)
                    if v is not None:
                        info[k] = v.decode() if isinstance(v, bytes) else (
                            int(v) if k == "n_workers" else str(v))
        return info


def _renamed(s: Signal, name: str) -> Signal:
    if s.name == name:
        return s
    return Signal(name, s.t, s.data, s.unit, s.cfc, dict(s.meta))


def distributed_confirm(baseline_signals: Mapping[str, Signal],
                        recording_signals: Mapping[str, Signal], scenario: Any,
                        out: str | os.PathLike, *, top_k: int = 2,
                        channel_map: Mapping[str, str] | None = None,
                        member_fn: Callable[[Any, Path], None] | None = None,
                        member_threads: int = 1, cluster: Any = None, client: Any = None,
                        work_dir: str | os.PathLike | None = None, keep_members: bool = False,
                        **diagnose_kw: Any):
    """``screen_then_confirm`` whose 1 + ``top_k`` full simulations run as one Dask ensemble.

    Parameters
    ----------
    baseline_signals, recording_signals, top_k, diagnose_kw : as ``screen_then_confirm``
    scenario, out, channel_map, member_fn, member_threads, cluster, client, work_dir,
    keep_members : as :class:`DaskFullSimulator`

    Returns
    -------
    Report; ``simulations["confirmation"]`` names the ensemble file(s) and the scheduler.
    """
    from crashdem.diagnosis import screen_then_confirm

    full = DaskFullSimulator(scenario, out, channel_map, member_fn, member_threads, cluster,
                             client, work_dir, keep_members)
    rep = screen_then_confirm(baseline_signals, recording_signals, full, top_k=top_k,
                              **diagnose_kw)
    rep.simulations["confirmation"] = full.describe()
    return rep


def full_simulator_from_args(args: Any, scenario: Any, channel_map: Mapping[str, str],
                             run_cache: Any = None) -> DaskFullSimulator:
    """The confirmation simulator of ``crashdem diagnose --full-confirm N``: a LocalCluster of
    ``--workers`` processes (default: cores) or the cluster at ``--scheduler``; the runs are
    gathered in ``OUT/confirmation.h5`` (and kept in / taken from ``run_cache``)."""
    from crashdem import ensemble as en

    workers = getattr(args, "workers", None)
    if workers is not None and not (isinstance(workers, int) and workers >= 0):
        raise ValueError(f"--workers={workers!r}: must be an int >= 0 (0 = runs in this process, "
                         "no Dask)")
    cluster = en.ClusterSettings(scheduler=getattr(args, "scheduler", None),
                                 n_workers=workers or None,
                                 retries=int(getattr(args, "retries", 2)))
    threads = getattr(args, "member_threads", 1)
    if not (isinstance(threads, int) and threads >= 0):
        raise ValueError(f"--member-threads={threads!r}: must be an int >= 0 (0 = all cores)")
    return DaskFullSimulator(scenario, Path(args.out) / "confirmation.h5",
                             channel_map=channel_map, member_threads=threads, cluster=cluster,
                             work_dir=getattr(args, "work_dir", None),
                             keep_members=bool(getattr(args, "keep_members", False)),
                             run_cache=run_cache)

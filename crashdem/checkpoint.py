"""Restart checkpoints of a coupled run: one HDF5 file next to the result, written atomically.

API
---
``checkpoint_path(result_path) -> Path``            ``<name>.ckpt.h5`` next to ``<name>.h5``
``scenario_hash(scenario) -> str``                  SHA-256 of what decides the results
``write_checkpoint(path, checkpoint) -> Path``      atomic: temp file, fsync, rename
``read_checkpoint(path) -> Checkpoint``
``Checkpoint.check_scenario(scenario)``             refuse another scenario (both hashes named)
``Checkpoint.capture(model, t, loop, ...)``          the state of a running ``crashdem.run.Model``
``Checkpoint.restore(model)``                       put the saved state into a freshly built
                                                    ``crashdem.run.Model`` (drop test, glider)

A checkpoint holds the DEM state (``soil.Simulation.state_dict()``: arrays as datasets, the
boundary objects pickled), the coupling and Exudyn state (``CoSimulation.state_dict()``, with
the Exudyn reference configuration and ODE2 coordinates for a bit-exact restart), the pickled
``crashdem.sensors.SensorSet`` (an opaque ``uint8`` dataset), the state of every stateful
*component* the model lists (``Model.components``: the glider's compliant walls and
fuselage-wall contact, ...), the run loop's counters, the scenario hash and the crashdem
version. The layout is documented in ``docs/restart.md``.

Component protocol
------------------
Anything a run keeps outside the DEM, the coupling and the sensors (and that changes during
the run) is a component, listed by name in ``Model.components``; it implements

``state_dict() -> dict``            its evolving state (arrays, scalars, nested dicts; copies)
``load_state_dict(d) -> None``      restore it in place, bit for bit
``rebind(old_sim, new_sim)``        optional: replace references to boundary bodies of the
                                    DEM being replaced by the same-index bodies of the DEM
                                    rebuilt from the checkpoint (called before loading)

A plain ``dict`` (exact type) is a component too: its items are the state (deep-copied, restored
with ``clear()`` + ``update()``), e.g. a per-step value store read by sensors.

Components are restored *in place*, so closures and other objects of the freshly built model
that hold them (the glider's per-step wall update) keep working. The sensor set is pickled
with the components as *persistent references* (``pickle`` ``persistent_id``): a sensor
reading a component (``crashdem.glider.WallChannel``) is reconnected to the live component
of the resumed model instead of a stale copy; the coupled Exudyn model is such a reference too
(:data:`MODEL_REF`), restored in place through the coupling's state.

Notes
-----
Atomic replacement: POSIX ``rename(2)`` replaces the target in one step; the data are made
durable first with ``fsync(2)`` on the temporary file and then on the directory, so a reader
(or a resumed run) sees either the previous complete checkpoint or the new complete one.
"""
from __future__ import annotations

import copy
import hashlib
import io
import json
import math
import os
import pickle
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

#: ``attrs["format"]`` of a checkpoint file
FORMAT_NAME = "crashdem-checkpoint"
#: layout version written (2: ``/components`` and component references in ``/sensors``)
FORMAT_VERSION = 2
#: layout versions this reader accepts (1 = drop-test checkpoints without components)
READABLE_VERSIONS = (1, 2)
#: scenario fields that cannot change the results (where files go, plots, checkpoint cadence);
#: they are left out of the scenario hash so that a run can be resumed with other values
HASH_EXCLUDED = (("output", "directory"), ("output", "plots"), ("output", "checkpoint_every_s"))
#: pickle protocol of opaque objects (Python >= 3.8)
PICKLE_PROTOCOL = 5


class CheckpointError(ValueError):
    """A checkpoint is missing, unreadable, or belongs to another scenario or version."""


def checkpoint_path(result_path: str | os.PathLike) -> Path:
    """The checkpoint file of a result: ``<dir>/<name>.ckpt.h5`` for ``<dir>/<name>.h5``."""
    p = Path(result_path)
    return p.with_name(p.stem + ".ckpt.h5")


def scenario_hash(scenario: Any) -> str:
    """SHA-256 (hex) of the scenario data that decide the results.

    Parameters
    ----------
    scenario : crashdem.scenario.Scenario (or a nested dict of its data)

    Notes
    -----
    Canonical JSON of ``scenario.data`` (sorted keys) without the fields in
    :data:`HASH_EXCLUDED`; SHA-256 (FIPS 180-4).
    """
    data = copy.deepcopy(getattr(scenario, "data", scenario))
    for sect, key in HASH_EXCLUDED:
        if isinstance(data.get(sect), dict):
            data[sect].pop(key, None)
    text = json.dumps(data, sort_keys=True, default=repr, allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _crashdem_version() -> str:
    import crashdem

    return str(crashdem.__version__)


# --------------------------------------------------------------------------------------------
# nested state <-> HDF5 (arrays and scalars bit-exact; other objects pickled)
# --------------------------------------------------------------------------------------------
_SCALARS = {bool: "bool", int: "int", float: "float", str: "str"}


def _put(g: h5py.Group, name: str, obj: Any) -> None:
    """Store ``obj`` as member ``name`` of ``g`` (recursive)."""
    # exact types only: subclasses (OrderedDict, np.matrix, ...) go through pickle, so that
    # every entry comes back with its own type
    if type(obj) is dict and all(isinstance(k, str) for k in obj):
        sub = g.create_group(name)
        sub.attrs["kind"] = "dict"
        keys = list(obj)
        sub.attrs["keys"] = json.dumps(keys)
        for i, k in enumerate(keys):
            _put(sub, str(i), obj[k])
    elif type(obj) in (list, tuple):
        sub = g.create_group(name)
        sub.attrs["kind"] = type(obj).__name__
        sub.attrs["n"] = len(obj)
        for i, v in enumerate(obj):
            _put(sub, str(i), v)
    elif type(obj) is np.ndarray and obj.dtype.kind in "biufc" and not obj.dtype.fields:
        d = g.create_dataset(name, data=obj)
        d.attrs["kind"] = "ndarray"
        d.attrs["fortran"] = bool(obj.flags.f_contiguous and not obj.flags.c_contiguous)
    elif isinstance(obj, np.generic) and np.asarray(obj).dtype.kind in "biufc":
        d = g.create_dataset(name, data=np.asarray(obj))
        d.attrs["kind"] = "npscalar"
    elif obj is None:
        d = g.create_dataset(name, data=np.zeros(0, dtype=np.uint8))
        d.attrs["kind"] = "none"
    elif type(obj) in _SCALARS and not (type(obj) is int and not -2**63 <= obj < 2**63):
        kind = _SCALARS[type(obj)]
        if kind == "str":
            d = g.create_dataset(name, data=obj, dtype=h5py.string_dtype())
        else:
            d = g.create_dataset(name, data={"bool": np.bool_, "int": np.int64,
                                             "float": np.float64}[kind](obj))
        d.attrs["kind"] = kind
    else:
        blob = pickle.dumps(obj, protocol=PICKLE_PROTOCOL)
        d = g.create_dataset(name, data=np.frombuffer(blob, dtype=np.uint8))
        d.attrs["kind"] = "pickle"
        d.attrs["type"] = f"{type(obj).__module__}.{type(obj).__qualname__}"


def _get(node: h5py.Group | h5py.Dataset) -> Any:
    """Inverse of :func:`_put`."""
    kind = node.attrs["kind"]
    if isinstance(kind, bytes):
        kind = kind.decode()
    if kind == "dict":
        keys = json.loads(node.attrs["keys"])
        return {k: _get(node[str(i)]) for i, k in enumerate(keys)}
    if kind in ("list", "tuple"):
        items = [_get(node[str(i)]) for i in range(int(node.attrs["n"]))]
        return items if kind == "list" else tuple(items)
    if kind == "ndarray":
        # np.array keeps 0-d arrays 0-d (np.ascontiguousarray would make them 1-d)
        return np.array(node[()], order="F" if node.attrs["fortran"] else "C")
    if kind == "npscalar":
        return node[()].dtype.type(node[()])
    if kind == "none":
        return None
    if kind == "bool":
        return bool(node[()])
    if kind == "int":
        return int(node[()])
    if kind == "float":
        return float(node[()])
    if kind == "str":
        v = node[()]
        return v.decode() if isinstance(v, bytes) else str(v)
    if kind == "pickle":
        return pickle.loads(node[()].tobytes())
    raise CheckpointError(f"checkpoint: unknown entry kind {kind!r} at {node.name}")


# --------------------------------------------------------------------------------------------
# the checkpoint
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Checkpoint:
    """State of a coupled run at DEM time ``t``.

    Attributes
    ----------
    t : float
        DEM time of the checkpoint [s].
    soil : dict
        ``soil.Simulation.state_dict()``.
    cosim : dict
        ``coupling.CoSimulation.state_dict()`` (Exudyn state included).
    sensors : crashdem.sensors.SensorSet
        The sensor set with its filter states and undrained samples.
    loop : dict
        Run-loop counters: ``steps`` (sensor records so far, the first one at t = 0),
        ``snap`` (snapshots written), ``next_checkpoint`` (time of the next one) [s]. The
        resumed progress bar starts at ``t`` and counts the steps after ``steps``.
    scenario_hash : str
        :func:`scenario_hash` of the run's scenario.
    crashdem_version : str
    complete : bool
        True for the checkpoint written at the end of a finished run (the final state).
    components : dict
        name -> ``state_dict()`` of each component of the model (``Model.components``).
    refs : dict
        name -> live component object: when writing, the sensor set is pickled with these as
        persistent references. After :func:`read_checkpoint` of a checkpoint with components,
        ``sensors`` is a :class:`PickledSensors` resolved by :meth:`restore`.
    """

    t: float
    soil: dict
    cosim: dict
    sensors: Any
    loop: dict = field(default_factory=dict)
    scenario_hash: str = ""
    crashdem_version: str = ""
    complete: bool = False
    components: dict = field(default_factory=dict)
    #: live component objects the sensor pickle refers to by name (writing only)
    refs: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not math.isfinite(self.t):
            raise ValueError(f"Checkpoint.t={self.t!r}: must be finite [s]")
        for k in ("steps", "snap"):
            v = self.loop.get(k, 0)
            if not (isinstance(v, (int, np.integer)) and v >= 0):
                raise ValueError(f"Checkpoint.loop[{k!r}]={v!r}: must be an int >= 0")

    def check_scenario(self, scenario: Any, path: str | os.PathLike = "") -> None:
        """Raise :class:`CheckpointError` unless ``scenario`` is the checkpointed one.

        The message names both hashes and the checkpoint file.
        """
        h = scenario_hash(scenario)
        if h != self.scenario_hash:
            raise CheckpointError(
                f"checkpoint {path or '(in memory)'} belongs to another scenario: checkpoint "
                f"scenario hash {self.scenario_hash}, this scenario's hash {h}; resume with the "
                "same scenario file and overrides (only output.directory, output.plots and "
                "output.checkpoint_every_s may differ), or run without --resume")
        here = _crashdem_version()
        if self.crashdem_version != here:
            raise CheckpointError(
                f"checkpoint {path or '(in memory)'} was written by crashdem "
                f"{self.crashdem_version}, this is crashdem {here}: a bit-identical restart "
                "needs the same version; run without --resume")

    @classmethod
    def capture(cls, model: Any, t: float, loop: dict | None = None, scenario_hash: str = "",
                complete: bool = False) -> "Checkpoint":
        """The state of a running ``crashdem.run.Model`` at DEM time ``t`` [s].

        DEM, coupling (with the Exudyn body), every component's ``state_dict()`` and the
        sensor set (pickled at write time, with the components as references).
        """
        comps = _components(model)
        return cls(t=float(t), soil=model.sim.state_dict(), cosim=model.cosim.state_dict(),
                   sensors=model.sensors, loop=dict(loop or {}), scenario_hash=scenario_hash,
                   complete=complete,
                   components={name: _state_of(c) for name, c in comps.items()},
                   refs=_refs(model, comps))

    def restore(self, model: Any) -> Any:
        """Put the saved state into a freshly built ``crashdem.run.Model`` (same scenario).

        The DEM is rebuilt by ``soil.Simulation.from_state_dict`` and the coupling by
        ``coupling.CoSimulation.from_state_dict`` on the model's Exudyn body; every component
        of the model is rebound to the new DEM (``rebind``) and loaded in place
        (``load_state_dict``); the sensor set is replaced by the saved one, its references to
        components resolved to the model's live components. Returns the model (modified in
        place).

        Raises
        ------
        CheckpointError
            If the model's components are not the checkpoint's (names compared), or the
            model keeps state outside the DEM without declaring components.
        """
        import coupling
        import soil

        comps = _components(model)
        if sorted(comps) != sorted(self.components):
            raise CheckpointError(
                f"checkpoint restore: the checkpoint holds the components "
                f"{sorted(self.components)}, the model has {sorted(comps)}; resume with the "
                "same scenario and crashdem version")
        old_sim = model.sim
        sim = soil.Simulation.from_state_dict(self.soil)
        cosim = coupling.CoSimulation.from_state_dict(sim, model.body_index, model.model,
                                                      self.cosim)
        for name, c in comps.items():
            if hasattr(c, "rebind"):
                c.rebind(old_sim, sim)
            _load_state(c, self.components[name])
        model.sim = sim
        model.cosim = cosim
        sensors = self.sensors
        if isinstance(sensors, PickledSensors):
            sensors = sensors.load(_refs(model, comps))
        model.sensors = sensors
        return model


class PickledSensors:
    """A sensor set read from a checkpoint that refers to components: unpickled by
    :meth:`load` once the live components of the resumed model exist."""

    def __init__(self, blob: bytes, refs: list[str]) -> None:
        self.blob = bytes(blob)
        self.refs = list(refs)

    def load(self, components: dict[str, Any]) -> Any:
        missing = [r for r in self.refs if r not in components]
        if missing:
            raise CheckpointError(f"checkpoint sensors refer to components {missing} the "
                                  f"model does not have (it has {sorted(components)})")
        return _RefUnpickler(io.BytesIO(self.blob), components).load()


class _RefPickler(pickle.Pickler):
    """Pickler writing the given objects as persistent references (their names)."""

    def __init__(self, file: Any, refs: dict[str, Any]) -> None:
        super().__init__(file, protocol=PICKLE_PROTOCOL)
        self._names = {id(obj): name for name, obj in refs.items()}
        self.used: set[str] = set()

    def persistent_id(self, obj: Any) -> str | None:
        name = self._names.get(id(obj))
        if name is not None:
            self.used.add(name)
        return name


class _RefUnpickler(pickle.Unpickler):
    def __init__(self, file: Any, refs: dict[str, Any]) -> None:
        super().__init__(file)
        self._refs = refs

    def persistent_load(self, pid: Any) -> Any:
        try:
            return self._refs[pid]
        except KeyError:
            raise CheckpointError(f"checkpoint sensors refer to an unknown component "
                                  f"{pid!r}") from None


def check_restartable(model: Any, what: str = "checkpoints") -> None:
    """Raise ``ScenarioError`` before a run starts if ``model`` cannot be checkpointed (state
    outside the DEM without declared components, a component or an Exudyn model without
    ``state_dict``), instead of failing at the first checkpoint."""
    from crashdem.scenario import ScenarioError

    try:
        _components(model)
        model.model.state_dict()
    except (CheckpointError, NotImplementedError) as exc:
        raise ScenarioError(f"{what}: this scenario cannot be restarted: {exc}") from None


#: name of the coupled Exudyn model as a persistent reference of the sensor pickle (a sensor
#: reading the model, e.g. the crush element's channels, sees the resumed model)
MODEL_REF = "__coupled_model__"


def _refs(model: Any, comps: dict[str, Any]) -> dict[str, Any]:
    """Objects the sensor pickle refers to by name: the components and the coupled Exudyn
    model (restored in place by ``CoSimulation.from_state_dict``)."""
    out = dict(comps)
    if getattr(model, "model", None) is not None:
        out[MODEL_REF] = model.model
    return out


def _state_of(c: Any) -> Any:
    if type(c) is dict:
        return copy.deepcopy(c)
    return c.state_dict()


def _load_state(c: Any, d: Any) -> None:
    if type(c) is dict:
        c.clear()
        c.update(copy.deepcopy(d))
    else:
        c.load_state_dict(d)


def _components(model: Any) -> dict[str, Any]:
    """``model.components``, checked against the component protocol."""
    comps = dict(getattr(model, "components", None) or {})
    if not comps and (model.pre_record is not None or model.extra):
        raise CheckpointError(
            "checkpoint: this model carries state outside the DEM, the coupling and the "
            "sensors (pre_record/extra) but declares no components (Model.components); "
            "a restart would lose that state")
    for name, c in comps.items():
        if type(c) is dict:  # a plain dict: its items are the state
            continue
        for meth in ("state_dict", "load_state_dict"):
            if not callable(getattr(c, meth, None)):
                raise CheckpointError(
                    f"checkpoint: component {name!r} ({type(c).__name__}) has no {meth}(); "
                    "every entry of Model.components must implement state_dict() and "
                    "load_state_dict(d)")
    return comps


def write_checkpoint(path: str | os.PathLike, ckpt: Checkpoint) -> Path:
    """Write ``ckpt`` to ``path`` atomically (temp file in the same directory, fsync, rename);
    the previous checkpoint is replaced, so only the last one is kept.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with h5py.File(tmp, "w", libver="latest") as f:
            f.attrs["format"] = FORMAT_NAME
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["crashdem_version"] = ckpt.crashdem_version or _crashdem_version()
            f.attrs["scenario_hash"] = ckpt.scenario_hash
            f.attrs["t"] = float(ckpt.t)
            f.attrs["t.unit"] = "s"
            f.attrs["complete"] = bool(ckpt.complete)
            _put(f, "soil", ckpt.soil)
            _put(f, "cosim", ckpt.cosim)
            _put(f, "loop", dict(ckpt.loop))
            _put(f, "components", dict(ckpt.components))
            if isinstance(ckpt.sensors, PickledSensors):
                blob, used, typ = ckpt.sensors.blob, ckpt.sensors.refs, "PickledSensors"
            else:
                buf = io.BytesIO()
                pk = _RefPickler(buf, ckpt.refs)
                pk.dump(ckpt.sensors)
                blob, used = buf.getvalue(), sorted(pk.used)
                typ = f"{type(ckpt.sensors).__module__}.{type(ckpt.sensors).__qualname__}"
            d = f.create_dataset("sensors", data=np.frombuffer(blob, dtype=np.uint8))
            d.attrs["kind"] = "pickle"
            d.attrs["type"] = typ
            d.attrs["refs"] = json.dumps(list(used))
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def read_checkpoint(path: str | os.PathLike) -> Checkpoint:
    """Read a checkpoint written by :func:`write_checkpoint`.

    Raises
    ------
    FileNotFoundError
        If there is no checkpoint at ``path``.
    CheckpointError
        If the file is not a crashdem checkpoint of this format version.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(
            f"{path}: no checkpoint to resume from (set output.checkpoint_every_s and run "
            "without --resume)")
    with h5py.File(path, "r") as f:
        fmt = f.attrs.get("format", "")
        fmt = fmt.decode() if isinstance(fmt, bytes) else str(fmt)
        if fmt != FORMAT_NAME:
            raise CheckpointError(f"{path}: attrs['format']={fmt!r}: not a {FORMAT_NAME} file")
        ver = int(f.attrs["format_version"])
        if ver not in READABLE_VERSIONS:
            raise CheckpointError(f"{path}: format_version={ver}: this reader accepts "
                                  f"{READABLE_VERSIONS}")
        ds = f["sensors"]
        refs = json.loads(ds.attrs.get("refs", "[]"))
        sensors = PickledSensors(ds[()].tobytes(), refs) if refs else _get(ds)
        return Checkpoint(t=float(f.attrs["t"]), soil=_get(f["soil"]), cosim=_get(f["cosim"]),
                          sensors=sensors, loop=_get(f["loop"]),
                          scenario_hash=str(f.attrs["scenario_hash"]),
                          crashdem_version=str(f.attrs["crashdem_version"]),
                          complete=bool(f.attrs["complete"]),
                          components=_get(f["components"]) if "components" in f else {})


def read_body_poses(result_path: str | os.PathLike, t_cut: float) -> dict[str, dict]:
    """Body surfaces and snapshot poses stored in a (possibly killed) result, up to ``t_cut``.

    ``ResultWriter.resume`` carries particle snapshots over but not the body poses written
    next to them (``crashdem.export.write_body_pose``); the resumed run puts these back.

    Returns
    -------
    dict
        body group name -> ``vertices``, ``triangles``, ``position`` (k, 3) [m],
        ``rotation`` (k, 3, 3) for the ``k`` snapshots with ``t <= t_cut``.
    """
    out: dict[str, dict] = {}
    with h5py.File(result_path, "r", swmr=True) as f:
        if "snapshots" not in f or "bodies" not in f["snapshots"]:
            return out
        ts = f["snapshots"]["t"][:]
        k = int(np.count_nonzero(ts <= t_cut))
        for name, g in f["snapshots"]["bodies"].items():
            kk = min(k, g["position"].shape[0], g["rotation"].shape[0])
            out[name] = {"vertices": g["vertices"][:], "triangles": g["triangles"][:],
                         "position": g["position"][:kk], "rotation": g["rotation"][:kk]}
    return out

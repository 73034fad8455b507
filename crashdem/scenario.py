"""Scenarios: TOML files checked on load.

A scenario composes *model* (soil, impactor, container), *parameters*, *event* (impact conditions)
and *solver settings*; every piece of physics is switchable from the file (``[physics.*]``), so the
diagnosis can re-run a scenario with one effect added by setting one key.

API
---
``load(path, overrides=None) -> Scenario``; ``loads(text, overrides=None, source="<string>")``;
``Scenario.get("soil.material.young")``; ``Scenario.with_overrides({"physics.cohesion.enabled": True})``;
``Scenario.to_toml()``; ``SCHEMA`` (the field reference, also rendered by ``schema_markdown()``).

Every field error names the dotted field, the value and the allowed range or choices, and suggests
close matches for misspelled keys (``difflib``).

Notes
-----
Angles are given in degrees in files (fields end in ``_deg``) and converted to radians by the code
that consumes them; every other quantity is SI.
"""
from __future__ import annotations

import copy
import difflib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

__all__ = [
    "Field",
    "Scenario",
    "ScenarioError",
    "SCHEMA",
    "load",
    "loads",
    "parse_override",
    "schema_markdown",
]


class ScenarioError(ValueError):
    """A scenario file or override is invalid; the message names the field, value and allowed range."""


@dataclass(frozen=True)
class Field:
    """One scenario field: its type, default, unit, allowed range or choices, and meaning."""

    kind: str  # "float", "int", "bool", "str", "choice", "float_list"
    default: Any
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    doc: str = ""
    nullable: bool = False

    def describe_range(self) -> str:
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        if self.kind == "bool":
            return "true or false"
        if self.kind == "str":
            return "a string"
        if self.lo is None and self.hi is None:
            return f"a {self.kind}"
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        lb = "(" if (self.lo_open or self.lo is None) else "["
        rb = ")" if (self.hi_open or self.hi is None) else "]"
        return f"in {lb}{lo}, {hi}{rb}" + (f" [{self.unit}]" if self.unit else "")

    def check(self, path: str, value: Any) -> Any:
        def bad(why: str = "") -> ScenarioError:
            msg = f"{path}={value!r}: must be {self.describe_range()}"
            return ScenarioError(msg + (f" ({why})" if why else ""))

        if value is None:
            if self.nullable:
                return None
            raise bad("null is not allowed here")
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise bad()
            return value
        if self.kind == "str":
            if not isinstance(value, str):
                raise bad()
            return value
        if self.kind == "choice":
            if not isinstance(value, str) or value not in self.choices:
                close = difflib.get_close_matches(str(value), self.choices, n=2)
                raise bad(f"did you mean {' or '.join(map(repr, close))}?" if close else "")
            return value
        if self.kind == "float_list":
            if not isinstance(value, list) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
            ):
                raise bad("a list of numbers is expected")
            out = [float(v) for v in value]
            for v in out:
                self._check_number(path, v, bad)
            return out
        if self.kind == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                raise bad("an integer is expected")
            self._check_number(path, value, bad)
            return value
        if self.kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise bad("a number is expected")
            value = float(value)
            self._check_number(path, value, bad)
            return value
        raise AssertionError(self.kind)

    def _check_number(self, path: str, v: float, bad: Callable[[str], ScenarioError]) -> None:
        if isinstance(v, float) and not math.isfinite(v):
            raise bad("not finite")
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            raise bad()
        if self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)):
            raise bad()


def F(default: float | None, unit: str = "", lo=None, hi=None, *, lo_open=False, hi_open=False,
      doc: str = "", nullable: bool = False) -> Field:
    return Field("float", default, unit, lo, hi, lo_open, hi_open, doc=doc, nullable=nullable)


def I(default: int, lo=None, hi=None, doc: str = "") -> Field:  # noqa: E743
    return Field("int", default, "", lo, hi, doc=doc)


def B(default: bool, doc: str = "") -> Field:
    return Field("bool", default, doc=doc)


def C(default: str, *choices: str, doc: str = "") -> Field:
    return Field("choice", default, choices=tuple(choices), doc=doc)


def S(default: str, doc: str = "") -> Field:
    return Field("str", default, doc=doc)


MATERIAL = {
    "young": F(2.0e7, "Pa", 0, None, lo_open=True, doc="Young's modulus of the grains (contact stiffness kn = E r for equal spheres)"),
    "density": F(2650.0, "kg/m^3", 0, None, lo_open=True, doc="grain density"),
    "friction_angle_deg": F(30.0, "deg", 0, 90, hi_open=True, doc="inter-particle friction angle"),
    "stiffness_ratio": F(0.25, "1", 0, 1, doc="ks/kn (Yade's FrictMat.poisson)"),
}

#: The scenario schema: nested dict of sections; leaves are ``Field``.
SCHEMA: dict[str, Any] = {
    "scenario": {
        "name": S("crash", doc="run name, used for output file names"),
        "kind": C("drop_test", "drop_test", "glider_crash", doc="which reference experiment"),
        "description": S("", doc="free text"),
        "seed": I(1, 0, 2**31 - 1, doc="seed of every random draw (packing, noise)"),
        "threads": I(0, 0, 256, doc="Numba threads; 0 = all cores"),
    },
    "soil": {
        "radius": F(0.05, "m", 0.002, 0.5, doc="mean particle radius"),
        "radius_spread": F(0.2, "1", 0, 0.5, hi_open=True, doc="uniform radius spread: r in [r(1-s), r(1+s)]"),
        "rotation": C("blocked", "blocked", "free", doc="particle rotations blocked (thesis) or free with rolling resistance"),
        "rolling_coefficient": F(0.1, "1", 0, 1, doc="rolling-resistance coefficient mu_r (rotation = free)"),
        "porosity_target": F(None, "1", 0.26, 0.6, doc="target porosity of the bed (null = as deposited)", nullable=True),
        "deposition_friction_deg": F(None, "deg", 0, 90, hi_open=True, doc="friction during deposition (null = material value)", nullable=True),
        "material": dict(MATERIAL),
        "restitution": F(None, "1", 0, 1, lo_open=True, doc="viscous normal damping from a restitution coefficient (null = off, thesis)", nullable=True),
        "shear_restitution": F(None, "1", 0, 1, lo_open=True, doc="viscous shear damping: a dashpot beside the shear spring of this restitution (damping ratio of the shear spring as the normal one's), acting while a contact sticks, as Yade's MindlinPhys (es) and ViscElPhys (et) and EDEM's and LIGGGHTS' Hertz-Mindlin; null = off (thesis; soil.Material.shear_restitution)", nullable=True),
        "contact_law": C("linear", "linear", "hertz_mindlin", doc="contact law of the impact phase: linear Cundall-Strack springs kn = E r, ks = stiffness_ratio kn (thesis, Yade's FrictPhys), or Hertz-Mindlin (Fn = 4/3 E* sqrt(R*) delta^1.5, ks = 8 G* sqrt(R* delta), Yade's MindlinPhys) for the grains, the walls and the impactor; the bed is deposited with the linear law either way (soil.Material.contact_law)"),
        "poisson": F(0.25, "1", 0, 0.5, hi_open=True, doc="Poisson's ratio of the grains, walls and impactor with contact_law = hertz_mindlin (unused by the linear law)"),
        "impact_young_factor": F(1.0, "1", 0.01, 100.0, doc="factor on the grains' Young's modulus (both layers) and on a wall of the soil's modulus (container.wall_young null) in the impact phase; the bed is deposited at soil.material.young, so its packing (and packing cache entry) is the factor-1 bed's. A contact law calibrated on the same bed at another modulus (Hertz-Mindlin at about 4 x the linear law's on the campaign's gravel) without depositing it again"),
        "packing_file": S("", doc="bed imported instead of deposited (drop tests): .npz with x (N,3) and radius (N,) [m], or text rows 'x y z r' [m] (Yade export.text); floor at z = 0, tank on the z axis; empty = deposit (crashdem.beds)"),
    },
    "container": {
        "shape": C("cylinder", "cylinder", "box", doc="test tank (cylinder) or box container"),
        "diameter": F(3.0, "m", 0.3, 20.0, doc="cylinder tank diameter (reference tank: 10.7 m)"),
        "length": F(4.8, "m", 0.3, 20.0, doc="box length along x"),
        "width": F(4.8, "m", 0.3, 20.0, doc="box width along y"),
        "soil_depth": F(2.0, "m", 0.1, 10.0, doc="thickness of the soil layer above the rigid floor"),
        "wall_young": F(None, "Pa", 0, None, lo_open=True, doc="wall Young's modulus (null = soil value, i.e. Yade's default wall)", nullable=True),
        "slope_deg": F(0.0, "deg", 0, 60, doc="inclination of the free surface (glider container: 45)"),
        "compaction": C("horizontal", "horizontal", "slope_normal", doc="direction the layers were compacted in"),
        "height": F(2.0, "m", 0.3, 10.0, doc="box container wall height"),
        "wall_thickness": F(0.03, "m", 0.001, 0.5, doc="container wall panel thickness (glider container: 30 mm poplar plywood)"),
    },
    "glider": {
        "release_speed": F(18.33, "m/s", 0, 100, lo_open=True, doc="horizontal speed at release from the sled (thesis: 18.33 m/s)"),
        "impact_height": F(0.85, "m", 0, 10, doc="height above the container floor of the point where the nose meets the slope"),
        "free_flight_time": F(0.05, "s", 0, 2, doc="free flight between release and first contact"),
        "cg_from_nose": F(None, "m", 0, 10, lo_open=True, doc="override: CG distance behind the nose", nullable=True),
        "cg_height": F(None, "m", -2, 2, doc="override: CG height above the fuselage floor line", nullable=True),
        "pitch_inertia": F(None, "kg*m^2", 0, None, lo_open=True, doc="override: pitch moment of inertia about the CG", nullable=True),
        "mesh": S("", doc="fuselage surface mesh file (STL/OBJ/VTU...); empty = parametric mesh"),
        "mesh_scale": F(1.0, "1", 0, None, lo_open=True, doc="scale of the mesh file's units to m (1e-3 for mm)"),
        "nose_droop": F(0.0, "1", 0, 1, doc="side-view asymmetry of the parametric nose: tip nose_droop x height/2 below the axis (0 = symmetric elliptic nose, 1 = straight floor line to the tip); ignored with glider.mesh"),
        "skin_friction_deg": F(30.0, "deg", 0, 90, hi_open=True, doc="friction angle of the fuselage skin on the grains (the pair uses min(skin, soil)); composite on gravel mu 0.3-0.6, i.e. 17-31 deg"),
        "release_pitch_rate_deg_s": F(0.0, "deg/s", -360, 360, doc="pitch rate at release from the sled, nose-up positive (sled braking through supports below the CG gives a nose-down rate); impactor.pitch_deg is the attitude at release"),
    },
    "impactor": {
        "body": C("drop_sphere", "drop_sphere", "glider", doc="the rigid impactor"),
        "mass": F(None, "kg", 0, None, lo_open=True, doc="override the body mass", nullable=True),
        "impact_velocity": F(None, "m/s", 0, 100, lo_open=True, doc="speed at first contact (null = from drop_height)", nullable=True),
        "drop_height": F(18.45, "m", 0, 100, lo_open=True, doc="free-fall height; v = sqrt(2 g h)"),
        "angle_deg": F(0.0, "deg", -90, 90, doc="flight-path angle below horizontal (glider) or off-vertical (drop)"),
        "pitch_deg": F(0.0, "deg", -90, 90, doc="initial pitch attitude"),
        "gap": F(0.01, "m", 0, 1, doc="clearance between impactor and soil at t = 0"),
        "material_young": F(3.0e10, "Pa", 0, None, lo_open=True, doc="impactor Young's modulus (reinforced concrete)"),
    },
    "physics": {
        "soil_layering": {
            "enabled": B(False, doc="a density/stiffness discontinuity at some depth"),
            "depth": F(1.0, "m", 0, 10, lo_open=True, doc="depth of the discontinuity below the free surface"),
            "lower_young_factor": F(3.0, "1", 0.01, 100, doc="lower-layer E / upper-layer E"),
            "lower_porosity": F(None, "1", 0.26, 0.6, doc="lower-layer target porosity, reached by a friction search on a trial column (null = use lower_deposition_friction_deg)", nullable=True),
            "lower_deposition_friction_deg": F(6.0, "deg", 0, 90, hi_open=True, doc="friction while depositing the lower layer (compacted): 6 deg gives porosity ~0.41 and settles 4x faster than 0 deg (~0.36)"),
            "compacted": B(True, doc="true: the lower layer is deposited on its own, denser (lower_porosity / lower_deposition_friction_deg) and stiffer; false: stiffness only -- the bed is deposited whole as without the layering and the grains whose centre lies deeper than depth below its nominal top (the soil depth, where deposition cuts the centres) take lower_young_factor x E (drop tests; an imported bed is always stiffness only, its depth counted from its free surface)"),
        },
        "boundary_proximity": {
            "enabled": B(False, doc="rigid floor or wall nearer than modelled / different wall compliance"),
            "floor_depth": F(None, "m", 0.05, 10, doc="soil thickness above the rigid floor (overrides container.soil_depth)", nullable=True),
            "wall_young": F(None, "Pa", 0, None, lo_open=True, doc="container wall Young's modulus", nullable=True),
        },
        "cohesion": {
            "enabled": B(False, doc="adhesion between grains (moisture, compaction)"),
            "normal_strength": F(1.0e4, "Pa", 0, None, doc="normal cohesion (tensile strength x r^2 = adhesion force)"),
            "shear_strength": F(1.0e4, "Pa", 0, None, doc="shear cohesion"),
            "moments": B(True, doc="bending/twisting contact moments"),
        },
        "particle_rotation": {
            "enabled": B(False, doc="free particle rotation with rolling resistance instead of blocked rotation"),
            "rolling_coefficient": F(0.1, "1", 0, 1, doc="rolling-resistance coefficient"),
        },
        "contact_damping": {
            "enabled": B(False, doc="viscous normal contact damping"),
            "restitution": F(0.5, "1", 0, 1, lo_open=True, doc="coefficient of restitution"),
            "tension": B(False, doc="the dashpot may pull while a contact opens (Yade's CundallStrackVisco and codes like it: a binary rebound at exactly the restitution); false: the contact force never pulls (the rebound is above the restitution)"),
            "shear": B(False, doc="the contacts' shear is damped too, at the same restitution (a shear dashpot acting while a contact sticks: Yade's MindlinPhys with es = en, EDEM's and LIGGGHTS' Hertz-Mindlin); false: the normal dashpot only (Yade's CundallStrackVisco)"),
        },
        "sensor_dynamics": {
            "enabled": B(False, doc="accelerometer-mount resonance or a different filter class"),
            "natural_frequency": F(400.0, "Hz", 1, 20000, doc="mount resonance"),
            "damping_ratio": F(0.05, "1", 0, 2, doc="mount damping ratio"),
            "model": C("lowpass", "lowpass", "mount", doc="'lowpass': seismic transducer wn^2/(s^2+2 zeta wn s+wn^2); 'mount': base-excitation transmissibility of a resonant mount (2 zeta wn s+wn^2)/(s^2+2 zeta wn s+wn^2)"),
            "cfc": F(None, "Hz", 1, 10000, doc="filter class actually used (null = instrumentation.cfc)", nullable=True),
        },
        "structural_crush": {
            "enabled": B(False, doc="crushable nose: force-limited element between nose and body"),
            "crush_force": F(5.0e4, "N", 0, None, lo_open=True, doc="crush force plateau"),
            "stroke": F(0.2, "m", 0, 5, lo_open=True, doc="available crush stroke"),
        },
        "initial_conditions": {
            "enabled": B(False, doc="offset in impact speed, angle or attitude"),
            "velocity_offset": F(0.0, "m/s", -20, 20, doc="added to the impact speed"),
            "angle_offset_deg": F(0.0, "deg", -30, 30, doc="added to the path angle"),
            "pitch_offset_deg": F(0.0, "deg", -30, 30, doc="added to the pitch attitude"),
        },
    },
    "instrumentation": {
        "sample_rate": F(12500.0, "Hz", 100, 1e6, doc="acquisition rate (reference tests: 12.5 kHz)"),
        "cfc": F(60.0, "Hz", 1, 10000, doc="SAE J211 channel frequency class applied to stored filtered channels"),
        "accel_full_scale_g": F(200.0, "g", 1, 1e5, doc="accelerometer full scale (drop mass: 200 g; glider: 250 g)"),
        "accel_failure_factor": F(None, "1", 1, 100, doc="an accelerometer fails (NaN afterwards) beyond this multiple of its full scale (null = never)", nullable=True),
    },
    "solver": {
        "dt": F(None, "s", 0, 1e-2, lo_open=True, doc="DEM time step (null = safety x critical step)", nullable=True),
        "safety": F(0.3, "1", 0.01, 1, doc="fraction of the critical time step used when dt is null"),
        "t_end": F(0.15, "s", 0, 10, lo_open=True, doc="simulated time after first contact"),
        "exchange_every": I(1, 1, 1000, doc="DEM steps per Exudyn step (sub-cycling)"),
        "deposit_unbalanced": F(0.01, "1", 1e-5, 0.5, doc="deposition stops below this unbalanced-force ratio"),
    },
    "output": {
        "directory": S("runs", doc="output directory (relative to the working directory)"),
        "snapshots": I(0, 0, 1000, doc="number of particle snapshots stored over the impact"),
        "plots": B(True, doc="write PNG plots next to the HDF5 file"),
        "checkpoint_every_s": F(None, "s", 0, None, lo_open=True, doc="simulated-time interval between restart checkpoints (null = off)", nullable=True),
    },
}


def _walk(schema: dict[str, Any], prefix: str = ""):
    for k, v in schema.items():
        p = f"{prefix}{k}"
        if isinstance(v, Field):
            yield p, v
        else:
            yield from _walk(v, p + ".")


def _defaults(schema: dict[str, Any]) -> dict[str, Any]:
    return {k: (v.default if isinstance(v, Field) else _defaults(v)) for k, v in schema.items()}


def _validate(data: Any, schema: dict[str, Any], prefix: str, source: str) -> dict[str, Any]:
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: [{prefix.rstrip('.') or 'root'}] must be a table, got {data!r}")
    out: dict[str, Any] = {}
    for key, value in data.items():
        path = f"{prefix}{key}"
        if key not in schema:
            close = difflib.get_close_matches(key, list(schema), n=3, cutoff=0.6)
            hint = f"; did you mean {', '.join(repr(prefix + c) for c in close)}?" if close else (
                f"; allowed keys here: {', '.join(sorted(schema))}")
            raise ScenarioError(f"{source}: unknown field {path!r}{hint}")
        spec = schema[key]
        if isinstance(spec, Field):
            try:
                out[key] = spec.check(path, value)
            except ScenarioError as exc:
                raise ScenarioError(f"{source}: {exc}") from None
        else:
            out[key] = _validate(value, spec, path + ".", source)
    for key, spec in schema.items():
        if key not in out:
            out[key] = copy.deepcopy(spec.default) if isinstance(spec, Field) else _validate({}, spec, f"{prefix}{key}.", source)
    return out


def _lookup_field(path: str) -> Field:
    node: Any = SCHEMA
    parts = path.split(".")
    for i, part in enumerate(parts):
        if not isinstance(node, dict) or part not in node:
            options = list(node) if isinstance(node, dict) else []
            close = difflib.get_close_matches(part, options, n=3, cutoff=0.6)
            where = ".".join(parts[:i]) or "root"
            hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise ScenarioError(f"unknown field {path!r} (no {part!r} under {where}){hint}")
        node = node[part]
    if not isinstance(node, Field):
        raise ScenarioError(f"{path!r} is a section, not a field; fields: {', '.join(sorted(node))}")
    return node


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``key=value`` from the command line; the value is read as a TOML value, else a string."""
    if "=" not in text:
        raise ScenarioError(f"--set {text!r}: expected key=value, e.g. soil.material.young=3e7")
    key, raw = text.split("=", 1)
    key = key.strip()
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


@dataclass(frozen=True)
class Scenario:
    """A checked scenario: ``data`` holds every field (defaults filled in); ``text`` the source TOML."""

    data: dict[str, Any]
    text: str = ""
    source: str = "<string>"
    overrides: dict[str, Any] = field(default_factory=dict)

    def get(self, path: str) -> Any:
        node: Any = self.data
        for part in path.split("."):
            node = node[part]
        return node

    def __getitem__(self, path: str) -> Any:
        return self.get(path)

    def with_overrides(self, overrides: dict[str, Any]) -> "Scenario":
        data = copy.deepcopy(self.data)
        for path, value in overrides.items():
            spec = _lookup_field(path)
            checked = spec.check(path, value)
            node = data
            parts = path.split(".")
            for part in parts[:-1]:
                node = node[part]
            node[parts[-1]] = checked
        merged = {**self.overrides, **overrides}
        return Scenario(data, self.text, self.source, merged)

    def flat(self) -> dict[str, Any]:
        """All fields as ``{"a.b.c": value}``."""
        out: dict[str, Any] = {}
        for path, _ in _walk(SCHEMA):
            out[path] = self.get(path)
        return out

    def to_toml(self) -> str:
        import tomli_w

        def strip_none(d: dict[str, Any]) -> dict[str, Any]:
            return {k: (strip_none(v) if isinstance(v, dict) else v) for k, v in d.items() if v is not None}

        return tomli_w.dumps(strip_none(self.data))

    # Convenience derived quantities ------------------------------------------------------------
    @property
    def impact_velocity(self) -> float:
        """Speed at first contact [m/s] (from drop height when not given), including IC offsets."""
        v = self.get("impactor.impact_velocity")
        if v is None:
            v = math.sqrt(2.0 * 9.81 * self.get("impactor.drop_height"))
        if self.get("physics.initial_conditions.enabled"):
            v += self.get("physics.initial_conditions.velocity_offset")
        if v <= 0:
            raise ScenarioError(f"impact velocity {v:g} m/s after offsets: must be > 0")
        return v


def loads(text: str, overrides: dict[str, Any] | None = None, source: str = "<string>") -> Scenario:
    """Parse and check a scenario from TOML text."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    data = _validate(raw, SCHEMA, "", source)
    sc = Scenario(data, text, source)
    if overrides:
        try:
            sc = sc.with_overrides(overrides)
        except ScenarioError as exc:
            raise ScenarioError(f"{source} (override): {exc}") from None
    return sc


def load(path: str | Path, overrides: dict[str, Any] | None = None) -> Scenario:
    """Read and check a scenario file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError(f"scenario file {str(path)!r} not found") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"scenario file {str(path)!r}: not UTF-8 text ({exc.reason})") from None
    return loads(text, overrides, source=str(path))


def schema_markdown() -> str:
    """The scenario reference as a Markdown table (used for README/docs)."""
    lines = ["| field | default | allowed | meaning |", "|---|---|---|---|"]
    for path, f in _walk(SCHEMA):
        default = "null" if f.default is None else repr(f.default).lower() if isinstance(f.default, bool) else repr(f.default)
        lines.append(f"| `{path}` | {default} | {f.describe_range()} | {f.doc} |")
    return "\n".join(lines)

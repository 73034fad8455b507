"""The catalogue of candidate missing physics (names fixed by issue 7) and the recalibration
pseudo-hypothesis.

Each :class:`Hypothesis` states the physics, its parameters (SI units, bounds, prior nominal value,
log/linear search scale), the ROM fields they set (``crashdem.diagnosis.rom.RomParams``) and how
the effect is switched on in a scenario (``physics.<name>.*`` keys of ``crashdem.scenario``).

Every hypothesis is fitted *together with* the recalibration parameters, so a missing-physics
hypothesis only wins when its extra terms explain what a refit of the existing parameters
cannot (nested models; see ``fit.py``).

Notes
-----
Physics sources per entry are in each ``physics`` text; the ROM terms are documented in
``rom.py``. The rolling-resistance mapping ``friction_ratio(mu_r)`` is a ROM assumption (an
exponential saturation towards the blocked-rotation strength, after the trend reported by
Estrada, Taboada & Radjai 2008, PRE 78:021301) to be calibrated against DEM runs.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping

__all__ = ["ParameterSpec", "Hypothesis", "Variant", "FullSearch", "DROP_FULL_SEARCH",
           "STIFFER_SOIL_FACTORS", "DAMPING_FORMS", "WHOLE_BED_DEPTH", "stiffer_soil_overrides",
           "layer_level_factor", "BedFloor", "impact_young_range",
           "stiffer_soil_depths",
           "CATALOGUE", "RECALIBRATION", "NAMES", "get", "combine",
           "Catalogue", "DROP", "drop_catalogue", "planar_catalogue",
           "friction_ratio_from_rolling", "rolling_from_friction_ratio"]

#: friction ratio with free rotation and no rolling resistance (mu_r = 0) [-] (ROM assumption)
FREE_ROTATION_RATIO = 0.45
#: rolling-resistance scale of the saturation [-] (ROM assumption)
ROLLING_SCALE = 0.08


def friction_ratio_from_rolling(mu_r: float) -> float:
    """Residual friction ratio r (free / blocked rotation) for a rolling coefficient mu_r [-]."""
    return FREE_ROTATION_RATIO + (1.0 - FREE_ROTATION_RATIO) * -math.expm1(-mu_r / ROLLING_SCALE)


def rolling_from_friction_ratio(r: float) -> float:
    """Inverse of ``friction_ratio_from_rolling`` (clipped to [0, 1])."""
    if r <= FREE_ROTATION_RATIO:
        return 0.0
    if r >= 1.0:
        return 1.0
    return float(min(1.0, -ROLLING_SCALE * math.log((1.0 - r) / (1.0 - FREE_ROTATION_RATIO))))


@dataclass(frozen=True)
class ParameterSpec:
    """One fitted parameter: ``name`` is the ROM field (or recalibration scale key)."""

    name: str
    unit: str
    lo: float
    hi: float
    nominal: float  # prior / starting value
    scale: str = "lin"  # "lin" or "log" search scale
    description: str = ""
    scenario_key: str | None = None
    off: float | None = None  # value at which the effect vanishes (nests the recalibration)
    grid: int | None = None  # coarse-grid levels for the multi-start (None = from the budget)

    def __post_init__(self) -> None:
        if not self.lo < self.hi:
            raise ValueError(f"ParameterSpec.{self.name}: lo={self.lo!r} must be < hi={self.hi!r} [{self.unit}]")
        if not self.lo <= self.nominal <= self.hi:
            raise ValueError(f"ParameterSpec.{self.name}.nominal={self.nominal!r}: must be in "
                             f"[{self.lo:g}, {self.hi:g}] [{self.unit}]")
        if self.off is not None and not self.lo <= self.off <= self.hi:
            raise ValueError(f"ParameterSpec.{self.name}.off={self.off!r}: must be in "
                             f"[{self.lo:g}, {self.hi:g}] [{self.unit}]")
        if self.scale not in ("lin", "log"):
            raise ValueError(f"ParameterSpec.{self.name}.scale={self.scale!r}: must be 'lin' or 'log'")
        if self.scale == "log" and self.lo <= 0:
            raise ValueError(f"ParameterSpec.{self.name}.lo={self.lo!r}: must be > 0 for a log scale [{self.unit}]")

    def to_unit(self, value: float) -> float:
        """Map a physical value into the search coordinate u in [0, 1]."""
        if self.scale == "log":
            return (math.log(value) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (value - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        """Physical value of the search coordinate u (clipped to [0, 1])."""
        u = min(1.0, max(0.0, float(u)))
        if self.scale == "log":
            return math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo)))
        return self.lo + u * (self.hi - self.lo)


@dataclass(frozen=True)
class Variant:
    """A discrete model form of a hypothesis: fixed screening-model values and the scenario
    keys that select the same form in the full simulation."""

    label: str
    rom_values: dict[str, float]
    scenario: dict[str, Any]
    description: str = ""


@dataclass(frozen=True)
class Hypothesis:
    """A candidate explanation: physics text, parameters and scenario switch."""

    name: str
    physics: str
    parameters: tuple[ParameterSpec, ...]
    scenario_switch: str | None
    signature: tuple[str, ...] = ()
    to_scenario: Callable[[dict[str, float]], dict[str, Any]] | None = field(default=None, compare=False)
    #: discrete model forms of the same physics, each fitted and the best kept (BIC, plus
    #: ln(number of forms) for the choice): ``Variant(label, rom_values, scenario_overrides)``
    variants: tuple["Variant", ...] = ()

    @property
    def n_params(self) -> int:
        """Number of the hypothesis's own parameters."""
        return len(self.parameters)

    def variant(self, label: str | None) -> "Variant | None":
        """The variant called ``label`` (None when the hypothesis has no variants)."""
        if label is None or not self.variants:
            return None
        for v in self.variants:
            if v.label == label:
                return v
        raise ValueError(f"{self.name}: variant {label!r} unknown; known: "
                         f"{[v.label for v in self.variants]}")

    def scenario_overrides(self, values: dict[str, float],
                           variant: str | None = None) -> dict[str, Any]:
        """Scenario keys that switch this effect on with the fitted ``values`` (and the scenario
        keys of the fitted ``variant``)."""
        out: dict[str, Any] = {}
        if self.scenario_switch:
            out[self.scenario_switch] = True
        if self.to_scenario is not None:
            out.update(self.to_scenario(values))
        else:
            for p in self.parameters:
                if p.scenario_key and p.name in values:
                    out[p.scenario_key] = float(values[p.name])
        var = self.variant(variant)
        if var is not None:
            out.update(var.scenario)
        return out

    def describe(self) -> dict[str, Any]:
        """JSON-ready description (physics, parameters with units/ranges, scenario keys)."""
        return {
            "name": self.name,
            "physics": self.physics,
            "scenario_switch": self.scenario_switch,
            "signature": list(self.signature),
            "variants": [{"label": v.label, "description": v.description,
                          "scenario": v.scenario} for v in self.variants],
            "parameters": [
                {"name": p.name, "unit": p.unit, "range": [p.lo, p.hi], "nominal": p.nominal,
                 "scale": p.scale, "scenario_key": p.scenario_key, "description": p.description}
                for p in self.parameters
            ],
        }


def _cohesion_to_scenario(v: dict[str, float]) -> dict[str, Any]:
    return {"physics.cohesion.normal_strength": float(v["cohesion"]),
            "physics.cohesion.shear_strength": float(v["cohesion"])}


def _combined_to_scenario(hs: tuple[Hypothesis, ...], v: dict[str, float]) -> dict[str, Any]:
    """The scenario overrides of the hypotheses ``hs`` switched on together."""
    out: dict[str, Any] = {}
    for h in hs:
        out.update(h.scenario_overrides(v))
    return out


def _wall_to_scenario(geo: dict[str, float], k0: float, v: dict[str, float]) -> dict[str, Any]:
    """Planar rear wall -> scenario: the container length from the wall distance, the panel
    modulus from the wall stiffness (``geo``: ``planar_catalogue``'s geometry, ``k0`` the
    baseline's wall stiffness)."""
    out: dict[str, Any] = {}
    if "impact_height" in geo and "slope" in geo and "wall_distance" in v:
        out["container.length"] = float(v["wall_distance"]) + \
            geo["impact_height"] / math.tan(geo["slope"])
    if "wall_young" in geo and "wall_stiffness" in v:
        out["container.wall_young"] = geo["wall_young"] * float(v["wall_stiffness"]) / k0
    return out


def _planar_ic_to_scenario(v: dict[str, float]) -> dict[str, Any]:
    """Planar initial conditions -> scenario (speed, flight-path angle and pitch offsets)."""
    return {"physics.initial_conditions.velocity_offset": float(v.get("speed_offset", 0.0)),
            "physics.initial_conditions.angle_offset_deg":
                math.degrees(float(v.get("angle_offset", 0.0))),
            "physics.initial_conditions.pitch_offset_deg":
                math.degrees(float(v.get("pitch_offset", 0.0)))}


def _rotation_to_scenario(v: dict[str, float]) -> dict[str, Any]:
    mu = rolling_from_friction_ratio(v["friction_ratio"])
    return {"soil.rotation": "free", "soil.rolling_coefficient": mu,
            "physics.particle_rotation.rolling_coefficient": mu}


def _recal_to_scenario(v: dict[str, float]) -> dict[str, Any]:
    # scale factors; the caller multiplies the scenario's own values (see docs/diagnosis.md)
    return {f"calibration.{k}": float(x) for k, x in v.items()}


RECALIBRATION = Hypothesis(
    name="recalibration",
    physics=("No new physics: the existing soil parameters are wrong. Refits the strength "
             "(friction) scale, the inertial-drag scale and the stiffness scale of the baseline "
             "model (Poncelet / Katsuragi-Durian resistance, anchors.md section 6)."),
    parameters=(
        ParameterSpec("strength_scale", "1", 0.3, 3.0, 1.0, "log",
                      "multiplies the frictional resistance q0 + k_p z (DEM: tan of the friction angle)",
                      "soil.material.friction_angle_deg"),
        ParameterSpec("drag_scale", "1", 0.3, 3.0, 1.0, "log",
                      "multiplies the inertial drag coefficient (DEM: bulk density)",
                      "soil.material.density"),
        ParameterSpec("stiffness_scale", "1", 0.3, 3.0, 1.0, "log",
                      "multiplies the soil modulus (DEM: Young's modulus of the grains)",
                      "soil.material.young"),
    ),
    scenario_switch=None,
    signature=("peak_too_high", "peak_too_low", "duration_too_long", "duration_too_short"),
    to_scenario=_recal_to_scenario,
)

CATALOGUE: tuple[Hypothesis, ...] = (
    Hypothesis(
        "soil_layering",
        ("A density/stiffness discontinuity at depth z_d (e.g. a compacted deep layer under a "
         "remoulded top layer, thesis section 2.1.2): resistance and stiffness jump by a ratio "
         "when the impactor reaches it, giving a second deceleration peak."),
        (ParameterSpec("interface_depth", "m", 0.03, 1.5, 0.3, "lin",
                       "depth of the discontinuity below the free surface", "physics.soil_layering.depth",
                       grid=16),
         ParameterSpec("strength_ratio", "1", 0.3, 5.0, 2.0, "log",
                       "lower/upper resistance and stiffness ratio",
                       "physics.soil_layering.lower_young_factor", off=1.0, grid=4)),
        "physics.soil_layering.enabled",
        ("missing_peak", "peak_too_low", "extra_peak"),
    ),
    Hypothesis(
        "boundary_proximity",
        ("A rigid floor (or wall) nearer than modelled, or of a different compliance: the stress "
         "bulb reaches it and stiffens the response (elastic layer on a rigid base, ~a/h), and "
         "the compression wave reflected by it returns at 2H/c as an extra lift (thesis "
         "section 2.1.2; Chrono issue #824 on truncated soil domains, anchors.md section 5)."),
        (ParameterSpec("floor_depth", "m", 0.4, 3.0, 1.2, "lin",
                       "soil thickness above the rigid floor", "physics.boundary_proximity.floor_depth",
                       off=2.0, grid=16),
         ParameterSpec("wave_reflection", "1", 0.0, 1.0, 0.5, "lin",
                       "reflection coefficient of the floor/wall (1 = rigid, lower = compliant)",
                       None, off=0.5, grid=1)),
        "physics.boundary_proximity.enabled",
        ("extra_peak", "missing_peak", "peak_early", "peak_too_low"),
    ),
    Hypothesis(
        "cohesion",
        ("Adhesion between grains (moisture, fines): a bulk cohesion c adds N_c c to the bearing "
         "pressure (N_c = 9, deep circular footing, Skempton 1951) and resists separation "
         "(tension down to -c A) on rebound."),
        (ParameterSpec("cohesion", "Pa", 1.0e3, 3.0e5, 2.0e4, "log",
                       "bulk cohesion (ROM); DEM contact normal/shear strength to be calibrated",
                       "physics.cohesion.normal_strength", off=1.0e3),),
        "physics.cohesion.enabled",
        ("peak_too_low", "rebound_too_strong", "force_too_low"),
        to_scenario=_cohesion_to_scenario,
    ),
    Hypothesis(
        "particle_rotation",
        ("Free particle rotation with rolling resistance instead of blocked rotation: the grains "
         "roll past the impactor, the mobilised friction softens from the interlocked value to a "
         "residual fraction r over a mobilisation depth delta (lower, longer pulse)."),
        (ParameterSpec("friction_ratio", "1", 0.2, 1.0, 0.6, "lin",
                       "residual / blocked-rotation friction (maps to the rolling coefficient)",
                       "physics.particle_rotation.rolling_coefficient", off=1.0),
         ParameterSpec("mobilisation_depth", "m", 0.01, 0.5, 0.08, "log",
                       "penetration over which the friction softens", None)),
        "physics.particle_rotation.enabled",
        ("peak_too_high", "duration_too_short", "peak_early"),
        to_scenario=_rotation_to_scenario,
    ),
    Hypothesis(
        "contact_damping",
        ("Energy dissipated in the contacts (viscous normal damping from a restitution "
         "coefficient): a dashpot in parallel with the soil spring lowers the stored elastic "
         "energy and the rebound."),
        (ParameterSpec("restitution", "1", 0.05, 1.0, 0.5, "lin",
                       "coefficient of restitution", "physics.contact_damping.restitution",
                       off=1.0),),
        "physics.contact_damping.enabled",
        ("rebound_too_strong",),
    ),
    Hypothesis(
        "sensor_dynamics",
        ("The measured acceleration is seen through the accelerometer mount: a base-excitation "
         "resonance fn with damping ratio zeta (Thomson & Dahl, section 3.5), ringing and "
         "overshoot in the recorded channel; or the channel was filtered with another CFC "
         "class than the simulation (measured from the pre-event noise spectrum, "
         "``filter_check``; fixed by ``instrumentation.cfc``)."),
        (ParameterSpec("mount_frequency", "Hz", 20.0, 1000.0, 120.0, "log",
                       "mount natural frequency", "physics.sensor_dynamics.natural_frequency",
                       off=1000.0),
         ParameterSpec("mount_damping", "1", 0.02, 1.0, 0.15, "log",
                       "mount damping ratio", "physics.sensor_dynamics.damping_ratio")),
        "physics.sensor_dynamics.enabled",
        ("oscillation", "peak_too_low", "extra_peak", "missing_peak"),
        variants=(
            Variant("mount", {"mount_form": 1.0},
                    {"physics.sensor_dynamics.model": "mount"},
                    "resonant mount: base-excitation transmissibility "
                    "(2 zeta wn s + wn^2)/(s^2 + 2 zeta wn s + wn^2)"),
            Variant("lowpass", {"mount_form": 0.0},
                    {"physics.sensor_dynamics.model": "lowpass"},
                    "seismic transducer: wn^2/(s^2 + 2 zeta wn s + wn^2)"),
        ),
    ),
    Hypothesis(
        "structural_crush",
        ("The impactor is not rigid: a crushable nose (force-limited series element of crush "
         "strength F_c over a stroke s_max between the soil and the body) clips the "
         "deceleration to a plateau F_c/m until the stroke is used up."),
        (ParameterSpec("crush_strength", "N", 2.0e4, 2.0e6, 2.0e5, "log",
                       "crush force plateau", "physics.structural_crush.crush_force", off=2.0e6,
                       grid=8),
         ParameterSpec("crush_stroke", "m", 0.01, 0.6, 0.1, "lin",
                       "available crush stroke", "physics.structural_crush.stroke", grid=10)),
        "physics.structural_crush.enabled",
        ("peak_too_high", "peak_early", "duration_too_short"),
    ),
    Hypothesis(
        "initial_conditions",
        ("The impact differed from the modelled one: an offset of the impact speed (drop-height "
         "error, air drag, release), of the path angle or of the attitude."),
        (ParameterSpec("speed_offset", "m/s", -5.0, 5.0, 0.0, "lin",
                       "added to the impact speed", "physics.initial_conditions.velocity_offset",
                       off=0.0),),
        "physics.initial_conditions.enabled",
        ("initial_offset", "peak_too_high", "peak_too_low"),
    ),
)

@dataclass(frozen=True)
class FullSearch:
    """Levels of one effect's main parameter in the *full* model's own terms (scenario keys),
    run by ``screen_then_confirm`` so that an effect is judged at the value the full model needs,
    not at the screening model's value mapped across (the reduced-order model's bulk cohesion
    is not the DEM's contact strength, its bulk dashpot not the contact restitution).

    ``keys`` are set to each value of ``values`` (ascending), ``fixed`` switches the effect on
    (and fixes its other parameters); ``parameter`` names the value in the report -- when it is
    also a catalogue parameter of the hypothesis with the same meaning, the full model's value
    replaces the screening's in the final answer; ``scale`` is the coordinate in which the
    refinement parabola is laid through the best level and its neighbours. ``fades`` says at
    which end of the span the effect fades towards the baseline ("high": a deeper floor or
    interface, a restitution or rolling resistance nearer the blocked/elastic baseline; "low":
    a weaker cohesion): a best run at that end is not a located effect but "a little of it",
    the shape a code-to-code or packing difference also takes, so it names nothing
    (``located``). ``deposits`` says that every level deposits a bed of its own (a floor or
    an interface depth changes the deposition): a level then differs from the baseline by its
    packing as well as by the effect, and ``screen_then_confirm`` runs it on several beds
    (``level_beds``) paired with the replicate packings. ``extension`` lists further values
    beyond the strong end (the end opposite ``fades``), outward in order: the confirmation
    runs the next of them only while the strong end of the span run so far fits the
    recording best among the effect's levels (``extended``), so that an effect stronger than
    the span is followed to its optimum at the cost of a level, not named at the wrong
    value or not at all."""

    parameter: str
    unit: str
    keys: tuple[str, ...]
    values: tuple[float, ...]
    fixed: dict[str, Any] = field(default_factory=dict)
    scale: str = "lin"
    fades: str = "high"
    deposits: bool = False
    extension: tuple[float, ...] = ()
    #: alternative forms of the effect, each a name and the overrides it adds to ``fixed``:
    #: every level then runs in every form, and the form whose best level fits the recording
    #: best is kept for everything after (``with_form``); () = one form, ``fixed``
    forms: tuple[tuple[str, dict[str, Any]], ...] = ()
    #: the form this search stands for (set by ``with_form``), None: ``fixed`` alone
    form: str | None = None
    #: the depth [m] of the top grain row of the bed the levels run on: one mean grain
    #: diameter of the simulator that runs them (set by the command line, which knows it:
    #: the scenario's own grains, or the coarse search tier's); the realisation floor's bed
    #: stiffer below its top grain row (``stiffer_soil_depths``). None: the shallowest level
    top_row_depth: float | None = None
    #: the Young's modulus factor of the realisation floor's whole bed with the Hertz-Mindlin
    #: contact law (``hertz_floor_overrides``; set by the command line for a scenario of the
    #: linear law: ``HERTZ_FLOOR_YOUNG_FACTOR``); None: no such run
    hertz_floor: float | None = None

    def __post_init__(self) -> None:
        names = [f[0] for f in self.forms]
        if self.forms and (len(self.forms) < 2 or len(set(names)) != len(names)
                           or any(not isinstance(n, str) or not n for n in names)):
            raise ValueError(f"FullSearch.{self.parameter}.forms: must be at least two forms "
                             f"with distinct non-empty names, got {names!r}")
        if len(self.values) < 2 or any(b <= a for a, b in zip(self.values, self.values[1:])):
            raise ValueError(f"FullSearch.{self.parameter}.values={self.values!r}: must be at "
                             f"least two ascending values [{self.unit}]")
        if self.hertz_floor is not None and not (math.isfinite(self.hertz_floor)
                                                 and self.hertz_floor > 0.0):
            raise ValueError(f"FullSearch.{self.parameter}.hertz_floor={self.hertz_floor!r}: "
                             "must be a finite factor > 0 [-] or None")
        if self.top_row_depth is not None and not (math.isfinite(self.top_row_depth)
                                                   and self.top_row_depth > 0.0):
            raise ValueError(f"FullSearch.{self.parameter}.top_row_depth="
                             f"{self.top_row_depth!r}: must be a finite depth > 0 [m] or None")
        if self.scale not in ("lin", "log") or (self.scale == "log" and self.values[0] <= 0):
            raise ValueError(f"FullSearch.{self.parameter}.scale={self.scale!r}: must be 'lin', "
                             f"or 'log' with positive values")
        if self.fades not in ("high", "low"):
            raise ValueError(f"FullSearch.{self.parameter}.fades={self.fades!r}: must be 'high' "
                             f"or 'low'")
        out = -1.0 if self.fades == "high" else 1.0  # outward beyond the strong end
        prev = self.strong_end
        for v in self.extension:
            if (v - prev) * out <= 0 or (self.scale == "log" and v <= 0):
                raise ValueError(f"FullSearch.{self.parameter}.extension={self.extension!r}: "
                                 f"each value must lie beyond the previous one, outward from "
                                 f"the strong end {self.strong_end:g} [{self.unit}]"
                                 + (" and be positive" if self.scale == "log" else ""))
            prev = v

    @property
    def strong_end(self) -> float:
        """The level at the end of the span opposite ``fades`` (where the effect is strongest)."""
        return self.values[0] if self.fades == "high" else self.values[-1]

    def extended(self) -> FullSearch:
        """This search with the next ``extension`` value added to its levels (it becomes the
        strong end) and removed from ``extension``; ValueError when none is left."""
        if not self.extension:
            raise ValueError(f"FullSearch.{self.parameter}.extension: no value left")
        return replace(self, values=tuple(sorted((*self.values, self.extension[0]))),
                       extension=self.extension[1:])

    @property
    def tolerance(self) -> float:
        """How near two values of this search count as the same level."""
        return 1e-9 * max(abs(v) for v in self.values)

    @property
    def edge(self) -> float:
        """The edge of the located span: the last level short of the fading end."""
        return self.values[-2] if self.fades == "high" else self.values[1]

    def located(self, value: float) -> bool:
        """True when ``value`` lies within the levels short of the fading end, i.e. not at the
        last level towards ``fades`` nor in the interval before it (a refinement vertex there
        is pulled by the fading level)."""
        if self.fades == "high":
            return value <= self.edge + self.tolerance
        return value >= self.edge - self.tolerance

    def inside(self, value: float) -> bool:
        """True when ``value`` lies strictly short of the ``edge`` of the located span."""
        if self.fades == "high":
            return value < self.edge - self.tolerance
        return value > self.edge + self.tolerance

    def overrides(self, value: float) -> dict[str, Any]:
        """Scenario overrides of the level ``value``."""
        return {**self.fixed, **{k: float(value) for k in self.keys}}

    @property
    def n_levels(self) -> int:
        """Runs of one pass over the levels (every level in every form)."""
        return len(self.values) * max(1, len(self.forms))

    def with_form(self, name: str) -> FullSearch:
        """This search in its form ``name`` alone: the form's overrides added to ``fixed``,
        ``forms`` emptied and ``form`` set; ValueError naming the forms when there is no such
        form."""
        forms = dict(self.forms)
        if name not in forms:
            raise ValueError(f"FullSearch.{self.parameter}.forms: no form {name!r}; allowed: "
                             f"{list(forms)}")
        return replace(self, fixed={**self.fixed, **forms[name]}, forms=(), form=name)

    def form_of(self, overrides: Mapping[str, Any]) -> str | None:
        """The form whose overrides -- ``fixed`` with the form's own on top -- ``overrides``
        all hold (the first such form), else ``form`` (the kept form, or None for a search of
        one form). A form that only adds keys to another's is told from it by the values its
        keys take in ``fixed``."""
        for n, f in self.forms:
            if all(k in overrides and overrides[k] == v for k, v in {**self.fixed, **f}.items()):
                return n
        return self.form

    def variants(self) -> list[FullSearch]:
        """One search per form (``with_form``), or this search when it has one form."""
        return [self.with_form(n) for n, _ in self.forms] if self.forms else [self]

    def coord(self, value: float) -> float:
        """The refinement coordinate of ``value`` (log or linear)."""
        return math.log(value) if self.scale == "log" else float(value)

    def value(self, coord: float) -> float:
        """Inverse of ``coord``."""
        return math.exp(coord) if self.scale == "log" else float(coord)


#: full-model search levels of the drop catalogue's soil effects (PoliMi 0.9 m sphere, beds of
#: 1-2 m; effect draws of generator_dem / the Yade truth lie inside these spans). Cohesion
#: and restitution are searched in the DEM's own (contact) terms, the values their scenario
#: keys take (the catalogue maps the screening's bulk values onto the same keys); the layering at a
#: lower layer 5 x stiffer (the ratio is not resolved by one impact on a 0.1 m grain bed, its
#: depth is), 0.05 m apart where a bed's response changes fastest with the depth (measured
#: on a DEM-truth layering at 0.288 m: Delta BIC 94 / 106 / 45 at 0.15 / 0.2 / 0.3 m).
#: Each floor level deposits its own bed, as a floor in a test does (measured: a
#: floor trimmed into the baseline's bed, grains below it removed, keeps the packing above it
#: but leaves the grains next to the floor unloaded; with it 2 of the 4 DEM/Yade floor
#: recordings and 2 others were named wrongly, against 0 and 1 with deposited beds).
#: The floor's extension levels run only while its shallowest level fits best
#: (``FullSearch.extension``): a Yade bed 0.6 m deep (13.7 m, command line) was named
#: ``soil_layering`` until the floor went on to 0.4 m. Cohesion levels of 9.6e5 and 1.92e6 Pa
#: were tried the same way and dropped: a Yade cohesion of 1e6 Pa (library path) went from a
#: wrong floor to nothing named, but on the 13.7 m set of 48 effect recordings (seeds 11-16)
#: two floors and a contact damping lost their right names (30 -> 27 named)
#: the two forms of a layer the drop search runs (``FullSearch.forms``): the lower part
#: deposited on its own, denser and stiffer (crashdem's compacted layer, as in the reference
#: campaign's tank), or the same packing with stiffer grains below the interface (how another
#: DEM code often makes a layer: a material assigned by depth). Measured on the 13.7 m
#: recordings: the stiffness form names Yade's layering 11 at 0.25 m (+5 % of the realised
#: depth; none named with the compacted form alone) but fits crashdem's compacted DEM truths
#: at 0.18 m (-32 / -35 %, against -7 / -30 % in the compacted form)
LAYER_FORMS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("stiffness", {"physics.soil_layering.compacted": False}),
    ("compacted", {"physics.soil_layering.compacted": True}),
)

#: the two forms of contact damping the drop search runs (``FullSearch.forms``): the normal
#: dashpot whose contact force never pulls (crashdem's default: a contact opens early, the
#: rebound is above the restitution) and the dashpot that may pull while the contact opens
#: (Yade's ``CundallStrackVisco``, and many codes: the rebound is the restitution). Measured
#: on the Yade damping recordings (session 45): the two forms' best runs fit within 1.6 Delta
#: BIC of each other, inside the replicates' scatter, so the drop test does not resolve the form;
#: the 13.7 m damping recordings named cohesion stay so with the pull (it is the model's grain
#: size: at the truths' 0.10 m grains they are named damping). A third form, the contacts' shear
#: damped too (``physics.contact_damping.shear``, as Yade's Hertz-Mindlin whose ``es`` is ``en``
#: unless given), was measured and left out (session 54): it fits Yade's Hertz-Mindlin damping
#: recordings better than these two by 9-18 Delta BIC but names none of them, and on crashdem's
#: own DEM truth it ties floor 11 (within 9.6), which is then no longer named
DAMPING_FORMS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("no_tension", {"physics.contact_damping.tension": False}),
    ("tension", {"physics.contact_damping.tension": True}),
)

#: factors of the whole bed's grain modulus that the full tier runs as a no-new-physics
#: alternative (``stiffer_soil_overrides``): a wrong soil stiffness is a recalibration, and the
#: screening model's recalibration does not map onto the DEM's modulus, so without these a layer
#: at the search's shallowest level stood for a stiffer soil. Measured on the Yade library
#: path: the 5 m null 27 was named a 0.15 m stiffness layer (Delta BIC 10.4 against the
#: replicates' 10.2), the whole bed x5 fits it at 11.2 (docs/diagnosis.md, session 28)
STIFFER_SOIL_FACTORS: tuple[float, ...] = (2.0, 5.0)
#: depth [m] of the stiffness-only layer that makes the whole bed stiffer: every grain centre
#: lies below the bed's nominal top, where the deposition cuts them
WHOLE_BED_DEPTH = 1e-3
#: Young's modulus factor of the realisation floor's run of the bed with the other contact law,
#: Hertz-Mindlin (``FullSearch.hertz_floor``, set by the command line for a linear scenario):
#: another code's law, calibrated on the same test. Measured on a Yade bed (null 21, 13.7 m):
#: Yade's Hertz-Mindlin grains penetrate as deep as its linear ones at 4 x the modulus (0.601
#: against 0.609 m), and crashdem's Hertz-Mindlin law on that bed follows Yade's within 3.2 %
#: (docs/diagnosis.md, "A Hertz-Mindlin law of our own")
HERTZ_FLOOR_YOUNG_FACTOR = 4.0
#: the form name of that run in the floor's rows and words
HERTZ_FLOOR_FORM = "Hertz-Mindlin"


def stiffer_soil_depths(fs: FullSearch | None) -> tuple[float, ...]:
    """Depths [m] below which the realisation floor's stiffer-soil alternatives make the bed
    stiffer: the whole bed (``WHOLE_BED_DEPTH``) and the bed below its top grain row, one mean
    grain diameter of the bed the levels run on (``FullSearch.top_row_depth``: 0.15 m for the
    campaign's 0.075 m grains, 0.2 m on the coarse search tier's 0.10 m), else the layering
    search's shallowest level (0.15 m). Empty when ``fs`` is None.

    The top row is the impactor's contact partner, and how stiff it is against the confined
    grains below is not one of the catalogue's physics: a contact law whose stiffness grows with
    the contact force (Hertz-Mindlin, the default of most DEM codes) makes the lightly loaded
    surface grains softer than the bed below, and another code's deposition cuts and settles its
    surface otherwise. A layer whose interface lies within that row is not told apart from it at
    this resolution. Measured on Yade recordings of the unchanged physics, through the command
    line: nulls made with the Hertz-Mindlin law at twice the calibrated modulus were named a
    stiffness-form layer at 0.15 m in 5 of 10 at 13.7 m, and the bed of Yade seed 24 in
    both laws and at both heights measured (docs/diagnosis.md, "Another contact law")."""
    if fs is None:
        return ()
    return (WHOLE_BED_DEPTH, float(min(fs.values) if fs.top_row_depth is None
                                   else fs.top_row_depth))


def stiffer_soil_overrides(fs: FullSearch | None, factor: float,
                           below: float = WHOLE_BED_DEPTH) -> dict[str, Any] | None:
    """Scenario overrides of the bed's grains deeper than ``below`` [m] (default: the whole
    bed, ``WHOLE_BED_DEPTH``) ``factor`` x stiffer, on the same bed: the stiffness form of the
    layering search ``fs`` (``LAYER_FORMS``; its own form when it is searched in that form
    alone) at that depth. None when ``fs`` is None or has no stiffness form (then the bed
    cannot be made stiffer without depositing it again)."""
    keys = _stiffness_form_keys(fs)
    if fs is None or keys is None:
        return None
    return {**keys, **{k: float(below) for k in fs.keys},
            "physics.soil_layering.lower_young_factor": float(factor)}


def hertz_floor_overrides(fs: FullSearch | None) -> dict[str, Any] | None:
    """Scenario overrides of the whole bed with the Hertz-Mindlin contact law at
    ``fs.hertz_floor`` x the scenario's Young's modulus, on the same bed (the stiffness form of
    the layering search ``fs``, as ``stiffer_soil_overrides``: the law does not change the
    deposition), or None when ``fs`` has no such run or no stiffness form."""
    if fs is None or fs.hertz_floor is None:
        return None
    ov = stiffer_soil_overrides(fs, fs.hertz_floor)
    return None if ov is None else {**ov, "soil.contact_law": "hertz_mindlin"}


def impact_young_range() -> tuple[float, float]:
    """The allowed ``soil.impact_young_factor`` (the grains' impact modulus factor), from the
    scenario schema."""
    from crashdem.scenario import SCHEMA

    field = SCHEMA["soil"]["impact_young_factor"]
    return float(field.lo), float(field.hi)


@dataclass(frozen=True)
class BedFloor:
    """The realisation floor's stiffer soil on a search that has no layering to make it with
    (``stiffer_soil_overrides`` needs the layering searched in its stiffness form): a scenario
    with its own layering, such as the reference campaign's compacted lower part, where the
    layering is the scenario's physics and is not searched. The whole bed (both layers, and a
    wall of the soil's modulus) is made stiffer through the grains' impact modulus
    (``soil.impact_young_factor``) on the same bed, at each of ``factors``; with ``hertz`` the
    whole bed also runs in the Hertz-Mindlin contact law at that factor (a linear scenario's,
    as ``FullSearch.hertz_floor``). The bed below its top grain row (``stiffer_soil_depths``)
    has no such run: it would be a second layer."""

    factors: tuple[float, ...] = STIFFER_SOIL_FACTORS
    hertz: float | None = None

    def __post_init__(self) -> None:
        lo, hi = impact_young_range()
        for name, fs in (("factors", self.factors),
                         ("hertz", () if self.hertz is None else (self.hertz,))):
            for f in fs:
                if not (isinstance(f, (int, float)) and math.isfinite(f) and lo <= f <= hi):
                    raise ValueError(f"BedFloor.{name}: {f!r} must be in [{lo:g}, {hi:g}] (the "
                                     "grains' impact modulus factor, soil.impact_young_factor)")

    def overrides(self) -> list[tuple[float, dict[str, Any]]]:
        """(factor, scenario overrides) of each run, the Hertz-Mindlin one last."""
        out = [(float(f), {"soil.impact_young_factor": float(f)}) for f in self.factors]
        if self.hertz is not None:
            out.append((float(self.hertz), {"soil.impact_young_factor": float(self.hertz),
                                            "soil.contact_law": "hertz_mindlin"}))
        return out


def _stiffness_form_keys(fs: FullSearch | None) -> dict[str, Any] | None:
    """The fixed overrides of the stiffness form of the layering search ``fs`` (its own form
    when it is searched in that form alone), or None when ``fs`` is None or has no such form."""
    if fs is None:
        return None
    forms = dict(fs.forms)
    if "stiffness" in forms:
        return {**fs.fixed, **forms["stiffness"]}
    return dict(fs.fixed) if fs.form == "stiffness" else None


def layer_level_factor(fs: FullSearch | None) -> float | None:
    """The modulus factor below the interface at which the stiffness form of the layering
    search ``fs`` runs its levels (``physics.soil_layering.lower_young_factor``), or None when
    ``fs`` is None or has no stiffness form: the stiffer-soil run of that factor
    (``stiffer_soil_overrides``) is the level without its interface."""
    keys = _stiffness_form_keys(fs)
    f = None if keys is None else keys.get("physics.soil_layering.lower_young_factor")
    return None if f is None else float(f)


DROP_FULL_SEARCH: dict[str, FullSearch] = {
    "soil_layering": FullSearch(
        "interface_depth", "m", ("physics.soil_layering.depth",),
        (0.15, 0.2, 0.25, 0.3, 0.4, 0.5),
        {"physics.soil_layering.enabled": True, "physics.soil_layering.lower_young_factor": 5.0},
        deposits=True, forms=LAYER_FORMS),
    "boundary_proximity": FullSearch(
        "floor_depth", "m", ("physics.boundary_proximity.floor_depth",),
        (0.6, 0.7, 0.8, 0.9, 1.05, 1.25), {"physics.boundary_proximity.enabled": True},
        deposits=True, extension=(0.5, 0.4)),
    "cohesion": FullSearch(
        "cohesion", "Pa", ("physics.cohesion.normal_strength",
                                   "physics.cohesion.shear_strength"),
        (3.0e4, 6.0e4, 1.2e5, 2.4e5, 4.8e5), {"physics.cohesion.enabled": True}, "log", "low"),
    "contact_damping": FullSearch(
        "restitution", "1", ("physics.contact_damping.restitution",),
        (0.1, 0.2, 0.3, 0.5), {"physics.contact_damping.enabled": True},
        forms=DAMPING_FORMS),
    "particle_rotation": FullSearch(
        "rolling_coefficient", "1", ("soil.rolling_coefficient",
                                     "physics.particle_rotation.rolling_coefficient"),
        (0.0, 0.05, 0.2), {"physics.particle_rotation.enabled": True, "soil.rotation": "free"}),
}


class Catalogue:
    """A set of candidate hypotheses for one screening model (names from issue 7).

    ``model`` names the screening model whose parameter names the entries use (``"drop"``:
    ``rom.RomParams``; ``"planar"``: ``rom_planar.PlanarParams`` and its soil record).
    ``excluded`` maps catalogue names the model does not represent to the reason (reported).
    ``full_search`` maps entry names to their full-model search levels (``FullSearch``);
    ``full_unsupported`` maps entry names the model's full simulation cannot run to the reason
    (their confirmation is skipped and the next candidate takes the place)."""

    def __init__(self, entries: tuple[Hypothesis, ...], model: str,
                 excluded: dict[str, str] | None = None,
                 full_search: dict[str, FullSearch] | None = None,
                 full_unsupported: dict[str, str] | None = None):
        self.entries = tuple(entries)
        self.model = model
        self.excluded = dict(excluded or {})
        self.full_unsupported = dict(full_unsupported or {})
        self.full_search = {k: v for k, v in (full_search or {}).items()
                            if k in self.names}

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the entries, in catalogue order."""
        return tuple(h.name for h in self.entries)

    def get(self, name: str) -> Hypothesis:
        """The entry (or the recalibration pseudo-hypothesis) called ``name``; ``"a+b"`` is the
        combination of entries a and b (``combine``)."""
        if name == RECALIBRATION.name:
            return RECALIBRATION
        if "+" in name:
            return self.combine(*name.split("+"))
        for h in self.entries:
            if h.name == name:
                return h
        if name in self.excluded:
            raise ValueError(f"hypothesis {name!r}: not represented by the {self.model} model "
                             f"({self.excluded[name]})")
        import difflib

        known = [*self.names, RECALIBRATION.name]
        close = difflib.get_close_matches(name, known, n=3)
        raise ValueError(f"hypothesis {name!r}: unknown; known: {known}"
                         + (f"; did you mean {close}?" if close else ""))

    def combine(self, *names: str) -> Hypothesis:
        """Several entries switched on together (name ``"a+b"``)."""
        hs = [self.get(n) for n in names]
        params: list[ParameterSpec] = []
        for h in hs:
            params += [p for p in h.parameters if p.name not in {q.name for q in params}]

        # discrete forms: the product of the parts' variants (labels joined by "+")
        variants: tuple[Variant, ...] = ()
        for h in hs:
            if not h.variants:
                continue
            if not variants:
                variants = h.variants
            else:
                variants = tuple(Variant(f"{a.label}+{b.label}", {**a.rom_values, **b.rom_values},
                                         {**a.scenario, **b.scenario}) for a in variants
                                 for b in h.variants)
        return Hypothesis("+".join(names), " AND ".join(h.physics for h in hs), tuple(params),
                          None, tuple(sig for h in hs for sig in h.signature),
                          to_scenario=functools.partial(_combined_to_scenario, tuple(hs)),
                          variants=variants)

    def describe(self) -> list[dict[str, Any]]:
        """JSON-ready descriptions of the recalibration and every entry."""
        return [h.describe() for h in (RECALIBRATION, *self.entries)]


#: the drop-test catalogue (``rom.RomParams`` parameter names)
DROP = Catalogue(CATALOGUE, "drop", full_search=DROP_FULL_SEARCH,
                 full_unsupported={"structural_crush": "the drop sphere is rigid (crashdem.run "
                                                       "needs the glider's crushable nose)"})
NAMES: tuple[str, ...] = DROP.names


def drop_catalogue(base=None) -> Catalogue:
    """The drop catalogue for the screening model ``base`` (``rom.RomParams``): ``DROP`` with
    the floor of ``boundary_proximity`` searched above the modelled one only.

    The entry is a floor *nearer* than modelled (or the modelled floor of another compliance),
    so its depth runs from ``min(0.4 m, H / 5)`` to the modelled soil thickness
    ``H = base.floor_depth``, where it vanishes (``off``). A floor farther than the bed is not
    this effect: in the screening model it is the reflected pulse arriving later (a slower
    soil, i.e. a recalibration), and in the full model it is another, deeper deposition.
    The other entries are ``DROP``'s; ``base`` None gives ``DROP`` itself."""
    if base is None:
        return DROP
    h_bed = float(base.floor_depth)
    if not (math.isfinite(h_bed) and h_bed > 0.0):
        raise ValueError(f"drop_catalogue: base.floor_depth={h_bed!r} must be a finite "
                         "thickness > 0 [m]")
    entries = []
    for h in DROP.entries:
        if h.name == "boundary_proximity":
            f = h.parameters[0]
            lo = min(f.lo, 0.2 * h_bed)
            nominal = min(f.nominal, 0.6 * h_bed)
            h = replace(h, parameters=(
                replace(f, lo=lo, hi=h_bed, nominal=max(lo, nominal), off=h_bed),
                *h.parameters[1:]))
        entries.append(h)
    return Catalogue(tuple(entries), DROP.model, DROP.excluded, DROP.full_search,
                     DROP.full_unsupported)


def combine(*names: str) -> Hypothesis:
    """Several drop-catalogue effects switched on together (name ``"a+b"``)."""
    return DROP.combine(*names)


def get(name: str) -> Hypothesis:
    """The drop-catalogue entry (or the recalibration pseudo-hypothesis) called ``name``;
    ``"a+b"`` is the combination of entries a and b (``combine``)."""
    return DROP.get(name)


def planar_catalogue(base, geometry: dict[str, float] | None = None) -> Catalogue:
    """The catalogue of the planar (glider) screening model ``rom_planar.PlanarParams``.

    Same entries and parameters as the drop catalogue for the soil, sensor and crush physics;
    ``boundary_proximity`` is the container's rear wall (its horizontal distance ahead of the
    first contact point and its stiffness; ``off`` = the baseline's wall) and
    ``initial_conditions`` adds the flight-path angle and pitch attitude offsets.
    ``soil_layering`` is not represented: the container's layers are horizontal, the planar
    model's interface runs parallel to the slope face, and the scenario's one interface is
    already in use (the compacted lower part).

    geometry : scenario facts for the scenario mapping (``crashdem.diagnosis.cli``):
        ``impact_height`` [m], ``slope`` [rad] (container length from the wall distance) and
        ``wall_young`` [Pa] (the panel modulus that gives the baseline's ``wall_stiffness``).
        Without them the two wall parameters have no scenario key.
    """
    geo = dict(geometry or {})
    d0 = float(base.wall_distance) if math.isfinite(base.wall_distance) else 4.0
    k0 = float(base.wall_stiffness)
    # the wall's basin is narrow (the second peak's timing): 24 grid levels over at most
    # 1.25 x the modelled distance; the range reaches below the nominal 0.75 x it however near
    # the modelled wall is
    d_hi = max(2.0, 1.25 * d0)
    d_lo = min(0.2, 0.5 * d0)

    entries = []
    for h in CATALOGUE:
        if h.name == "soil_layering":
            continue
        if h.name == "boundary_proximity":
            h = Hypothesis(
                "boundary_proximity",
                ("The container's rear wall nearer than modelled or of another compliance: the "
                 "nose reaches it and a second longitudinal peak appears (thesis section 2.4); "
                 "penalty contact of the nose on a vertical wall."),
                (ParameterSpec("wall_distance", "m", d_lo, d_hi, 0.75 * d0, "lin",
                               "horizontal distance from the first contact point to the rear "
                               "wall", None, off=d0, grid=24),
                 ParameterSpec("wall_stiffness", "N/m", k0 / 30.0, k0 * 30.0, k0, "log",
                               "rear-wall stiffness at the nose (panel generalised stiffness)",
                               None, off=k0, grid=3)),
                "physics.boundary_proximity.enabled",
                ("missing_peak", "extra_peak", "peak_early"),
                to_scenario=functools.partial(_wall_to_scenario, geo, k0))
        elif h.name == "initial_conditions":
            h = Hypothesis(
                "initial_conditions",
                ("The impact differed from the modelled one: an offset of the impact speed, of "
                 "the flight-path angle or of the pitch attitude at contact."),
                (h.parameters[0],
                 ParameterSpec("angle_offset", "rad", -0.3, 0.3, 0.0, "lin",
                               "added to the flight-path angle below horizontal",
                               None, off=0.0),
                 ParameterSpec("pitch_offset", "rad", -0.3, 0.3, 0.0, "lin",
                               "added to the pitch attitude (nose up positive)", None, off=0.0)),
                "physics.initial_conditions.enabled",
                ("initial_offset", "peak_too_high", "peak_too_low", "peak_early", "peak_late"),
                to_scenario=_planar_ic_to_scenario)
        entries.append(h)
    return Catalogue(tuple(entries), "planar",
                     {"soil_layering": "the container's layers are horizontal, the planar "
                                       "model's interface is parallel to the slope face"})

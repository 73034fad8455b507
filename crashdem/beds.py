"""Beds imported from a file (``soil.packing_file``) instead of deposited by crashdem.

A crash engineer often has the bed already: deposited by another DEM code (Yade's
``export.text`` / ``SpherePack.save``, a LIGGGHTS dump reduced to centres and radii) or by an
earlier crashdem run. Running the impact on *that* bed compares like with like: what then
differs between two codes is their contact laws, integrators and boundaries, not their
depositions (``validation/diagnosis_yade/same_bed.py`` does this against Yade).

Formats (SI, metres):

* ``.npz``: arrays ``x`` (N, 3) centres and ``radius`` (N,) (as ``numpy.savez`` writes them);
* anything else: text, one grain per row ``x y z r`` separated by blanks or commas; ``#`` starts
  a comment (Yade's ``#format x_y_z_r`` header is one).

The bed stands in the scenario's container as given: its floor at z = 0, a cylinder tank
centred on the z axis, a box centred on the origin. Every grain must lie inside the container
(a grain may overlap a wall by ``WALL_OVERLAP`` of its radius, the contact overlap a settled bed
has against its walls); the first grain outside is named in the error. The grains take the
scenario's soil material; with ``physics.soil_layering`` on, those whose centre lies deeper than
``physics.soil_layering.depth`` below the bed's free surface (``free_surface``) take the lower
layer's material, as a stiffness-only layer of a deposited bed does below its nominal top.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import numpy as np

from crashdem.scenario import Scenario, ScenarioError

#: overlap of a grain with a container wall or the floor accepted in an imported bed, as a
#: fraction of its radius (a settled bed presses its walls by well under 1 %; a grain past this
#: has escaped the container or the bed belongs to another one)
WALL_OVERLAP = 0.05

FIELD = "soil.packing_file"


def read_bed(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Centres (N, 3) and radii (N,) [m] of the bed file ``path`` (formats: module docstring).

    Raises ``ScenarioError`` naming ``soil.packing_file`` when the file is missing, unreadable
    or holds no valid grains (non-finite values, radius <= 0, a wrong shape)."""
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"{FIELD}={str(path)!r}: no such file (give an .npz with x (N,3) and "
                            "radius (N,) [m], or a text file of rows 'x y z r' [m])")
    try:
        if p.suffix.lower() == ".npz":
            with np.load(p, allow_pickle=False) as z:
                missing = [k for k in ("x", "radius") if k not in z.files]
                if missing:
                    raise ScenarioError(f"{FIELD}={str(path)!r}: the .npz has no array "
                                        f"{missing[0]!r} (needs x (N,3) and radius (N,) [m]; "
                                        f"it has {sorted(z.files)})")
                x = np.asarray(z["x"], dtype=np.float64)
                r = np.asarray(z["radius"], dtype=np.float64)
        else:
            rows = np.loadtxt(p, comments="#", delimiter=_delimiter(p), ndmin=2)
            if rows.shape[1] != 4:
                raise ScenarioError(f"{FIELD}={str(path)!r}: rows of {rows.shape[1]} columns; "
                                    "each row must be 'x y z r' [m]")
            x, r = rows[:, :3].copy(), rows[:, 3].copy()
    except ScenarioError:
        raise
    except (OSError, ValueError) as e:
        raise ScenarioError(f"{FIELD}={str(path)!r}: cannot be read as a bed ({e})") from None
    if x.ndim != 2 or x.shape[1] != 3 or r.shape != (x.shape[0],) or len(r) == 0:
        raise ScenarioError(f"{FIELD}={str(path)!r}: x must be (N, 3) and radius (N,) with "
                            f"N >= 1; got x {x.shape} and radius {r.shape}")
    bad = ~(np.all(np.isfinite(x), axis=1) & np.isfinite(r) & (r > 0.0))
    if bad.any():
        i = int(np.argmax(bad))
        raise ScenarioError(f"{FIELD}={str(path)!r}: grain {i} has centre {x[i].tolist()} and "
                            f"radius {r[i]!r}; centres must be finite and radii > 0 [m]")
    return x, r


def _delimiter(p: Path) -> str | None:
    """',' when the first data row of the text file ``p`` has commas, else blanks."""
    with open(p, encoding="utf-8", errors="replace") as f:
        for line in f:
            s = line.split("#", 1)[0].strip()
            if s:
                return "," if "," in s else None
    return None


def _through_floor(x: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Mask of the grains through the floor z = 0 by more than ``WALL_OVERLAP`` of their radius."""
    return x[:, 2] - r < -WALL_OVERLAP * r


def _through_cylinder(x: np.ndarray, r: np.ndarray, radius: float) -> np.ndarray:
    """Mask of the grains through a cylinder wall of ``radius`` on the z axis by more than
    ``WALL_OVERLAP`` of their radius."""
    return np.hypot(x[:, 0], x[:, 1]) + r - radius > WALL_OVERLAP * r


def inside_cylinder(x: np.ndarray, r: np.ndarray, radius: float) -> np.ndarray:
    """Mask of the grains an imported bed may hold in a cylinder tank of ``radius`` on the z
    axis: above the floor and inside the wall, each within ``WALL_OVERLAP`` of their radius."""
    return ~(_through_floor(x, r) | _through_cylinder(x, r, radius))


def _outside(scen: Scenario, x: np.ndarray, r: np.ndarray, top: float) -> tuple[int, str] | None:
    """The first grain of the bed outside the scenario's container (index, how), or None."""
    below = _through_floor(x, r)
    if below.any():
        i = int(np.argmax(below))
        return i, f"below the floor (z - r = {x[i, 2] - r[i]:.4g} m, allowed >= 0)"
    if scen["container.shape"] == "cylinder":
        R = 0.5 * scen["container.diameter"]
        out = _through_cylinder(x, r, R)
        if out.any():
            i = int(np.argmax(out))
            rad = float(np.hypot(x[i, 0], x[i, 1]) + r[i])
            return i, (f"outside the tank wall (distance from the axis + r = {rad:.4g} m, "
                       f"allowed <= container.diameter/2 = {R:g} m)")
    else:
        half = np.array([0.5 * scen["container.length"], 0.5 * scen["container.width"]])
        reach = np.abs(x[:, :2]) + r[:, None]
        out = np.any(reach - half > WALL_OVERLAP * r[:, None], axis=1)
        if out.any():
            i = int(np.argmax(out))
            return i, (f"outside the box (|x|, |y| + r = {reach[i].tolist()} m, allowed <= "
                       f"container.length/2, container.width/2 = {half.tolist()} m)")
    high = x[:, 2] + r > top
    if high.any():
        i = int(np.argmax(high))
        return i, f"above the container's top at {top:g} m (z + r = {x[i, 2] + r[i]:.4g} m)"
    return None


#: grains needed in the central footprint of an imported bed to locate its free surface
SURFACE_MIN_GRAINS = 10
#: the footprint keeps this many mean grain radii clear of the container's walls
SURFACE_WALL_CLEARANCE = 3.0


def footprint_surface(x: np.ndarray, r: np.ndarray, *, radius: float | None = None,
                      half_length: float | None = None, half_width: float | None = None
                      ) -> tuple[float | None, int]:
    """Height [m] of a bed's free surface over a container's central footprint, and the number
    of grain centres in that footprint. The container is a cylinder of ``radius`` about the z
    axis, or a box of ``half_length`` x ``half_width`` about it; its footprint is the
    cross-section with ``SURFACE_WALL_CLEARANCE`` mean radii kept clear of the walls. The
    surface is ``soil.packing.free_surface_height`` of the grains there: the level at which the
    solid fraction of horizontal sections falls for the last time to half of the bed's own. None
    (with the count) when fewer than ``SURFACE_MIN_GRAINS`` grains lie in the footprint. The
    one definition of a bed's surface for an imported bed (``free_surface``) and for the Yade
    validation's realised depths (``validation/diagnosis_yade/cases.bed_surface``)."""
    from soil.packing import free_surface_height

    x = np.asarray(x, float)
    r = np.asarray(r, float)
    clear = SURFACE_WALL_CLEARANCE * float(np.mean(r))
    if radius is not None:
        within = float(radius) - clear
        inside = np.hypot(x[:, 0], x[:, 1]) < within
        area = math.pi * max(within, 0.0) ** 2
    elif half_length is not None and half_width is not None:
        hx, hy = float(half_length) - clear, float(half_width) - clear
        inside = (np.abs(x[:, 0]) < hx) & (np.abs(x[:, 1]) < hy)
        area = 4.0 * max(hx, 0.0) * max(hy, 0.0)
    else:
        raise ValueError("footprint_surface: give radius, or half_length and half_width")
    n = int(np.count_nonzero(inside))
    if n < SURFACE_MIN_GRAINS or area <= 0.0:
        return None, n
    return float(free_surface_height(x[inside, 2], r[inside], area)), n


def free_surface(scen: Scenario, x: np.ndarray, r: np.ndarray) -> float:
    """Height [m] of an imported bed's free surface over the container's central footprint
    (``footprint_surface``). For a bed cut where the grain centres pass a height, as crashdem
    deposits its layers, this is that height to within a fraction of a radius: a layer depth
    then means the same on an imported bed as on a deposited one (below the free surface),
    whatever grain happens to stand highest. ``ScenarioError`` naming
    ``physics.soil_layering.depth`` when fewer than ``SURFACE_MIN_GRAINS`` grains lie in the
    footprint."""
    if scen["container.shape"] == "cylinder":
        z, n = footprint_surface(x, r, radius=0.5 * scen["container.diameter"])
    else:
        z, n = footprint_surface(x, r, half_length=0.5 * scen["container.length"],
                                 half_width=0.5 * scen["container.width"])
    if z is None:
        raise ScenarioError(
            f"physics.soil_layering.depth={scen['physics.soil_layering.depth']!r}: the depth is "
            f"counted from the imported bed's free surface, located in the container's central "
            f"footprint ({SURFACE_WALL_CLEARANCE:g} mean radii clear of the walls), which holds "
            f"{n} grains of {str(scen[FIELD])!r}; needs at least {SURFACE_MIN_GRAINS}")
    return z


def check_scenario(scen: Scenario) -> None:
    """Refuse what an imported bed cannot take, before the file is read: a floor depth
    (``physics.boundary_proximity.floor_depth`` re-deposits the bed; the file's bed has its own
    floor at z = 0). ``ScenarioError`` naming the field."""
    if (scen["physics.boundary_proximity.enabled"]
            and scen["physics.boundary_proximity.floor_depth"] is not None):
        raise ScenarioError(
            f"physics.boundary_proximity.floor_depth={scen['physics.boundary_proximity.floor_depth']!r}"
            f": a floor depth re-deposits the bed, and {FIELD} gives the bed with its own floor "
            "at z = 0; allowed: null with an imported bed")


def imported_packing(scen: Scenario, spec: Any, container_top: float) -> Any:
    """The ``soil.packing.Packing`` of the scenario's ``soil.packing_file`` with the materials of
    its deposition spec ``spec`` (``crashdem.run.packing_spec``): the upper soil for every
    grain, the lower layer's below ``physics.soil_layering.depth`` from the bed's free surface
    (``free_surface``) when the layering is on. ``container_top`` [m]: the height of the container's walls."""
    from soil import packing as pk

    path = Path(scen["soil.packing_file"])
    check_scenario(scen)
    x, r = read_bed(path)
    bad = _outside(scen, x, r, container_top)
    if bad is not None:
        i, how = bad
        raise ScenarioError(f"{FIELD}={str(path)!r}: grain {i} of {len(r)} (centre "
                            f"{np.round(x[i], 5).tolist()} m, radius {r[i]:.5g} m) is {how}; "
                            f"a grain may overlap a wall by {WALL_OVERLAP:g} of its radius. "
                            "Remove grains that escaped the container, or set the container "
                            "to the bed's")
    from crashdem.run import lower_grains, soil_material

    top = float(np.max(x[:, 2] + r))
    material = np.zeros(len(r), dtype=np.int32)
    materials = (spec.materials[0],)
    if scen["physics.soil_layering.enabled"]:
        surface = free_surface(scen, x, r)
        material[lower_grains(scen, x, surface)] = 1
        materials = (spec.materials[0], soil_material(scen, lower=True))
        info_layer = {"free_surface_z": surface}
    else:
        info_layer = {}
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    info = {"source": "imported", "packing_file": str(path), "packing_file_sha256": digest,
            "grains": int(len(r)), "bed_top_z": top, **info_layer}
    return pk.Packing(x=x, radius=r, material=material, materials=materials,
                      spec={"imported": str(path), "sha256": digest}, seed=0,
                      porosity=math.nan, porosity_region=None, info=info)

"""The physics catalogue: names, parameter specs, scenario keys accepted by the scenario loader."""
from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from crashdem.diagnosis import catalogue
from crashdem.diagnosis.rom import RomParams

ISSUE7_NAMES = ("soil_layering", "boundary_proximity", "cohesion", "particle_rotation",
                "contact_damping", "sensor_dynamics", "structural_crush", "initial_conditions")


def test_names_are_the_issue_7_catalogue():
    assert catalogue.NAMES == ISSUE7_NAMES
    assert catalogue.get("recalibration") is catalogue.RECALIBRATION
    with pytest.raises(ValueError, match="did you mean"):
        catalogue.get("cohesoin")


@pytest.mark.parametrize("h", catalogue.CATALOGUE, ids=lambda h: h.name)
def test_entry_is_complete_and_maps_onto_rom_and_scenario(h):
    """Every parameter is a ROM field with SI unit, bounds, nominal and 'off' inside the bounds;
    the scenario overrides it produces are accepted by ``crashdem.scenario`` (field names and
    ranges checked by the loader)."""
    assert h.physics and h.scenario_switch == f"physics.{h.name}.enabled"
    fields = set(RomParams.__dataclass_fields__)
    for p in h.parameters:
        assert p.name in fields and p.unit
        assert p.from_unit(p.to_unit(p.nominal)) == pytest.approx(p.nominal, rel=1e-12)
        RomParams().with_values({p.name: p.nominal})  # valid ROM value
    scenario = pytest.importorskip("crashdem.scenario")
    ov = h.scenario_overrides({p.name: p.nominal for p in h.parameters})
    assert ov[h.scenario_switch] is True
    scenario.loads("").with_overrides(ov)


@given(st.floats(min_value=0.0, max_value=0.6))
def test_rolling_mapping_round_trip(mu):
    """The ROM's friction-ratio <-> rolling-coefficient map is monotone and invertible."""
    r = catalogue.friction_ratio_from_rolling(mu)
    assert catalogue.FREE_ROTATION_RATIO <= r <= 1.0
    if r < 1.0 - 1e-9:
        assert catalogue.rolling_from_friction_ratio(r) == pytest.approx(mu, abs=1e-6)


def test_parameter_spec_errors_name_the_field():
    with pytest.raises(ValueError, match=r"ParameterSpec\.x\.nominal=5.*\[0, 1\] \[m\]"):
        catalogue.ParameterSpec("x", "m", 0.0, 1.0, 5.0)


@given(st.floats(min_value=0.1, max_value=20.0))
def test_drop_catalogue_searches_a_floor_above_the_modelled_one(h_bed):
    """``boundary_proximity`` is a floor nearer than modelled: for a screening model with a
    bed of thickness H its depth runs up to H, where the effect is off, and starts no deeper
    than H / 5; every other entry is the drop catalogue's."""
    cat = catalogue.drop_catalogue(RomParams(floor_depth=h_bed))
    f = cat.get("boundary_proximity").parameters[0]
    assert f.name == "floor_depth"
    assert f.hi == h_bed and f.off == h_bed
    assert f.lo <= 0.2 * h_bed + 1e-12 and f.lo <= 0.4 and f.lo <= f.nominal <= f.hi
    assert cat.names == catalogue.DROP.names
    assert cat.full_search == catalogue.DROP.full_search
    assert cat.full_unsupported == catalogue.DROP.full_unsupported
    for name in cat.names:
        if name != "boundary_proximity":
            assert cat.get(name) is catalogue.DROP.get(name)
    assert catalogue.drop_catalogue(None) is catalogue.DROP

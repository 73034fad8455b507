"""Scenario loader: checked fields, clear errors, typo suggestions, overrides, fuzzing."""
import string
import tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from crashdem import scenario as sc


def test_defaults_fill_every_field():
    s = sc.loads("")
    flat = s.flat()
    assert flat["soil.material.young"] == 2.0e7
    assert flat["instrumentation.sample_rate"] == 12500.0
    assert flat["physics.cohesion.enabled"] is False
    assert len(flat) == sum(1 for _ in sc._walk(sc.SCHEMA))


def test_impact_velocity_from_drop_height():
    """Oracle: free fall v = sqrt(2 g h): the thesis's 18.45 m gives 19.0 m/s (Tab 2.1)."""
    s = sc.loads("[impactor]\ndrop_height = 18.45\n")
    assert s.impact_velocity == pytest.approx(19.03, abs=0.01)
    s2 = s.with_overrides({"physics.initial_conditions.enabled": True,
                           "physics.initial_conditions.velocity_offset": -1.0})
    assert s2.impact_velocity == pytest.approx(18.03, abs=0.01)


def test_out_of_range_names_field_value_and_range():
    with pytest.raises(sc.ScenarioError) as e:
        sc.loads("[soil.material]\nyoung = -3e7\n", source="x.toml")
    msg = str(e.value)
    assert "x.toml" in msg and "soil.material.young" in msg and "-3" in msg and "(0, inf)" in msg


def test_typo_suggests_close_match():
    with pytest.raises(sc.ScenarioError, match=r"unknown field 'soil.material.yuong'.*'soil.material.young'"):
        sc.loads("[soil.material]\nyuong = 3e7\n")
    with pytest.raises(sc.ScenarioError, match=r"did you mean 'blocked'"):
        sc.loads("[soil]\nrotation = 'blockd'\n")


def test_wrong_types_rejected():
    with pytest.raises(sc.ScenarioError, match="scenario.seed"):
        sc.loads("[scenario]\nseed = 1.5\n")
    with pytest.raises(sc.ScenarioError, match="physics.cohesion.enabled"):
        sc.loads("[physics.cohesion]\nenabled = 1\n")
    with pytest.raises(sc.ScenarioError, match="must be a table"):
        sc.loads("soil = 3\n")


def test_overrides_are_checked():
    s = sc.loads("")
    assert s.with_overrides({"soil.material.young": 3e7}).get("soil.material.young") == 3e7
    with pytest.raises(sc.ScenarioError, match="did you mean 'young'"):
        s.with_overrides({"soil.material.yung": 3e7})
    assert sc.parse_override("soil.material.young=3e7") == ("soil.material.young", 3e7)
    assert sc.parse_override("scenario.name=abc") == ("scenario.name", "abc")
    with pytest.raises(sc.ScenarioError, match="key=value"):
        sc.parse_override("novalue")


def test_round_trip_toml():
    s = sc.loads("[soil]\nradius = 0.04\n[physics.cohesion]\nenabled = true\n")
    s2 = sc.loads(s.to_toml())
    assert s2.flat() == s.flat()


def test_shipped_scenarios_load():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "validation" / "scenarios"
    files = sorted(root.glob("*.toml"))
    assert files, "validation/ must ship scenario files"
    for f in files:
        sc.load(f)


_keys = st.sampled_from([p for p, _ in sc._walk(sc.SCHEMA)] + ["soil.bogus", "physics.x.y", "a"])
_values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12),
    st.floats(allow_nan=True, allow_infinity=True), st.text(string.printable, max_size=12),
    st.lists(st.floats(allow_nan=False), max_size=3),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(_keys, _values, max_size=6))
def test_fuzz_structured_inputs_never_crash_unclearly(fields):
    """Fuzz (Hypothesis): any assignment of any value to any key either loads or raises
    ScenarioError naming the offending field; nothing else escapes."""
    try:
        s = sc.loads("").with_overrides(fields)
    except sc.ScenarioError as exc:
        assert any(k in str(exc) for k in fields)
    else:
        for k in fields:
            assert k in s.flat()


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet=string.printable, max_size=200))
def test_fuzz_raw_text_never_crashes_unclearly(text):
    """Fuzz (Hypothesis): arbitrary text loads or raises ScenarioError, never another exception."""
    try:
        sc.loads(text, source="fuzz.toml")
    except sc.ScenarioError as exc:
        assert "fuzz.toml" in str(exc)


def test_markdown_reference_lists_every_field():
    md = sc.schema_markdown()
    for path, _ in sc._walk(sc.SCHEMA):
        assert f"`{path}`" in md


def test_docs_scenario_reference_is_current():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs/scenario_reference.md").read_text()
    assert sc.schema_markdown() in doc, "regenerate docs/scenario_reference.md with `crashdem schema`"

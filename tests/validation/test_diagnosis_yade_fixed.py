"""Pinned draws of the Yade truth (``yade_case(fixed=...)``, ``diagnose_yade.py --fix``): a
stronger effect than the drawn span on an otherwise unchanged case. No Yade run is needed: the
run is intercepted where the case hands its configuration to Yade."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from validation.diagnosis_yade import cases  # noqa: E402


class _Handed(Exception):
    pass


def _cfg(monkeypatch, tmp_path, *args, **kw) -> dict:
    """The configuration ``yade_case`` hands to Yade."""
    def intercept(cfg, cache):
        raise _Handed(cfg)

    monkeypatch.setattr(cases, "run_yade", intercept)
    with pytest.raises(_Handed) as got:
        cases.yade_case(*args, cache=tmp_path, **kw)
    return got.value.args[0]


def test_a_pinned_draw_changes_only_that_parameter(monkeypatch, tmp_path):
    drawn = _cfg(monkeypatch, tmp_path, 31, "cohesion")
    pinned = _cfg(monkeypatch, tmp_path, 31, "cohesion", fixed={"cohesion": 1.0e6})
    assert 1.0e5 <= drawn["cohesion"] <= 3.0e5 and pinned["cohesion"] == 1.0e6
    # the seed's other draws (grain radius, time step, Yade seed) are those of the drawn case
    assert {k: v for k, v in pinned.items() if k != "cohesion"} == \
        {k: v for k, v in drawn.items() if k != "cohesion"}
    bed = _cfg(monkeypatch, tmp_path, 32, "boundary_proximity", fixed={"bed_depth": 0.6})
    assert bed["bed_depth"] == 0.6


@pytest.mark.parametrize("effect, fixed, words", [
    ("cohesion", {"bed_depth": 0.6}, ["fixed['bed_depth']", "effect='cohesion'", "['cohesion']"]),
    (None, {"cohesion": 1e6}, ["fixed['cohesion']", "effect=None"]),
    ("boundary_proximity", {"bed_depth": 2.5}, ["fixed['bed_depth']=2.5", "(0.3, 2]", "[m]"]),
    ("cohesion", {"cohesion": -1.0}, ["fixed['cohesion']=-1.0", "[Pa]"]),
])
def test_a_pin_outside_the_truth_is_refused_with_its_name_and_range(monkeypatch, tmp_path,
                                                                    effect, fixed, words):
    monkeypatch.setattr(cases, "run_yade", lambda cfg, cache: pytest.fail("ran Yade"))
    with pytest.raises(ValueError) as err:
        cases.yade_case(21, effect, cache=tmp_path, fixed=fixed)
    for w in words:
        assert w in str(err.value), str(err.value)


@pytest.mark.parametrize("argv", [["--fix", "cohesion"], ["--fix", "cohesion=strong"],
                                  ["--effects", "cohesion", "--fix", "bed_depth=0.6"],
                                  # out of the truth's range: refused before any Yade run
                                  ["--effects", "boundary_proximity", "--fix", "bed_depth=2.5"],
                                  # a later --fix adds to an earlier one, not replaces it
                                  ["--effects", "cohesion", "--fix", "bed_depth=0.6",
                                   "--fix", "cohesion=1e6"]])
def test_the_script_refuses_a_malformed_pin(argv, capsys):
    from validation.diagnose_yade import main

    with pytest.raises(SystemExit) as ex:
        main(argv)
    assert ex.value.code == 2 and "--fix" in capsys.readouterr().err

"""``validation/diagnose_cost.py``'s truth: the effect's switch and value, or none
(``--effect none``) with a recalibrated soil (``--recalibrate``). No run: the truth's
configuration is intercepted where it is handed to the DEM."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


class _Handed(Exception):
    pass


def _truth(monkeypatch, tmp_path, *args) -> dict:
    from crashdem.diagnosis import generator_dem
    from validation import diagnose_cost

    def intercept(ov, filtered):
        raise _Handed(ov)

    monkeypatch.setattr(generator_dem, "run_dem", intercept)
    with pytest.raises(_Handed) as got:
        diagnose_cost.truth_recording(*args[:2], tmp_path, 1, *args[2:])
    return got.value.args[0]


def test_truth_with_an_effect_without_one_and_recalibrated(monkeypatch, tmp_path):
    from validation.diagnose_cost import DEFAULT_RESOLUTION

    damped = _truth(monkeypatch, tmp_path, "contact_damping", 0.15)
    assert damped["physics.contact_damping.enabled"] is True
    assert damped["physics.contact_damping.restitution"] == 0.15
    null = _truth(monkeypatch, tmp_path, None, 0.15)
    assert not any(k.startswith("physics.contact_damping") for k in null)
    assert {k: v for k, v in damped.items() if not k.startswith("physics.contact_damping")} \
        == null
    for k, v in DEFAULT_RESOLUTION.items():
        assert null[k] == v
    stiff = _truth(monkeypatch, tmp_path, None, 0.15, {"soil.material.young": 4.0e7})
    assert stiff == {**null, "soil.material.young": 4.0e7}


def test_a_free_rotation_and_a_mount_switch_only_their_own_physics(monkeypatch, tmp_path):
    """The free-rotation truth sets the rolling coefficient, the sensor truth a resonant mount
    (not the scenario's default seismic low-pass) at the frequency given, damping ratio 0.1;
    everything else is the null truth's."""
    null = _truth(monkeypatch, tmp_path, None, 0.0)
    rot = _truth(monkeypatch, tmp_path, "particle_rotation", 0.1)
    assert {k: v for k, v in rot.items() if not k.startswith("physics.particle_rotation")} \
        == null
    assert rot["physics.particle_rotation.enabled"] is True
    assert rot["physics.particle_rotation.rolling_coefficient"] == 0.1
    mount = _truth(monkeypatch, tmp_path, "sensor_dynamics", 60.0)
    assert {k: v for k, v in mount.items() if not k.startswith("physics.sensor_dynamics")} \
        == null
    assert (mount["physics.sensor_dynamics.enabled"], mount["physics.sensor_dynamics.model"],
            mount["physics.sensor_dynamics.natural_frequency"],
            mount["physics.sensor_dynamics.damping_ratio"]) == (True, "mount", 60.0, 0.1)
    from crashdem.diagnosis.generator_dem import scenario_path
    from crashdem.scenario import load

    # the keys and values are the scenario's own (a misspelt key or a value out of range
    # would be refused here rather than in a 50 s truth run)
    for ov in (rot, mount):
        load(scenario_path(), overrides=ov)


@pytest.mark.parametrize("argv", [["--effect", "none", "--recalibrate", "young"],
                                  ["--effect", "none", "--recalibrate", "soil.radius=0.1"],
                                  ["--recalibrate", "soil.material.young=1e12"]])
def test_the_script_refuses_a_malformed_recalibration(argv, capsys):
    from validation.diagnose_cost import main

    with pytest.raises(SystemExit) as ex:
        main(argv)
    assert ex.value.code == 2 and "--recalibrate" in capsys.readouterr().err


def test_the_ratio_is_taken_on_the_baseline_run_of_the_same_diagnosis(tmp_path):
    """``baseline_wall``: the wall time of the full run the diagnosis made of the scenario
    itself (its result file's ``wall_time``), the same-run reference of the benchmark's ratio;
    None without such a run (an existing result was used) or with a run that recorded none."""
    import h5py

    from validation.diagnose_cost import baseline_wall

    assert baseline_wall(tmp_path) is None
    (tmp_path / "baseline").mkdir()
    with h5py.File(tmp_path / "baseline" / "a.h5", "w") as f:
        f.attrs["wall_time"] = float("nan")  # a run killed before it finished
    assert baseline_wall(tmp_path) is None
    with h5py.File(tmp_path / "baseline" / "b.h5", "w") as f:
        f.attrs["wall_time"] = 42.5
    assert baseline_wall(tmp_path) == 42.5


def test_a_truth_of_other_grains(monkeypatch, tmp_path, capsys):
    """``--truth-grains F``: the null truth with the grain radius F x the scenario's 0.075 m and
    nothing else changed; outside ``TRUTH_GRAINS`` an error naming the span, before any run."""
    from validation.diagnose_cost import DEFAULT_RESOLUTION, TRUTH_GRAINS, truth_recording

    null = _truth(monkeypatch, tmp_path, None, 0.0)
    coarse = _truth(monkeypatch, tmp_path, None, 0.0, None, 1.25)
    radius = pytest.approx(1.25 * DEFAULT_RESOLUTION["soil.radius"])
    assert coarse == {**null, "soil.radius": radius}
    assert _truth(monkeypatch, tmp_path, None, 0.0, None, 1.0) == null
    for bad in (TRUTH_GRAINS[0] - 0.01, TRUTH_GRAINS[1] + 0.01, float("nan")):
        with pytest.raises(ValueError, match=r"grains=.*: must be in \[0.8, 1.5\]"):
            truth_recording(None, 0.0, tmp_path, 1, None, bad)
    # the command line says so before any run, naming the option
    from validation.diagnose_cost import main

    with pytest.raises(SystemExit):
        main(["--effect", "none", "--truth-grains", "2", "--out", str(tmp_path / "o")])
    assert "--truth-grains: grains=2.0: must be in [0.8, 1.5]" in capsys.readouterr().err


def test_a_truth_in_another_contact_law(monkeypatch, tmp_path, capsys):
    """``--truth-law hertz_mindlin --truth-young-factor F``: the null truth's impact in the
    Hertz-Mindlin law at F x the grains' modulus (``soil.contact_law``,
    ``soil.impact_young_factor``; the bed deposited as the scenario's), nothing else changed,
    and keys the scenario takes; a law or a factor it does not take is refused naming the
    field, before any run, and on the command line naming the options."""
    from crashdem.diagnosis.generator_dem import scenario_path
    from crashdem.scenario import load
    from validation.diagnose_cost import check_law, main, truth_recording

    null = _truth(monkeypatch, tmp_path, None, 0.0)
    hm = _truth(monkeypatch, tmp_path, None, 0.0, None, 1.0, "hertz_mindlin", 8.0)
    assert hm == {**null, "soil.contact_law": "hertz_mindlin", "soil.impact_young_factor": 8.0}
    assert _truth(monkeypatch, tmp_path, None, 0.0, None, 1.0, "linear", 1.0) == null
    load(scenario_path(), overrides=hm)
    assert check_law("linear", 2) == ("linear", 2.0)
    with pytest.raises(ValueError, match=r"law='hertz': must be one of linear, hertz_mindlin"):
        truth_recording(None, 0.0, tmp_path, 1, None, 1.0, "hertz", 4.0)
    for bad in (0.0, 1e3, float("nan")):
        with pytest.raises(ValueError, match=r"young_factor=.*soil\.impact_young_factor"):
            check_law("hertz_mindlin", bad)
    with pytest.raises(SystemExit):
        main(["--effect", "none", "--truth-young-factor", "0", "--out", str(tmp_path / "o")])
    assert "--truth-law / --truth-young-factor: young_factor=0.0" in capsys.readouterr().err

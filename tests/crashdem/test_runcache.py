"""The run cache (``crashdem.runcache``): a cached run is the run, bit for bit; the key sees
everything that decides a run's signals and nothing that only names its files; a killed or
failed run leaves no entry; a damaged entry is run again."""
from pathlib import Path

import h5py
import numpy as np
import pytest

from crashdem import scenario as sc
from crashdem.results import open_result
from crashdem.run import run_scenario
from crashdem.runcache import KEY_EXCLUDED, RunCache, code_fingerprint, from_option, run_key

ROOT = Path(__file__).resolve().parents[2]

TINY = {
    "scenario.name": "tiny_cached",
    "container.diameter": 1.3,
    "container.soil_depth": 0.45,
    "soil.radius": 0.075,
    "physics.soil_layering.enabled": False,
    "impactor.drop_height": 5.0,
    "solver.t_end": 0.02,
    "output.snapshots": 0,
    "output.plots": False,
    "scenario.threads": 1,
}
SCEN = ROOT / "validation/scenarios/drop_s2_h5p00.toml"


def _tiny(**over):
    return sc.load(SCEN, {**TINY, **over})


def _channels(path):
    with open_result(path) as res:
        return {n: (np.asarray(res.channel(n, filtered=False).t),
                    np.asarray(res.channel(n, filtered=False).data)) for n in res.channels()}


def test_the_key_sees_the_physics_and_not_the_names(tmp_path):
    base = run_key(_tiny())
    assert base is not None and len(base) == 24
    # the fields that only name or place the output do not change it
    assert run_key(_tiny(**{"scenario.name": "other", "scenario.description": "x",
                            "output.directory": str(tmp_path), "output.plots": True})) == base
    assert {s for s, _ in KEY_EXCLUDED} == {"scenario", "output"}
    # every field that shapes the signals does
    for k, v in {"scenario.seed": 2, "soil.radius": 0.076, "solver.safety": 0.31,
                 "impactor.drop_height": 5.01, "physics.cohesion.enabled": True,
                 "instrumentation.cfc": 180.0, "scenario.threads": 2,
                 "output.snapshots": 3}.items():
        assert run_key(_tiny(**{k: v})) != base, k
    # an imported bed is keyed by its contents, and a missing one has no key (it is run)
    bed = tmp_path / "bed.txt"
    bed.write_text("0 0 0.1 0.1\n")
    k1 = run_key(_tiny(**{"soil.packing_file": str(bed)}))
    bed.write_text("0 0 0.1 0.11\n")
    k2 = run_key(_tiny(**{"soil.packing_file": str(bed)}))
    assert None not in (k1, k2) and k1 != k2
    assert run_key(_tiny(**{"soil.packing_file": str(tmp_path / "none.txt")})) is None


def test_a_cached_run_is_the_run(tmp_path):
    """The second run of one scenario (another name, another directory) is taken from the
    cache: its channels are the first run's bit for bit, its stored scenario is its own, and it
    names the entry; a run of another scenario is made; ``keep=False`` gives the entry."""
    rc = RunCache(tmp_path / "cache")
    assert rc.directory == tmp_path / "cache" / code_fingerprint()
    first = rc.run(_tiny(), tmp_path / "a")
    assert (rc.hits, rc.runs) == (0, 1)
    assert first == tmp_path / "a" / "tiny_cached.h5"
    entries = list(rc.directory.glob("*.h5"))
    assert len(entries) == 1 and not list(rc.directory.glob(".*tmp"))
    second = rc.run(_tiny(**{"scenario.name": "again"}), tmp_path / "b")
    assert (rc.hits, rc.runs) == (1, 1)
    assert second == tmp_path / "b" / "again.h5"
    a, b = _channels(first), _channels(second)
    assert a.keys() == b.keys() and len(a) > 3
    for n in a:
        assert np.array_equal(a[n][0], b[n][0]) and np.array_equal(a[n][1], b[n][1]), n
    with open_result(second) as res:
        assert res.complete
        assert res.parameters["scenario"]["name"] == "again"
    with h5py.File(second, "r") as f:
        assert f.attrs["run_cache_entry"] == str(entries[0])
        assert f.attrs["run_cache_key"] == entries[0].stem
    with h5py.File(first, "r") as f:
        assert "run_cache_key" not in f.attrs
    assert rc.run(_tiny(), tmp_path / "c", keep=False) == entries[0]
    # a fresh run, not cached, gives the same channels again (the run is deterministic)
    fresh = _channels(run_scenario(_tiny(**{"scenario.name": "fresh"}), tmp_path / "d",
                                   progress=False))
    for n in a:
        assert np.array_equal(a[n][1], fresh[n][1]), n
    # another scenario is run; keep=False moves the new result into the cache
    other = rc.run(_tiny(**{"scenario.seed": 7}), tmp_path / "e", keep=False)
    assert other.parent == rc.directory and (rc.hits, rc.runs) == (2, 2)
    assert not (tmp_path / "e" / "tiny_cached.h5").exists()
    assert not np.array_equal(_channels(other)["drop_mass_accel_z"][1],
                              a["drop_mass_accel_z"][1])


def test_a_failed_run_leaves_no_entry_and_a_damaged_one_is_run_again(tmp_path, monkeypatch):
    import crashdem.run as run_mod

    rc = RunCache(tmp_path / "cache")

    def killed(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(run_mod, "run_scenario", killed)
    with pytest.raises(KeyboardInterrupt):
        rc.run(_tiny(), tmp_path / "a")
    assert not rc.directory.exists() or not any(rc.directory.iterdir())
    monkeypatch.undo()
    e = rc.entry(_tiny())
    e.parent.mkdir(parents=True)
    e.write_bytes(b"not an HDF5 file")
    assert rc.lookup(_tiny()) is None and not e.exists()
    path = rc.run(_tiny(), tmp_path / "b")
    assert rc.runs == 1 and rc.lookup(_tiny()) == e
    with open_result(path) as res:
        assert res.complete


def test_the_option_and_the_default_root(tmp_path, monkeypatch):
    monkeypatch.setenv("CRASHDEM_CACHE", str(tmp_path / "user"))
    assert from_option(None).root == tmp_path / "user" / "runs"
    assert from_option("off") is None and from_option("none") is None
    assert from_option(str(tmp_path / "x")).root == tmp_path / "x"
    import pickle

    rc = RunCache(tmp_path / "x")
    rc.hits = 3
    back = pickle.loads(pickle.dumps(rc))  # a worker gets the root, not the counts
    assert back.root == rc.root and back.hits == 0

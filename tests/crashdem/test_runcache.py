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


def _fake_entries(root, spec, now):
    """Entries ``{(version, name): (bytes, age_s)}`` under ``root`` (not results: prune reads
    sizes and times only)."""
    import os

    paths = {}
    for (version, name), (size, age) in spec.items():
        f = root / version / f"{name}.h5"
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_bytes(b"x" * size)
        os.utime(f, (now - age, now - age))
        paths[(version, name)] = f
    return paths


def test_parse_size_reads_sizes_and_names_the_field_of_a_bad_one():
    from crashdem.runcache import parse_size

    assert parse_size("20G") == 20 * 10**9
    assert parse_size("500 MB") == 500 * 10**6
    assert parse_size("1.5GiB") == int(1.5 * 2**30)
    assert parse_size("1000") == 1000 and parse_size(4096) == 4096
    for bad in ("12X", "", "-3G", "G", "0", "1e30"):
        with pytest.raises(ValueError, match="--max-size"):
            parse_size(bad, "--max-size")


def test_prune_evicts_the_least_recently_used_and_other_code_first(tmp_path):
    from crashdem.runcache import prune, usage

    now = 1.0e9
    cur = code_fingerprint()
    day = 86400.0
    p = _fake_entries(tmp_path, {
        (cur, "a"): (1000, 5 * day), (cur, "b"): (1000, 3 * day), (cur, "c"): (1000, 1 * day),
        (cur, "fresh"): (1000, 60.0),                       # used a minute ago: never evicted
        ("0123456789abcdef", "old"): (1000, 2 * day),       # another code version
    }, now)
    stray = tmp_path / cur / ".x.h5.pid1.tmp"
    stray.write_bytes(b"partial")
    import os

    os.utime(stray, (now - day, now - day))
    u = usage(tmp_path)
    assert u["entries"] == 5 and u["bytes"] == 5000 and u["versions"][cur]["current"]
    assert not u["versions"]["0123456789abcdef"]["current"]
    # a dry run reports and removes nothing
    dry = prune(tmp_path, max_bytes=2500, dry_run=True, now=now)
    assert all(f.exists() for f in p.values()) and stray.exists()
    # the other version goes first, then the least recently used of this code's
    out = prune(tmp_path, max_bytes=2500, now=now)
    assert out == dry
    assert set(out["removed"]) == {str(p["0123456789abcdef", "old"]), str(p[cur, "a"]),
                                   str(p[cur, "b"])}
    assert out["freed_bytes"] == 3000 and out["kept_bytes"] == 2000 and out["over_bytes"] == 0
    assert not (tmp_path / "0123456789abcdef").exists()   # its empty directory is gone too
    assert not stray.exists()                                # a killed copy's left-over
    # what was used within the grace period stays, even above the cap
    out = prune(tmp_path, max_bytes=10, now=now)
    assert out["removed"] == [str(p[cur, "c"])] and p[cur, "fresh"].exists()
    assert out["over_bytes"] == 990


def test_prune_by_age_and_by_code_version(tmp_path):
    from crashdem.runcache import prune

    now = 2.0e9
    cur = code_fingerprint()
    day = 86400.0
    p = _fake_entries(tmp_path, {(cur, "new"): (10, 2 * day), (cur, "old"): (10, 40 * day),
                                 ("ffffffffffffffff", "x"): (10, 2 * day)}, now)
    out = prune(tmp_path, stale=True, now=now)
    assert out["removed"] == [str(p["ffffffffffffffff", "x"])]
    out = prune(tmp_path, older_than_s=30 * day, now=now)
    assert out["removed"] == [str(p[cur, "old"])] and p[cur, "new"].exists()
    with pytest.raises(ValueError, match="older_than_s"):
        prune(tmp_path, older_than_s=-1.0)


def test_a_hit_is_a_use_and_a_capped_cache_evicts_on_store(tmp_path, monkeypatch):
    """A hit refreshes its entry's last use, so a size cap evicts the entry not used since;
    the cap comes from ``$CRASHDEM_RUN_CACHE_MAX`` (a bad value names the variable); an
    entry evicted between the lookup and the copy is run instead of failing."""
    import os
    import shutil

    from crashdem import runcache

    rc = RunCache(tmp_path / "cache")
    assert rc.max_bytes is None and "max_bytes" not in rc.describe()
    a = rc.run(_tiny(), tmp_path / "a", keep=False)
    b = rc.run(_tiny(**{"scenario.seed": 7}), tmp_path / "b", keep=False)
    long_ago = 1.0e9
    for e in (a, b):
        os.utime(e, (long_ago, long_ago))
    assert rc.run(_tiny(), tmp_path / "c", keep=False) == a   # a hit: a is used now
    assert a.stat().st_mtime > long_ago + 1e8
    monkeypatch.setenv(runcache.MAX_ENV, "nonsense")
    with pytest.raises(ValueError, match="CRASHDEM_RUN_CACHE_MAX"):
        RunCache(tmp_path / "cache")
    monkeypatch.setenv(runcache.MAX_ENV, str(a.stat().st_size + b.stat().st_size
                                             + b.stat().st_size // 2))
    capped = RunCache(tmp_path / "cache")
    c = capped.run(_tiny(**{"scenario.seed": 8}), tmp_path / "d", keep=False)
    assert c.exists() and a.exists() and not b.exists()       # b, unused since, went
    assert capped.describe()["evicted"] == 1
    import pickle

    assert pickle.loads(pickle.dumps(capped)).max_bytes == capped.max_bytes
    # an entry that vanishes after the lookup: the run is made again, not an error
    monkeypatch.delenv(runcache.MAX_ENV)
    rc2 = RunCache(tmp_path / "cache")
    real_copy = shutil.copyfile

    def evicted_meanwhile(src, dst, *k, **kw):
        if Path(src) == a:
            Path(src).unlink()
            raise FileNotFoundError(src)
        return real_copy(src, dst, *k, **kw)

    monkeypatch.setattr(runcache.shutil, "copyfile", evicted_meanwhile)
    out = rc2.run(_tiny(**{"scenario.name": "again"}), tmp_path / "e")
    assert (rc2.hits, rc2.runs) == (0, 1) and out.exists()
    with open_result(out) as res:
        assert res.complete


def test_the_cache_command_shows_and_prunes(tmp_path, capsys):
    """``crashdem cache`` over both caches: the finished runs (``runs/``) and the diagnoses'
    shared beds (``packings/<soil engine fingerprint>/``, ``crashdem.run.packing_cache``).
    Oracle: which files each option removes (a bed with its build lock), the counts printed,
    and exit code 2 with the option named for bad input."""
    import json
    import os
    import time

    from crashdem.cli import main
    from soil.packing import code_fingerprint as soil_fingerprint

    cur = code_fingerprint()
    now = time.time()
    p = _fake_entries(tmp_path / "runs", {(cur, "a"): (2000, 10 * 86400.0),
                                          (cur, "b"): (3000, 7200.0),
                                          ("0123456789abcdef", "c"): (500, 86400.0)}, now)
    soil = soil_fingerprint()
    beds = _fake_entries(tmp_path / "packings", {(soil, "packing-new"): (700, 7200.0),
                                                 (soil, "packing-old"): (800, 20 * 86400.0),
                                                 ("fedcba9876543210", "packing-x"): (900, 60.0)},
                         now)
    lock = beds[soil, "packing-old"].with_suffix(".lock")
    lock.write_bytes(b"")
    stray = tmp_path / "packings" / soil / "packing-new.h5.tmp99"
    stray.write_bytes(b"half")
    os.utime(stray, (now - 86400.0, now - 86400.0))
    (tmp_path / "exports").mkdir()
    (tmp_path / "exports" / "thing.bin").write_bytes(b"z" * 70)
    assert main(["cache", "--root", str(tmp_path), "info", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["runs"]["entries"] == 3 and info["runs"]["bytes"] == 5500
    assert info["packings"]["entries"] == 3 and info["packings"]["bytes"] == 2400
    assert info["packings"]["current"] == soil
    assert info["packings"]["versions"][soil]["current"]
    assert not info["packings"]["versions"]["fedcba9876543210"]["current"]
    assert info["other"] == {"exports": {"files": 1, "bytes": 70}}
    assert main(["cache", "--root", str(tmp_path), "info"]) == 0
    text = capsys.readouterr().out
    assert "runs: 3 runs" in text and "(other code)" in text and "packings: 3 beds" in text
    assert main(["cache", "--root", str(tmp_path), "prune", "--stale", "--dry-run"]) == 0
    # the other engine's bed was used a minute ago: it stays whatever the criteria
    assert "would remove 1 run entries and 0 beds" in capsys.readouterr().out
    assert p["0123456789abcdef", "c"].exists()
    assert main(["cache", "--root", str(tmp_path), "prune", "--older-than", "5"]) == 0
    assert "removed 1 run entries and 1 beds" in capsys.readouterr().out
    assert not p[cur, "a"].exists() and p[cur, "b"].exists()
    assert not beds[soil, "packing-old"].exists() and not lock.exists()
    assert beds[soil, "packing-new"].exists() and not stray.exists()
    assert main(["cache", "--root", str(tmp_path), "prune", "--only", "runs",
                 "--max-size", "1k"]) == 0
    assert not p["0123456789abcdef", "c"].exists() and not p[cur, "b"].exists()
    assert beds[soil, "packing-new"].exists()                  # --only runs keeps the beds
    assert main(["cache", "--root", str(tmp_path), "prune", "--max-size", "1k"]) == 0
    assert "removed 0 run entries and 1 beds" in capsys.readouterr().out.splitlines()[-1]
    assert not beds[soil, "packing-new"].exists()
    assert beds["fedcba9876543210", "packing-x"].exists()      # used within the hour
    assert (tmp_path / "exports" / "thing.bin").exists()       # not a cache of crashdem's
    # bad input: a clear message naming the option, exit code 2
    assert main(["cache", "--root", str(tmp_path), "prune"]) == 2
    assert "--max-size, --stale, --older-than" in capsys.readouterr().err
    assert main(["cache", "--root", str(tmp_path), "prune", "--max-size", "lots"]) == 2
    assert "--max-size" in capsys.readouterr().err
    assert main(["cache", "--root", str(tmp_path), "prune", "--older-than", "-2"]) == 2
    assert "--older-than" in capsys.readouterr().err


def test_shared_beds_are_those_of_this_soil_engine(tmp_path, monkeypatch):
    """A run directory or cache root kept across a change of the soil engine never offers the
    old engine's beds to the new one: ``share_packings`` points a run directory's link at the
    cache it is given even when an earlier call linked it elsewhere (a real directory is kept),
    and the diagnosis truths' beds live under the engine's fingerprint
    (``generator_dem.packings_dir``). Regression: a CI home that kept the previous engine's
    beds in ``diagnosis_truth/runs/pid<N>/packings`` failed 26 tests on the rebuild warning."""
    from crashdem.diagnosis import generator_dem as gd
    from crashdem.run import packing_cache, share_packings
    from soil.packing import code_fingerprint

    old = tmp_path / "packings" / "0123456789abcdef"
    new = tmp_path / "packings" / "fedcba9876543210"
    run = tmp_path / "runs" / "pid1"
    share_packings(run, old)
    assert (run / "packings").is_symlink() and (run / "packings").resolve() == old.resolve()
    (old / "packing-x.h5").write_bytes(b"old engine")
    share_packings(run, new)  # the engine changed: re-pointed, the old beds left where they are
    assert (run / "packings").resolve() == new.resolve()
    assert not (run / "packings" / "packing-x.h5").exists() and (old / "packing-x.h5").exists()
    share_packings(run, new)  # idempotent
    assert (run / "packings").resolve() == new.resolve()

    own = tmp_path / "own_run"
    (own / "packings").mkdir(parents=True)
    (own / "packings" / "packing-y.h5").write_bytes(b"local")
    share_packings(own, new)  # a real directory (beds deposited in place) is never replaced
    assert not (own / "packings").is_symlink() and (own / "packings" / "packing-y.h5").exists()

    assert gd.packings_dir(tmp_path) == (tmp_path / "packings" / code_fingerprint()).absolute()
    assert gd.packings_dir(tmp_path) == packing_cache(tmp_path / "packings")
    monkeypatch.setenv("CRASHDEM_CACHE", str(tmp_path / "env"))
    assert gd.packings_dir() == (tmp_path / "env" / "packings" / code_fingerprint()).absolute()

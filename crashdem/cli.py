"""The ``crashdem`` command line.

Subcommands: ``run``, ``info``, ``plot``, ``export``, ``sweep``, ``calibrate``, ``diagnose``,
``cache`` and ``schema``. Errors in user input end with a one-line message and exit code 2;
no traceback.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

log = logging.getLogger("crashdem")


def _cmd_run(args: argparse.Namespace) -> int:
    from crashdem import scenario as sc
    from crashdem.run import run_scenario

    overrides = dict(sc.parse_override(s) for s in args.set or [])
    scen = sc.load(args.scenario, overrides)
    path = run_scenario(scen, out_dir=args.out, progress=not args.quiet, resume=args.resume,
                        plots=None if not args.no_plots else False)
    print(path)
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    import h5py

    from crashdem.results import open_result

    path = Path(args.result)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such result file")
    with h5py.File(path, "r", swmr=True) as f:
        is_ensemble = "members" in f and "channels" not in f
    if is_ensemble:
        from crashdem.ensemble import open_ensemble

        print(open_ensemble(path).summary())
        return 0
    with open_result(path) as res:
        print(res.summary())
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from crashdem.plotting import plot_result

    out = Path(args.out) if args.out else Path(args.result).with_suffix("")
    for p in plot_result(args.result, out, channels=args.channel or None):
        print(p)
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from crashdem.export import export_result

    for p in export_result(args.result, fmt=args.format, out=args.out):
        print(p)
    return 0


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from crashdem.diagnosis.cli import diagnose_command

    return diagnose_command(args)


def _human(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} TB"  # pragma: no cover


def _dir_bytes(d: Path) -> tuple[int, int]:
    files = [f for f in d.rglob("*") if f.is_file()]
    return len(files), sum(f.stat().st_size for f in files)


def _cmd_cache(args: argparse.Namespace) -> int:
    import json
    import os
    import time

    from crashdem import runcache

    base = Path(args.root or os.environ.get("CRASHDEM_CACHE") or "~/.cache/crashdem")
    base = base.expanduser().absolute()
    trees = {"runs": runcache.run_tree(base / "runs"),
             "packings": runcache.packing_tree(base / "packings")}
    if args.cache_command == "info":
        uses = {name: runcache.usage(tree) for name, tree in trees.items()}
        others = {d.name: dict(zip(("files", "bytes"), _dir_bytes(d)))
                  for d in sorted(base.iterdir()) if d.is_dir() and d.name not in trees} \
            if base.is_dir() else {}
        if args.json:
            print(json.dumps({"root": str(base), **uses, "other": others}, indent=1))
            return 0
        print(f"crashdem cache {base}")
        for name, use in uses.items():
            what = "runs" if name == "runs" else "beds"
            print(f"{name}: {use['entries']} {what}, {_human(use['bytes'])} "
                  f"(this code: {use['current']})")
            for fp, v in sorted(use["versions"].items(), key=lambda kv: -kv[1]["newest_use"]):
                age = (time.time() - v["newest_use"]) / 86400.0
                print(f"  {fp}{' (this code)' if v['current'] else ' (other code)'}: "
                      f"{v['entries']} {what}, {_human(v['bytes'])}, last used {age:.1f} days ago")
        for name, v in others.items():
            print(f"{name}: {v['files']} files, {_human(v['bytes'])}")
        cap = os.environ.get(runcache.MAX_ENV)
        print(f"size cap of the runs (${runcache.MAX_ENV}): {cap or 'none'}")
        return 0
    # prune
    if args.max_size is None and not args.stale and args.older_than is None:
        raise ValueError("cache prune: give at least one of --max-size, --stale, --older-than")
    max_bytes = None if args.max_size is None else runcache.parse_size(args.max_size,
                                                                       "--max-size")
    if args.older_than is not None and not (args.older_than >= 0):
        raise ValueError(f"--older-than: {args.older_than} is out of range; allowed: >= 0 days")
    chosen = [trees[name] for name in (("runs", "packings") if args.only is None
                                       else (args.only,))]
    out = runcache.prune(chosen, max_bytes=max_bytes, stale=args.stale,
                         older_than_s=None if args.older_than is None
                         else args.older_than * 86400.0, dry_run=args.dry_run)
    verb = "would remove" if args.dry_run else "removed"
    n_beds = sum(1 for f in out["removed"] if Path(f).is_relative_to(trees["packings"].root))
    print(f"{verb} {len(out['removed']) - n_beds} run entries and {n_beds} beds "
          f"({_human(out['freed_bytes'])}); kept {out['kept_entries']} "
          f"({_human(out['kept_bytes'])})")
    if out["over_bytes"]:
        print(f"still {_human(out['over_bytes'])} over --max-size: those entries were used "
              f"within the last {runcache.GRACE_S / 3600:.0f} h")
    return 0


def _cmd_fingerprint(args: argparse.Namespace) -> int:
    import json

    from crashdem.realisation import fingerprint

    fp = fingerprint()
    if args.json:
        print(json.dumps(fp))
        return 0
    print(f"DEM realisation digest: {fp['digest']} (bed {fp['deposition_digest']})")
    print(f"cpu {fp['cpu']} ({fp['machine']}), python {fp['python']}, numpy {fp['numpy']} "
          f"(SIMD above baseline: {' '.join(fp['numpy_simd']) or 'none'}), scipy {fp['scipy']}, "
          f"numba {fp['numba']}, threads {fp['threads']}")
    print("two machines with the same digest give the same DEM runs, bit for bit")
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    from crashdem.scenario import schema_markdown

    print(schema_markdown())
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="crashdem", description=__doc__.splitlines()[0])
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="run a scenario (TOML) and write HDF5 + plots")
    r.add_argument("scenario")
    r.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scenario field")
    r.add_argument("--out", default=None, help="output directory (default: output.directory)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--resume", action="store_true", help="continue a killed run from its last checkpoint")
    r.add_argument("--no-plots", action="store_true")
    r.set_defaults(func=_cmd_run)

    i = sub.add_parser("info", help="print a result file's summary")
    i.add_argument("result")
    i.set_defaults(func=_cmd_info)

    pl = sub.add_parser("plot", help="plot a result's channels to PNG")
    pl.add_argument("result")
    pl.add_argument("--out", default=None)
    pl.add_argument("--channel", action="append")
    pl.set_defaults(func=_cmd_plot)

    e = sub.add_parser("export", help="export particle snapshots for ParaView")
    e.add_argument("result")
    e.add_argument("--format", choices=["vtu", "xdmf"], default="vtu")
    e.add_argument("--out", default=None)
    e.set_defaults(func=_cmd_export)

    from crashdem import ensemble

    sw = sub.add_parser("sweep", help="parameter sweep fanned out over Dask, one HDF5 per ensemble")
    ensemble.add_sweep_arguments(sw)
    sw.set_defaults(func=ensemble.sweep_command)

    ca = sub.add_parser("calibrate", help="fit scenario parameters to a recording channel on Dask")
    ensemble.add_calibrate_arguments(ca)
    ca.set_defaults(func=ensemble.calibrate_command)

    d = sub.add_parser("diagnose", help="locate a simulation-recording mismatch and name the missing physics")
    d.add_argument("--scenario", required=True)
    d.add_argument("--recording", required=True)
    d.add_argument("--channel", action="append")
    d.add_argument("--unit", action="append", metavar="NAME=UNIT",
                   help="unit of a CSV column whose header gives none (e.g. accel_z=g)")
    d.add_argument("--out", required=True)
    d.add_argument("--set", action="append", metavar="KEY=VALUE")
    d.add_argument("--full-confirm", type=int, default=None,
                   help="confirm the top hypotheses with this many full DEM runs at most "
                        "(default 3 with a full-simulation baseline: the recalibrated run and "
                        "the two best candidates; 0 = screening only; in parallel on Dask: a "
                        "LocalCluster, or --scheduler; --workers 0 runs them in this process)")
    d.add_argument("--full-search", choices=("auto", "full", "coarse", "off"), default="auto",
                   help="run each soil effect at levels of its main parameter in the full DEM "
                        "(its own terms, e.g. contact cohesion) before naming one: on the "
                        "scenario itself (full), on the scenario at 0.10 m grains (or its own, "
                        "when coarser) in a 2 m tank (or its own, when smaller) with the "
                        "leading levels confirmed at the scenario's resolution (coarse), "
                        "auto = coarse when the scenario is finer and one impact costs more "
                        "than in a bed of about 2,500 grains at 0.075 m, off = none")
    d.add_argument("--replicates", type=int, default=None, metavar="N",
                   help="run the baseline with N other packing seeds (scenario.seed + 1 ... + N) "
                        "on the simulator the search runs on; an effect must fit the recording "
                        "better than every one of them (the realisation floor; default 4 with "
                        "the full-model search, 0 = none; none when the search runs on an "
                        "imported bed, soil.packing_file, the recording's one bed)")
    d.add_argument("--level-beds", type=int, default=None, metavar="N",
                   help="run each search level of an effect that deposits its own bed (floor, "
                        "interface depth) on N beds: the baseline's packing and the first N - 1 "
                        "replicates', each taken against the baseline run of its bed, and "
                        "average the changes (default 5 when the search runs on the scenario "
                        "itself, 1 on the coarse search tier or on an imported bed; at most "
                        "1 + --replicates)")
    d.add_argument("--numerics-check", default=None, metavar="F[,F...]|off",
                   help="rerun a named soil effect's search levels with the grain radius times "
                        "each factor and widen its uncertainty to how far the value moves "
                        "(default 0.9,1.1; off = none, and on an imported bed)")
    d.add_argument("--grain-check", default=None, metavar="F[,F...]|off",
                   help="when a soil effect is named, make the whole confirmation again with the "
                        "grain radius times each factor (its own baseline, replicates and "
                        "search) and name the effect only if those name it too, see "
                        "--grain-check-agree (default off; e.g. 1.1,0.9)")
    d.add_argument("--grain-fit", default=None, metavar="F[,F...]|off",
                   help="run the baseline and its replicate packings with the grain radius "
                        "times each factor; when one grain size fits the recording decisively "
                        "better than the scenario's, make the whole confirmation at it "
                        "(default off; e.g. 0.8,1.25,1.5)")
    d.add_argument("--law-fit", default=None, metavar="K[,K...]|off",
                   help="run the baseline and its replicate packings on their own beds with the "
                        "other contact law (Hertz-Mindlin for a linear scenario, linear for a "
                        "Hertz-Mindlin one), and in the scenario's law, at each factor K on "
                        "the grains' modulus; when one fits the recording decisively better "
                        "than the scenario's law at its modulus, make the whole confirmation "
                        "in it (the other law only when it also beats the scenario's law at "
                        "its best modulus; default off; e.g. 2,4,8 for Hertz-Mindlin against a "
                        "linear law calibrated on the same test)")
    d.add_argument("--law-fit-stiffness", default="on", choices=("on", "off"),
                   help="with --law-fit, also rate the scenario's own law at the same factors "
                        "on the modulus (on, default): the other law is then taken only when "
                        "it also beats the scenario's law at its best modulus, otherwise a "
                        "decisive modulus of the scenario's law is taken as a stiffness "
                        "recalibration; off: the other law alone, against the scenario's law "
                        "at its modulus")
    d.add_argument("--grain-fit-tier", default=None, choices=("search", "tier", "full"),
                   help="where the grain fit runs when the search runs on the coarse tier: "
                        "search (default) on that tier; tier = on the scenario's own grains in "
                        "the coarse tier's container (when one impact there costs at most as "
                        "much as in a bed of about 5,000 grains); full = on the scenario itself "
                        "(5 full runs per grain size). Measured at the default resolution, "
                        "neither found a recording's grain size")
    d.add_argument("--grain-check-agree", default=None, choices=("all", "any"),
                   help="how many of the --grain-check factors must name the effect: all "
                        "(default) or any (at least one)")
    d.add_argument("--packing-cache", default=None, metavar="DIR|off",
                   help="deposit the beds of the baseline, search and confirmation runs in this "
                        "cache, shared by later diagnoses (default: $CRASHDEM_CACHE/packings or "
                        "~/.cache/crashdem/packings; beds are kept under the soil engine's code "
                        "fingerprint and found by their spec's hash, so the results are the same "
                        "as with fresh beds); off = in OUT only")
    d.add_argument("--run-cache", default=None, metavar="DIR|off",
                   help="keep every finished full run (baseline, replicates, search levels, "
                        "confirmations) in this cache and take a run from it instead of running "
                        "it again: diagnoses of one scenario share all but their confirmation "
                        "runs (default: $CRASHDEM_CACHE/runs or ~/.cache/crashdem/runs; runs "
                        "are kept under the code's fingerprint and found by the hash of what "
                        "decides their signals, so the results are those of a fresh run); off = "
                        "run everything")
    d.add_argument("--baseline", choices=("run", "result", "rom"), default="run",
                   help="baseline simulation: the scenario's full result, run now when missing "
                        "(run, default); the existing result only (result); the reduced-order "
                        "model only (rom, fast, no anchor)")
    ensemble.add_cluster_arguments(d, set_option=False)
    d.set_defaults(func=_cmd_diagnose)

    c = sub.add_parser("cache", help="show or prune the caches of finished runs and of "
                                     "deposited beds")
    c.add_argument("--root", default=None,
                   help="the crashdem cache directory (default: $CRASHDEM_CACHE, else "
                        "~/.cache/crashdem)")
    csub = c.add_subparsers(dest="cache_command", required=True)
    ci = csub.add_parser("info", help="entries and bytes per cache and per code version")
    ci.add_argument("--json", action="store_true")
    cp = csub.add_parser("prune", help="evict finished runs and deposited beds (runs/ and "
                                       "packings/); entries used in the last hour always stay")
    cp.add_argument("--max-size", default=None, metavar="SIZE",
                    help="evict the least recently used entries (other code versions first) "
                         "until the runs and beds together fit, e.g. 20G, 500M, 2GiB")
    cp.add_argument("--only", choices=("runs", "packings"), default=None,
                    help="prune only the finished runs or only the beds (default: both)")
    cp.add_argument("--stale", action="store_true",
                    help="evict every entry made by another version of the code")
    cp.add_argument("--older-than", type=float, default=None, metavar="DAYS",
                    help="evict entries not used for this many days")
    cp.add_argument("--dry-run", action="store_true", help="say what would go; remove nothing")
    c.set_defaults(func=_cmd_cache)

    f = sub.add_parser("fingerprint", help="digest of this machine's DEM realisation (a small "
                                           "deposition and impact, ~10 s): the same digest on "
                                           "two machines = the same runs bit for bit")
    f.add_argument("--json", action="store_true")
    f.set_defaults(func=_cmd_fingerprint)

    s = sub.add_parser("schema", help="print the scenario field reference (Markdown)")
    s.set_defaults(func=_cmd_schema)
    return p


def main(argv: list[str] | None = None) -> int:
    from crashdem.scenario import ScenarioError

    args = build_parser().parse_args(argv)
    level = "WARNING" if getattr(args, "quiet", False) else args.log_level
    logging.basicConfig(level=getattr(logging, level), format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except (ScenarioError, FileNotFoundError, ValueError) as exc:
        print(f"crashdem {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

#!/usr/bin/env python3
"""Times `poseboard eval` on a paper-sized evaluation built from the reference fixture.

The reference dataset (tests/fixtures/reference, 2 scenes, 28 targets) is copied COPIES times
under new scene ids (depth images, models and camera files are symbolic links, the small scene
JSON files are linked too), and a reference result file is replicated with its scene ids
remapped the same way. Every copy is evaluated exactly as the original, so every score of the
paper-sized set must equal the original's: the script checks that, then prints the wall time
and the peak memory of each protocol on all cores, and the VSD estimates per second. The set is
then prepared (`poseboard dataset prepare`, its time and size printed) and evaluated again
from its prepared form; those scores must be equal too, and the ratio of the times is printed.

bop24 (6D detection) runs on the same copies with the BOP'24 fixture's target images and its
`noisy` result file (tests/fixtures/bop24: random scores, so no two estimates tie and every
copy ranks like the original), and must give the original's average precisions.

    cargo build --release -p server
    python3 evaluator/benches/paper_sized.py [--copies 611] [--results noisemedium] [--threads N]

611 copies give 17,108 targets, the size of a BOP'19 core dataset's test set (the ECCV'18
paper's figures are for sets of this size). Uses only the Python standard library.

`--set large` is the second set: the reference objects cover about 2,600 pixels, real BOP
objects 5,000 to 25,000, and per-pixel work (rasterising, depth tests, the VSD comparison)
weighs as much as the per-target overhead. It is a synthetic dataset of distinct images
(`poseboard dataset synth --size 960x720`: the intrinsics scale with the size, so the objects
cover 2.25 times the pixels of the 640 x 480 demo, a median over 5,000 per instance, as YCB-V's
or T-LESS's do), with the demo result files of `poseboard dataset demo-results`: eccv18 scores
the `noisy` file (one estimate per instance), bop19 all three files together (three estimates
per instance, as a method proposing several hypotheses). Its scores are checked identical
between the unprepared and the prepared runs.

    python3 evaluator/benches/paper_sized.py --set large [--images 4450] [--threads N]
        [--workdir DIR]

4,450 images hold about 17,000 target instances. With `--workdir`, the dataset is made there
once and kept (making it takes minutes and is not what is measured); its prepared form is
made afresh on every run.
"""

import argparse
import csv
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FIXTURE = ROOT / "tests" / "fixtures" / "reference"
BOP24 = ROOT / "tests" / "fixtures" / "bop24"
BINARY = ROOT / "target" / "release" / "poseboard"
TOOLKIT_VSD_PER_S = 47.0


def build_dataset(out: Path, copies: int) -> dict:
    """Writes the replicated dataset to `out`; returns {new scene id: original scene id}."""
    src = FIXTURE / "dataset"
    out.mkdir(parents=True)
    for name in ["camera.json", "models", "models_eval"]:
        (out / name).symlink_to(src / name)
    scenes = sorted(int(p.name) for p in (src / "test").iterdir() if p.is_dir())
    mapping = {}
    (out / "test").mkdir()
    for c in range(copies):
        for s in scenes:
            new = c * len(scenes) + s
            mapping[new] = s
            d = out / "test" / f"{new:06d}"
            d.mkdir()
            for entry in (src / "test" / f"{s:06d}").iterdir():
                (d / entry.name).symlink_to(entry)
    targets = json.loads((src / "test_targets_bop19.json").read_text())
    by_original = {}
    for t in targets:
        by_original.setdefault(t["scene_id"], []).append(t)
    replicated = [
        dict(t, scene_id=new) for new, s in sorted(mapping.items()) for t in by_original.get(s, [])
    ]
    (out / "test_targets_bop19.json").write_text(json.dumps(replicated))
    images = json.loads((BOP24 / "test_targets_bop24.json").read_text())
    replicated = [
        dict(t, scene_id=new) for new, s in sorted(mapping.items()) for t in images
        if t["scene_id"] == s
    ]
    (out / "test_targets_bop24.json").write_text(json.dumps(replicated))
    return mapping


def replicate_results(src: Path, dst: Path, mapping: dict) -> int:
    """Writes `src` once per copy with remapped scene ids; returns the number of rows."""
    with src.open() as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    copies_of = {}
    for new, s in mapping.items():
        copies_of.setdefault(s, []).append(new)
    n = 0
    with dst.open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        for new_ids in zip(*[sorted(v) for _, v in sorted(copies_of.items())]):
            remap = dict(zip(sorted(copies_of), new_ids))
            for r in body:
                w.writerow([str(remap[int(r[0])])] + r[1:])
                n += 1
    return n


def evaluate(binary: Path, dataset: Path, results: Path, protocol: str, threads, out: Path,
             prepared: bool = False, extra=()):
    """Runs poseboard eval; returns (report, seconds, peak resident MB)."""
    cmd = [str(binary), "eval", "--dataset", str(dataset), "--results", str(results),
           "--protocol", protocol, "--out", str(out), *extra]
    if not prepared:
        cmd += ["--unprepared"]
    if threads:
        cmd += ["--threads", str(threads)]
    cmd = ["/usr/bin/time", "-v"] + cmd
    start = time.monotonic()
    run = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.monotonic() - start
    if run.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{run.stderr}")
    peak_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr).group(1))
    return json.loads(out.read_text()), seconds, peak_kb / 1024


# Scores that do not depend on how many copies there are (per-scene breakdowns do).
COMPARED = ["recall", "mean_obj_recall", "obj_recalls", "bop19_average_recall",
            "bop19_average_recall_vsd", "bop19_average_recall_mssd",
            "bop19_average_recall_mspd", "obj_average_recalls", "average_recalls",
            "per_error_recall_per_threshold"]
COMPARED_BOP24 = ["bop24_mAP", "bop24_mAP_mssd", "bop24_mAP_mssd_mm", "bop24_mAP_mspd"]


def average_precisions(report: dict) -> list:
    """bop24's per-object APs (the instance counts grow with the copies)."""
    return [(e["error"], [(o["obj_id"], o["AP"], o["ap_per_threshold"]) for o in e["objects"]])
            for e in report["errors"]]


def run(binary: Path, cmd: list) -> str:
    """Runs a poseboard command; returns its standard output."""
    done = subprocess.run([str(binary), *cmd], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"poseboard {' '.join(cmd)} failed:\n{done.stderr}")
    return done.stdout


def prepare(binary: Path, dataset: Path, threads) -> None:
    cmd = ["dataset", "prepare", str(dataset)]
    if threads:
        cmd += ["--threads", str(threads)]
    start = time.monotonic()
    out = run(binary, cmd)
    print(f"  prepared in {time.monotonic() - start:.2f} s: {out.strip()}")


def large_set(args, tmp: Path) -> None:
    """The second set: distinct images of BOP-sized objects (see the module doc)."""
    dataset = tmp / "synthL"
    per_scene = 50
    scenes = max(1, round(args.images / per_scene))
    made = "kept"
    if not (dataset / "test_targets_bop19.json").exists():
        start = time.monotonic()
        run(args.binary, ["dataset", "synth", str(dataset), "--size", "960x720", "--seed", "3",
                          "--scenes", str(scenes), "--images-per-scene", str(per_scene)])
        made = f"made in {time.monotonic() - start:.0f} s"
    shutil.rmtree(dataset / "poseboard_prepared", ignore_errors=True)
    scenes = sum(1 for _ in (dataset / "test").iterdir())
    run(args.binary, ["dataset", "demo-results", str(dataset), str(tmp / "demo")])
    styles = sorted((tmp / "demo").glob("*_synthL-test.csv"))
    pixels = sorted(i["px_count_all"] for d in (dataset / "test").iterdir()
                    for v in json.loads((d / "scene_gt_info.json").read_text()).values()
                    for i in v)
    targets = json.loads((dataset / "test_targets_bop19.json").read_text())
    instances = sum(t["inst_count"] for t in targets)
    print(f"large set: {scenes * per_scene} distinct images at 960 x 720 ({made}), "
          f"{instances} target instances, median {pixels[len(pixels) // 2]} px per instance "
          f"(the reference set's: 2,659), threads: {args.threads or os.cpu_count()}")
    by_style = {f.name.split("_")[0]: f for f in styles}
    noisy = by_style["demo-noisy"]
    # One file of three hypotheses per instance; an image's estimates must share one time.
    three = tmp / "three-hypotheses_synthL-test.csv"
    times, rows = {}, []
    for style in ["demo-precise", "demo-noisy", "demo-rough"]:
        with by_style[style].open() as f:
            body = list(csv.reader(f))
        header = body[0]
        for r in body[1:]:
            r[-1] = times.setdefault((r[0], r[1]), r[-1])
            rows.append(r)
    with three.open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        w.writerows(rows)
    prepare(args.binary, dataset, args.threads)
    for protocol, results in [("eccv18", noisy), ("bop19", three)]:
        rows = len(results.read_text().splitlines()) - 1
        reports, times = {}, {}
        for prepared in [False, True]:
            report, seconds, mb = evaluate(args.binary, dataset, results, protocol, args.threads,
                                           tmp / f"large_{protocol}.json", prepared)
            reports[prepared], times[prepared] = report, seconds
            evaluated = report["estimates_evaluated"]
            how = "prepared" if prepared else "from the dataset"
            print(f"  {protocol:<7} {how:<16} {seconds:6.2f} s  peak {mb:6.0f} MB  "
                  f"{evaluated / seconds:8.0f} estimates/s "
                  f"({evaluated / seconds / TOOLKIT_VSD_PER_S:.0f}x bop_toolkit's 47/s)  "
                  f"{rows} rows, {evaluated} evaluated")
        if reports[False] != reports[True]:
            sys.exit(f"{protocol}: the prepared run's scores differ from the unprepared run's")
        print(f"  {protocol:<7} ratio {times[False] / times[True]:.2f}, scores identical")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=["reference", "large"], default="reference")
    ap.add_argument("--images", type=int, default=4450, help="--set large: distinct images")
    ap.add_argument("--workdir", type=Path, help="--set large: where the dataset is kept")
    ap.add_argument("--copies", type=int, default=611)
    ap.add_argument("--results", default="noisemedium")
    ap.add_argument("--threads", type=int, default=None, help="default: every core")
    ap.add_argument("--binary", type=Path, default=BINARY,
                    help="poseboard to time (e.g. an older build, for a ratio)")
    args = ap.parse_args()
    if not args.binary.exists():
        sys.exit(f"{args.binary} is missing: cargo build --release -p server")

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.set == "large":
            if args.workdir:
                args.workdir.mkdir(parents=True, exist_ok=True)
            large_set(args, args.workdir or tmp)
            return
        mapping = build_dataset(tmp / "big" / "synthA", args.copies)
        name = f"{args.results}_synthA-test.csv"
        rows = replicate_results(FIXTURE / "results" / name, tmp / "big" / name, mapping)
        targets = len(json.loads((tmp / "big" / "synthA" / "test_targets_bop19.json").read_text()))
        print(f"paper-sized set: {len(mapping)} scenes, {targets} targets, {rows} estimates "
              f"({args.copies} copies of the reference), threads: {args.threads or os.cpu_count()}")
        prepare(args.binary, tmp / "big" / "synthA", args.threads)
        unprepared_seconds = {}
        for protocol in ["eccv18", "bop19"]:
            small, _, _ = evaluate(args.binary, FIXTURE / "dataset", FIXTURE / "results" / name, protocol,
                                   args.threads, tmp / f"small_{protocol}.json")
            times = {}
            for prepared in [False, True]:
                big, seconds, mb = evaluate(args.binary, tmp / "big" / "synthA", tmp / "big" / name,
                                            protocol, args.threads, tmp / f"big_{protocol}.json",
                                            prepared)
                differing = [k for k in COMPARED if small.get(k) != big.get(k)]
                if differing:
                    sys.exit(f"{protocol}: scores differ from the reference file's: {differing}")
                evaluated = big["estimates_evaluated"]
                times[prepared] = seconds
                how = "prepared" if prepared else "from the dataset"
                print(f"  {protocol:<7} {how:<16} {seconds:6.2f} s  peak {mb:6.0f} MB  "
                      f"{evaluated / seconds:8.0f} estimates/s "
                      f"({evaluated / seconds / TOOLKIT_VSD_PER_S:.0f}x bop_toolkit's 47/s)  "
                      f"scores equal the reference file's")
            print(f"  {protocol:<7} ratio {times[False] / times[True]:.2f}")
            unprepared_seconds[protocol] = times[False]

        name = "noisy_synthA-test.csv"
        rows = replicate_results(BOP24 / "results" / name, tmp / "big" / name, mapping)
        small, _, _ = evaluate(args.binary, FIXTURE / "dataset", BOP24 / "results" / name, "bop24",
                               args.threads, tmp / "small_bop24.json", prepared=True,
                               extra=["--targets-file", str(BOP24 / "test_targets_bop24.json")])
        big, seconds, mb = evaluate(args.binary, tmp / "big" / "synthA", tmp / "big" / name,
                                    "bop24", args.threads, tmp / "big_bop24.json", prepared=True)
        differing = [k for k in COMPARED_BOP24 if small[k] != big[k]]
        if differing or average_precisions(small) != average_precisions(big):
            sys.exit(f"bop24: scores differ from the fixture file's: {differing or 'per object'}")
        evaluated = big["estimates_evaluated"]
        print(f"  bop24   {seconds:6.2f} s  peak {mb:6.0f} MB  {evaluated / seconds:8.0f} "
              f"estimates/s ({rows} estimates, {big['target_images']} target images)  "
              f"{seconds / unprepared_seconds['bop19']:.2f}x bop19's time (unprepared)  scores equal the fixture file's")


if __name__ == "__main__":
    main()

#!/usr/bin/env bash
# Speed of two commits side by side in one run: builds `photon` at each (in temporary worktrees),
# then times the same runs with both binaries in interleaved rounds, so a shared machine's drift
# hits both alike. Reports each configuration's median photons/s per build and the median over
# rounds of the per-round ratio B/A (above 1: B is faster).
# Usage: bash bench/compare_builds.sh <commit A> <commit B> [rounds, default 7]
set -euo pipefail
cd "$(dirname "$0")/.."
a=$1; b=$2; rounds=${3:-7}
work=$(mktemp -d)
trap 'git worktree remove --force "$work/a" 2>/dev/null || true; git worktree remove --force "$work/b" 2>/dev/null || true; rm -rf "$work"' EXIT
for side in a b; do
  rev=${!side}
  git worktree add --quiet --detach "$work/$side" "$rev"
  CARGO_TARGET_DIR="$work/target-$side" cargo build --release --quiet --manifest-path "$work/$side/Cargo.toml"
  cp "$work/target-$side/release/photon" "$work/photon-$side"
done
python3 - "$work" "$rounds" "$a" "$b" <<'PY'
import json, subprocess, sys, statistics
work, rounds, name_a, name_b = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
# scene, photons, flags: the estimator is fixed so no pilot runs (its time is not the loop's).
configs = [
    ("scenes/cornell_box.toml", 524_288, ["--no-image", "--estimator", "expected"], "cornell, no image"),
    ("scenes/cornell_box.toml", 524_288, ["--estimator", "expected"], "cornell, light-traced image"),
    ("scenes/cornell_box.toml", 131_072, ["--integrator", "path", "--estimator", "expected"], "cornell, path tracer"),
    ("scenes/cornell_box.toml", 65_536, ["--integrator", "bdpt", "--estimator", "expected"], "cornell, BDPT"),
    ("scenes/furnace.toml", 131_072, ["--estimator", "analog"], "furnace 0.9, analog"),
    ("scenes/glass.toml", 262_144, ["--estimator", "expected"], "glass, light-traced image"),
]
rate = {(c[3], s): [] for c in configs for s in "ab"}
ratio = {c[3]: [] for c in configs}
for r in range(rounds):
    for scene, photons, flags, label in configs:
        got = {}
        for side in ("ab" if r % 2 == 0 else "ba"):
            out = f"{work}/out-{side}"
            subprocess.run([f"{work}/photon-{side}", "run", scene, "--photons", str(photons), "--seed", "1",
                            "--threads", "2", "--out", out, "--quiet", *flags], check=True)
            run = json.load(open(f"{out}/run.json"))
            got[side] = photons / run["counters"]["trace_seconds"] * run["threads"]
            rate[(label, side)].append(got[side])
        ratio[label].append(got["b"] / got["a"])
print(f"| configuration | {name_a} photons/s | {name_b} photons/s | ratio B/A (median of {rounds} rounds) | spread |")
print("|---|---:|---:|---:|---:|")
for *_, label in configs:
    ra = statistics.median(rate[(label, 'a')]); rb = statistics.median(rate[(label, 'b')])
    rs = sorted(ratio[label])
    print(f"| {label} | {ra:,.0f} | {rb:,.0f} | {statistics.median(rs):.3f} | {rs[0]:.3f}–{rs[-1]:.3f} |")
PY

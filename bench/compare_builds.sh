#!/usr/bin/env bash
# Speed of several commits side by side in one run: builds `photon` at each (in temporary
# worktrees), then times the same runs with every binary in interleaved rounds (the order
# rotating each round), so a shared machine's drift hits them all alike. Reports each
# configuration's median photons/s per build and, for each later build, the median over rounds
# of the per-round ratio to the first (above 1: faster than the first).
# Usage: ROUNDS=7 [CONFIGS=BDPT,glass] bash bench/compare_builds.sh <commit> <commit> [<commit> ...]
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${ROUNDS:-7}
work=$(mktemp -d)
trap 'for k in $(seq 0 $(($# - 1))); do git worktree remove --force "$work/src$k" 2>/dev/null || true; done; rm -rf "$work"' EXIT
k=0
for rev in "$@"; do
  git worktree add --quiet --detach "$work/src$k" "$rev"
  CARGO_TARGET_DIR="$work/target" cargo build --release --quiet --manifest-path "$work/src$k/Cargo.toml"
  cp "$work/target/release/photon" "$work/photon-$k"
  k=$((k + 1))
done
python3 - "$work" "$rounds" "$@" <<'PY'
import json, os, subprocess, sys, statistics
work, rounds, names = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
builds = list(range(len(names)))
# scene, photons, flags: the estimator is fixed so no pilot runs (its time is not the loop's).
configs = [
    ("scenes/cornell_box.toml", 524_288, ["--no-image", "--estimator", "expected"], "cornell, no image"),
    ("scenes/cornell_box.toml", 524_288, ["--estimator", "expected"], "cornell, light-traced image"),
    ("scenes/cornell_box.toml", 131_072, ["--integrator", "path", "--estimator", "expected"], "cornell, path tracer"),
    ("scenes/cornell_box.toml", 65_536, ["--integrator", "bdpt", "--estimator", "expected"], "cornell, BDPT"),
    ("scenes/furnace.toml", 131_072, ["--estimator", "analog"], "furnace 0.9, analog"),
    ("scenes/glass.toml", 262_144, ["--estimator", "expected"], "glass, light-traced image"),
]
# CONFIGS="BDPT,glass" keeps the configurations whose label contains one of the words.
only = [w for w in os.environ.get("CONFIGS", "").split(",") if w]
if only:
    configs = [c for c in configs if any(w in c[3] for w in only)]
rate = {(c[3], b): [] for c in configs for b in builds}
ratio = {(c[3], b): [] for c in configs for b in builds[1:]}
for r in range(rounds):
    for scene, photons, flags, label in configs:
        got = {}
        for b in builds[r % len(builds):] + builds[:r % len(builds)]:
            out = f"{work}/out-{b}"
            subprocess.run([f"{work}/photon-{b}", "run", scene, "--photons", str(photons), "--seed", "1",
                            "--threads", "2", "--out", out, "--quiet", *flags], check=True)
            run = json.load(open(f"{out}/run.json"))
            got[b] = photons / run["counters"]["trace_seconds"] * run["threads"]
            rate[(label, b)].append(got[b])
        for b in builds[1:]:
            ratio[(label, b)].append(got[b] / got[0])
head = " | ".join(f"{n} photons/s" for n in names)
ratios = " | ".join(f"{n} / {names[0]} (median, range)" for n in names[1:])
print(f"| configuration | {head} | {ratios} |")
print("|---|" + "---:|" * (len(names) + len(names) - 1))
for *_, label in configs:
    cells = [f"{statistics.median(rate[(label, b)]):,.0f}" for b in builds]
    for b in builds[1:]:
        rs = sorted(ratio[(label, b)])
        cells.append(f"{statistics.median(rs):.3f} ({rs[0]:.3f}–{rs[-1]:.3f})")
    print(f"| {label} | " + " | ".join(cells) + " |")
PY

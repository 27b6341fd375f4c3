#!/usr/bin/env bash
# Figure of merit FOM = 1/(relative error² · seconds) of each variance-reduction choice, measured
# side by side in one run on the same machine. Usage: bash bench/fom.sh [photons-scale]
# Writes bench/fom.md. Each configuration runs 3 times, in 3 interleaved rounds; the table shows
# the median FOM.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
scale=${1:-1}
out=$(mktemp -d)
python3 - "$out" "$scale" <<'PY'
import json, subprocess, sys, statistics
out, scale = sys.argv[1], float(sys.argv[2])
runs = [
    # scene, photons, label, flags
    ("scenes/cornell_box.toml", 500_000, "analog", ["--estimator", "analog", "--no-hero"]),
    ("scenes/cornell_box.toml", 500_000, "expected", ["--estimator", "expected", "--no-hero"]),
    ("scenes/cornell_box.toml", 500_000, "analog + stratified", ["--estimator", "analog", "--stratified", "--no-hero"]),
    ("scenes/cornell_box.toml", 500_000, "expected + stratified", ["--estimator", "expected", "--stratified", "--no-hero"]),
    ("scenes/cornell_box.toml", 500_000, "analog + hero", ["--estimator", "analog"]),
    ("scenes/cornell_box.toml", 500_000, "expected + hero", ["--estimator", "expected"]),
    ("scenes/cornell_box.toml", 500_000, "expected + stratified + hero", ["--estimator", "expected", "--stratified"]),
    ("scenes/cornell_box.toml", 500_000, "auto + hero (default; pilot time included)", []),
    ("scenes/furnace.toml", 200_000, "analog", ["--estimator", "analog"]),
    ("scenes/furnace.toml", 200_000, "expected", ["--estimator", "expected"]),
    ("scenes/furnace.toml", 200_000, "analog + stratified", ["--estimator", "analog", "--stratified"]),
    ("scenes/furnace.toml", 200_000, "expected + stratified", ["--estimator", "expected", "--stratified"]),
    ("scenes/furnace.toml", 200_000, "auto (default; pilot time included)", []),
]
# Rounds outer, configurations inner: each round runs every configuration once, so a change in
# the machine's load falls on all of them alike.
foms = [{"tally": [], "image": []} for _ in runs]
for rep in range(3):
    for k, (scene, photons, label, flags) in enumerate(runs):
        d = f"{out}/{k}-{rep}"
        subprocess.run(["target/release/photon", "run", scene, "--out", d, "--quiet", "--threads", "2",
                        "--photons", str(int(photons * scale)), "--seed", str(rep + 1)] + flags, check=True)
        run = json.load(open(f"{d}/run.json"))
        flux = json.load(open(f"{d}/flux.json"))
        t = run["wall_seconds"]
        # Tally FOM: the worst (smallest) over surfaces with a non-zero result.
        rels = [s["rel_error"] for s in flux["surfaces"] if s["rel_error"] > 0]
        foms[k]["tally"].append(1 / (max(rels) ** 2 * t))
        if run.get("image_pixel_rel_error"):
            foms[k]["image"].append(1 / (run["image_pixel_rel_error"] ** 2 * t))
rows = []
for (scene, photons, label, flags), f in zip(runs, foms):
    rows.append((scene.split("/")[-1].removesuffix(".toml"), label, int(photons * scale),
                 statistics.median(f["tally"]), statistics.median(f["image"]) if f["image"] else None))
lines = ["| scene | choice | photons | worst-tally FOM | image FOM |", "| --- | --- | ---: | ---: | ---: |"]
for scene, label, photons, ft, fi in rows:
    lines.append(f"| {scene} | {label} | {photons} | {ft:.3g} | {'-' if fi is None else f'{fi:.3g}'} |")
text = "\n".join(lines) + "\n"
print(text)
open("bench/fom.md", "w").write(text)
PY

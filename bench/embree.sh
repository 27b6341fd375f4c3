#!/usr/bin/env bash
# photon side by side with this machine's ray-casting limit (issue #23): Intel Embree 3's
# raybench and the minimal Embree photon tracer from ../shared/bench/embree/, and photon's own
# figures for the same work, in interleaved rounds (the order rotates each round), with the
# median and [min, max] of each figure and of each per-round ratio.
#
#   bash bench/embree.sh                  # 5 rounds, Cornell box and the 1.3 M-triangle sphere
#   ROUNDS=9 SPHERE=0 bash bench/embree.sh
#   LEVEL=5 bash bench/embree.sh          # the sphere subdivided 5 times (20 492 triangles), not 8
#
# Not part of CI. Installs libembree-dev (Debian) when it is missing and we are root. The
# figures are CPU time per ray or per photon on one thread, which preemption by other machines'
# work does not touch (wall time would).
#
# mini_ptracer.cpp's --brute path is AVX-512; on a CPU without it the file does not compile
# with -march=native, so a copy is built with that one function marked
# __attribute__((target("avx512f"))) (the path is never taken here; the original is unchanged).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SRC=${EMBREE_BENCH:-$ROOT/../shared/bench/embree}
WORK=${WORK:-/tmp/photon-embree-bench}
ROUNDS=${ROUNDS:-5}
SPHERE=${SPHERE:-1}
RAYS_M=${RAYS_M:-2}          # millions of rays per raybench case
PHOTONS=${PHOTONS:-2000000}  # photons per whole-loop run
LEVEL=${LEVEL:-8}            # the sphere's subdivision level (8: 1 310 732 triangles in all)
case $LEVEL in [0-9] | 10) ;; *) echo "bench/embree.sh: LEVEL must be 0-10" >&2; exit 2 ;; esac
mkdir -p "$WORK"

if ! [ -e /usr/include/embree3/rtcore.h ] || ! [ -x /usr/bin/time ]; then
  if [ "$(id -u)" = 0 ]; then
    apt-get install -y libembree-dev g++ time >/dev/null
  else
    echo "bench/embree.sh: needs libembree-dev and time (apt-get install -y libembree-dev time)" >&2
    exit 2
  fi
fi
# Copies of the reference programs with the sphere's level set to LEVEL (the originals build 8).
sed "s/icosphere(8, {278, 160.5, 280}, 160)/icosphere($LEVEL, {278, 160.5, 280}, 160)/" "$SRC/raybench.cpp" \
  > "$WORK/raybench.cpp"
grep -q "icosphere($LEVEL, {278" "$WORK/raybench.cpp" || { echo "raybench level rewrite failed" >&2; exit 1; }
g++ -O3 -march=native -std=c++17 "$WORK/raybench.cpp" -o "$WORK/raybench" -lembree3 -lpthread
awk '/^static inline int bf_avx512/{print "__attribute__((target(\"avx512f\")))"}{print}' "$SRC/mini_ptracer.cpp" |
  sed "s/icosphere(t, BLOCK1, 8, /icosphere(t, BLOCK1, $LEVEL, /" > "$WORK/mini_ptracer.cpp"
grep -q "icosphere(t, BLOCK1, $LEVEL, " "$WORK/mini_ptracer.cpp" || { echo "mini_ptracer level rewrite failed" >&2; exit 1; }
g++ -O3 -march=native -std=c++17 "$WORK/mini_ptracer.cpp" -o "$WORK/mini_ptracer" -lembree3 -lpthread
cargo build --release --quiet --bin photon --example raybench
PHOTON=$ROOT/target/release/photon
RAYBENCH=$ROOT/target/release/examples/raybench

# The grey Cornell box of the throughput benchmark (each measured reflectance replaced by its
# mean under the light's spectrum), with absolute paths so it can live in $WORK.
sed -e "s#file = \"#file = \"$ROOT/scenes/#" \
    -e 's#{ file = "[^"]*cornell_white.csv" }#0.7355#' \
    -e 's#{ file = "[^"]*cornell_red.csv" }#0.3446#' \
    -e 's#{ file = "[^"]*cornell_green.csv" }#0.2045#' scenes/cornell_box.toml > "$WORK/cornell_grey.toml"
grep -q "reflectance = 0.7355" "$WORK/cornell_grey.toml" || { echo "grey box rewrite failed" >&2; exit 1; }
# The grey box with both blocks replaced by the 1.3 M-triangle sphere, as mini_ptracer's `sphere`
# (and the throughput benchmark's million_triangles) has it.
python3 - "$WORK/cornell_grey.toml" "$WORK/million_grey.toml" "$LEVEL" <<'PY'
import re, sys
t = open(sys.argv[1]).read()
sphere = 'shape = { type = "sphere", center = [278, 160.5, 280], radius = 160, subdivisions = %s }' % sys.argv[3]
t, n1 = re.subn(r'name = "short_block"\nmaterial = "white"\nshape = \{ type = "mesh", file = "[^"]*" \}',
                'name = "sphere"\nmaterial = "white"\n' + sphere, t)
t, n2 = re.subn(r'\[\[surfaces\]\]\nname = "tall_block"\nmaterial = "white"\nshape = \{[^\n]*\}\n\n', "", t)
assert n1 == 1 and n2 == 1, "sphere box rewrite failed"
open(sys.argv[2], "w").write(t)
PY

LOG=$WORK/figures.txt
: > "$LOG"
# CPU ns per photon of one `photon run` (user + system time of the whole process).
photon_run() {  # label, scene, extra args...
  local label=$1 scene=$2
  shift 2
  /usr/bin/time -f "%U %S" -o "$WORK/time.txt" "$PHOTON" run "$scene" --out "$WORK/out" --photons "$PHOTONS" \
    --threads 1 --estimator expected "$@" > /dev/null
  python3 -c "import sys; u,s=map(float,open(sys.argv[1]).read().split()[-2:]); print(sys.argv[2], (u+s)*1e9/$PHOTONS)" \
    "$WORK/time.txt" "$label" >> "$LOG"
}
photon_trace() {  # label, scene, extra args...: tracing time only (run.json's wall time on one
  # worker thread), as mini_ptracer times its trace: loading the 1.3 M-triangle sphere and
  # building its tree cost photon ~1.5 s of process time, which is not what is compared.
  local label=$1 scene=$2
  shift 2
  "$PHOTON" run "$scene" --out "$WORK/out" --photons "$PHOTONS" --threads 1 --estimator expected "$@" > /dev/null
  python3 -c "import json, sys; print(sys.argv[2], json.load(open(sys.argv[1]))['wall_seconds'] * 1e9 / $PHOTONS)" \
    "$WORK/out/run.json" "$label" >> "$LOG"
}
embree_rays() {  # scene
  "$WORK/raybench" "$1" "$RAYS_M" 1 "$ROOT/scenes/meshes" | awk -v s="$1" '
    /^embree default\(medium\) rtcIntersect1 +1 / {print "embree_closest_" s, $(NF-1)}
    /^embree default\(medium\) rtcOccluded1 \(shadow\) +1 / {print "embree_shadow_" s, $(NF-1)}
    /^embree robust\+high rtcIntersect1 +1 / {print "embree_robust_closest_" s, $(NF-1)}
    /^brute force AVX2 8-wide closest +1 / {print "brute_avx2_closest_" s, $(NF-1)}' >> "$LOG"
}
photon_rays() {  # scene
  LEVEL=$LEVEL "$RAYBENCH" "$1" "$RAYS_M" 1 | awk -v s="$1" '
    /^photon intersect \(/ {print "photon_closest_" s, $5}
    /^photon intersect_many/ {print "photon_closest_many_" s, $5}
    /^grey loop/ {for (i = 1; i < NF; i++) if ($i == "ns/photon") v = $(i + 1)}
    /^grey loop, 1 photon at a time/ {print "minimal_loop_one_" s, v}
    /^grey loop, [0-9]+ photons in flight/ {print "minimal_loop_flight_" s, v}
    /^photon unoccluded/ {print "photon_shadow_" s, $5}' >> "$LOG"
}
mini() {
  "$WORK/mini_ptracer" cornell 1 1 | awk '
    /^no-image +1 / {print "mini_no_image", $7}
    /^image +1 / {print "mini_image", $7}' >> "$LOG"
}
mini_sphere() {
  "$WORK/mini_ptracer" sphere 1 1 | awk '/^no-image +1 / {print "mini_sphere_no_image", $7}' >> "$LOG"
}
jobs=(mini "photon_run photon_grey_no_image $WORK/cornell_grey.toml --no-image"
      "photon_run photon_spectral_image scenes/cornell_box.toml" "embree_rays cornell" "photon_rays cornell")
if [ "$SPHERE" = 1 ]; then
  jobs+=("embree_rays sphere" "photon_rays sphere" mini_sphere
        "photon_trace photon_trace_grey_cornell $WORK/cornell_grey.toml --no-image"
        "photon_trace photon_trace_grey_million $WORK/million_grey.toml --no-image")
fi
for ((r = 0; r < ROUNDS; r++)); do
  echo "round $((r + 1)) of $ROUNDS" >&2
  n=${#jobs[@]}
  for ((k = 0; k < n; k++)); do
    job=${jobs[$(((k + r) % n))]}
    $job
    echo "@round $r" >> "$LOG"
  done
done

python3 - "$LOG" <<'EOF'
import sys, statistics
cur = {}
# Each job's lines are followed by "@round r"; collect figures per round.
by_round = {}
for line in open(sys.argv[1]):
    parts = line.split()
    if parts[0] == "@round":
        by_round.setdefault(int(parts[1]), {}).update(cur)
        cur = {}
    else:
        cur[parts[0]] = float(parts[1])
names = sorted({k for r in by_round.values() for k in r})
def stat(xs):
    return f"{statistics.median(xs):8.1f} [{min(xs):.1f}, {max(xs):.1f}]"
print(f"\n{len(by_round)} rounds, interleaved (order rotating); CPU ns per ray or per photon, 1 thread: median [min, max]")
for k in names:
    xs = [r[k] for r in by_round.values() if k in r]
    print(f"  {k:32s} {stat(xs)}")
def ratio(label, a, b, target):
    xs = [r[a] / r[b] for r in by_round.values() if a in r and b in r]
    if xs:
        print(f"  {label:58s} {statistics.median(xs):5.2f}x [{min(xs):.2f}, {max(xs):.2f}]   target {target}")
print("\nratios (median of per-round ratios [min, max])")
ratio("ray cast, Cornell: photon / Embree (closest hit)", "photon_closest_cornell", "embree_closest_cornell", "<= 1.2")
ratio("ray cast, Cornell: photon / Embree (shadow ray)", "photon_shadow_cornell", "embree_shadow_cornell", "<= 1.2")
ratio("ray cast, Cornell: photon / Embree robust (closest hit)", "photon_closest_cornell", "embree_robust_closest_cornell", "")
ratio("ray cast, sphere: photon / Embree (closest hit)", "photon_closest_sphere", "embree_closest_sphere", "<= 1.2")
ratio("ray cast, sphere: photon / Embree (shadow ray)", "photon_shadow_sphere", "embree_shadow_sphere", "<= 1.2")
ratio("ray cast, sphere: photon, 32 rays in turns / Embree (closest)", "photon_closest_many_sphere", "embree_closest_sphere", "")
ratio("raybench's minimal grey loop, Cornell: 32 in flight / 1 at a time", "minimal_loop_flight_cornell", "minimal_loop_one_cornell", "")
ratio("raybench's minimal grey loop, sphere: 32 in flight / 1 at a time", "minimal_loop_flight_sphere", "minimal_loop_one_sphere", "")
ratio("raybench's minimal grey loop: sphere / Cornell, 1 at a time", "minimal_loop_one_sphere", "minimal_loop_one_cornell", "")
ratio("raybench's minimal grey loop: sphere / Cornell, 32 in flight", "minimal_loop_flight_sphere", "minimal_loop_flight_cornell", "")
ratio("whole loop, grey box --no-image: photon / mini tracer", "photon_grey_no_image", "mini_no_image", "<= 1.25")
ratio("spectral box with image: photon / mini tracer with image", "photon_spectral_image", "mini_image", "")
ratio("whole loop, sphere box --no-image (tracing): photon / mini", "photon_trace_grey_million", "mini_sphere_no_image", "")
ratio("sphere / Cornell box per photon (tracing): photon", "photon_trace_grey_million", "photon_trace_grey_cornell", "<= 1.5")
ratio("sphere / Cornell box per photon: mini tracer (Embree)", "mini_sphere_no_image", "mini_no_image", "")
xs = [r["photon_spectral_image"] for r in by_round.values() if "photon_spectral_image" in r]
if xs:
    print(f"  {'spectral box with image, photon CPU ns per photon':58s} {statistics.median(xs):7.0f}   target <= 1100")
EOF

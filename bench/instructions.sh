#!/usr/bin/env bash
# Instructions a photon, counted by Valgrind's cachegrind: a figure that shared, noisy hosts do not
# move (CPU time there spreads by 10-30 % between runs of one binary). The photon loop runs at
# ~2.8 instructions a cycle on this project's hosts, so at equal work fewer instructions is
# nearly proportionally less time; confirm a change's time with bench/embree.sh all the same.
#
#   bash bench/instructions.sh                       # target/release/photon
#   bash bench/instructions.sh OLD_BINARY NEW_BINARY # side by side, with the ratio
#
# Each binary runs the grey Cornell box of bench/embree.sh (`--no-image --estimator expected`,
# 1 thread) and the spectral box with its image, at two photon counts; the difference of the two
# counts over the difference of the photons leaves out loading, building and writing. Not part of
# CI. Installs valgrind (Debian) when it is missing and we are root.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
WORK=${WORK:-/tmp/photon-instructions}
FEW=${FEW:-10000}
MANY=${MANY:-100000}
mkdir -p "$WORK"
if ! command -v valgrind > /dev/null; then
  if [ "$(id -u)" = 0 ]; then
    apt-get install -y valgrind > /dev/null
  else
    echo "bench/instructions.sh: needs valgrind (apt-get install -y valgrind)" >&2
    exit 2
  fi
fi
if [ $# = 0 ]; then
  cargo build --release --quiet --bin photon
  set -- "$ROOT/target/release/photon"
fi
for b in "$@"; do
  [ -x "$b" ] || { echo "bench/instructions.sh: $b is not an executable" >&2; exit 2; }
done
# The grey box, as bench/embree.sh writes it.
sed -e "s#file = \"#file = \"$ROOT/scenes/#" \
    -e 's#{ file = "[^"]*cornell_white.csv" }#0.7355#' \
    -e 's#{ file = "[^"]*cornell_red.csv" }#0.3446#' \
    -e 's#{ file = "[^"]*cornell_green.csv" }#0.2045#' scenes/cornell_box.toml > "$WORK/cornell_grey.toml"
grep -q "reflectance = 0.7355" "$WORK/cornell_grey.toml" || { echo "grey box rewrite failed" >&2; exit 1; }

count() {  # binary scene photons extra...: instructions of the whole process
  local bin=$1 scene=$2 photons=$3
  shift 3
  valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null "$bin" run "$scene" \
    --out "$WORK/out" --photons "$photons" --threads 1 --estimator expected --quiet "$@" 2>&1 |
    awk '/I +refs:/ {gsub(",", "", $NF); print $NF}'
}
per_photon() {  # binary scene extra...
  local bin=$1 scene=$2
  shift 2
  local few many
  few=$(count "$bin" "$scene" "$FEW" "$@")
  many=$(count "$bin" "$scene" "$MANY" "$@")
  python3 -c "print(round(($many - $few) / ($MANY - $FEW)))"
}
declare -A first
for b in "$@"; do
  grey=$(per_photon "$b" "$WORK/cornell_grey.toml" --no-image)
  spectral=$(per_photon "$b" "$ROOT/scenes/cornell_box.toml")
  if [ -z "${first[grey]:-}" ]; then
    first[grey]=$grey
    first[spectral]=$spectral
  fi
  python3 -c "
g, s, g0, s0 = $grey, $spectral, ${first[grey]}, ${first[spectral]}
print(f'{\"$b\"}: grey box {g} instructions a photon ({g / g0:.3f}x the first), spectral image {s} ({s / s0:.3f}x)')"
done

#!/usr/bin/env bash
# photon vs Mitsuba 3's particle tracer (`ptracer`) on the measured Cornell box.
#
#   bash bench/mitsuba/run.sh [compare.py options, e.g. --spp 8 --ref-photons 40000000]
#   bash bench/mitsuba/run.sh --scene glossy [glossy.py options, e.g. --runs 16 --spp 8]
#   bash bench/mitsuba/run.sh --scene glossy --mitsuba-conventions
#
# Makes bench/mitsuba/.venv (Mitsuba from PyPI, CPU variants), builds photon in release mode, then
# renders the same scene with both and prints the table it also writes to bench/mitsuba/results.md.
# Images and run outputs go to bench/mitsuba/out/. Not part of `cargo test` or CI.
#
# --scene cornell (the default) is that speed and error benchmark (compare.py). --scene glossy
# runs glossy.py instead: scenes/cornell_glossy.toml (rough aluminium, frosted glass, a rough
# plastic back wall) with both renderers at equal light paths, compared tile by tile in units of
# the combined standard error; table in bench/mitsuba/results_glossy.md, images in
# bench/mitsuba/out/glossy/ (about 6 minutes on 2 cores with the defaults). With
# --mitsuba-conventions photon is built with the `mitsuba-conventions` feature (separable Smith
# G, Mitsuba's rough-coat tables) into target/mitsuba-conventions, so that both renderers
# evaluate the same BSDFs: table in bench/mitsuba/results_glossy_mitsuba_conventions.md.
#
# Mitsuba's llvm_ad_* variants need a libLLVM that can compile Dr.Jit's kernels (LLVM 14 and 15
# abort with "Cannot select: fmaximum"; 19 works): on Debian 12, `apt-get install libllvm19`.
# Without one the benchmark runs the scalar_spectral variant only.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
VENV="$HERE/.venv"
MITSUBA_VERSION=3.9.1   # drjit 1.5.0 comes with it
NUMPY_VERSION=2.4.6

SCRIPT=compare.py
case "${1:-}" in
    --scene|--scene=*)
        if [[ "$1" == --scene ]]; then scene="${2:-}"; shift 2 || shift; else scene="${1#--scene=}"; shift; fi
        case "$scene" in
            cornell) SCRIPT=compare.py ;;
            glossy) SCRIPT=glossy.py ;;
            *) echo "run.sh: --scene must be cornell or glossy, not '$scene'" >&2; exit 2 ;;
        esac ;;
esac

CONVENTIONS=photon
rest=()
for a in "$@"; do
    if [[ "$a" == --mitsuba-conventions ]]; then CONVENTIONS=mitsuba; else rest+=("$a"); fi
done
set -- "${rest[@]+"${rest[@]}"}"
if [[ "$CONVENTIONS" == mitsuba && "$SCRIPT" != glossy.py ]]; then
    echo "run.sh: --mitsuba-conventions goes with --scene glossy" >&2
    exit 2
fi

if [[ ! -x "$VENV/bin/python" ]]; then
    python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
    "mitsuba==$MITSUBA_VERSION" "numpy==$NUMPY_VERSION"

(cd "$ROOT" && cargo build --release --quiet)
EXTRA=()
if [[ "$CONVENTIONS" == mitsuba ]]; then
    (cd "$ROOT" && CARGO_TARGET_DIR="$ROOT/target/mitsuba-conventions" \
        cargo build --release --quiet --features mitsuba-conventions)
    EXTRA=(--photon "$ROOT/target/mitsuba-conventions/release/photon" --conventions mitsuba)
fi
# Which photon that is (the table names it).
if rev="$(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null)"; then
    git -C "$ROOT" diff --quiet HEAD -- src Cargo.toml Cargo.lock || rev="$rev+uncommitted"
    export PHOTON_REV="$rev"
fi

# Point Dr.Jit at the newest libLLVM >= 16 on the machine, unless the caller chose one.
if [[ -z "${DRJIT_LIBLLVM_PATH:-}" ]]; then
    best=""; best_major=0
    for lib in /usr/lib/llvm-*/lib/libLLVM*.so* /usr/lib/*-linux-gnu/libLLVM*.so* /usr/lib64/libLLVM*.so*; do
        [[ -e "$lib" ]] || continue
        major="$(basename "$lib" | sed -nE 's/^libLLVM(-|\.so\.)([0-9]+).*/\2/p')"
        [[ -n "$major" ]] || continue
        if (( major >= 16 && major > best_major )); then best="$lib"; best_major="$major"; fi
    done
    if [[ -n "$best" ]]; then
        export DRJIT_LIBLLVM_PATH="$best"
        echo "Dr.Jit LLVM backend: $best"
    else
        echo "no libLLVM >= 16 found: llvm_ad_spectral will be skipped (apt-get install libllvm19 to add it)"
    fi
fi

cd "$ROOT"
"$VENV/bin/python" "$HERE/$SCRIPT" "${EXTRA[@]+"${EXTRA[@]}"}" "$@"
echo "run.sh: ${SECONDS} s in all (venv, build and benchmark)"

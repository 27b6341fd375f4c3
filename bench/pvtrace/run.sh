#!/usr/bin/env bash
# pvtrace against photon on pvtrace's LSC validation case, side by side (not part of CI):
#   bash bench/pvtrace/run.sh                 # ROUNDS=3 RAYS=2000 PHOTONS=1000000 by default
# Installs pvtrace 2.1.4 from PyPI into bench/pvtrace/.venv with the numpy/pandas it was written
# for (it uses np.float and DataFrame.append, gone from numpy 1.24 and pandas 2).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="$here/.venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "pvtrace==2.1.4" "numpy<1.24" "pandas<2" "scipy<1.12" "shapely<2.1"
fi
(cd "$root" && cargo build --release -q)
"$venv/bin/python" -W ignore "$here/compare.py" "$root/target/release/photon" "${ROUNDS:-3}" "${RAYS:-2000}" "${PHOTONS:-1000000}"

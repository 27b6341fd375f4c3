"""Side by side on the LSC validation case: pvtrace (lsc_validation.py) and photon
(scenes/lsc_plate.toml), alternating rounds, each on one core. Prints the CPU time per ray
(pvtrace: one lamp ray followed to its end; photon: one photon history, the same thing) and
the ratio per round, then the median and spread.

    python compare.py PHOTON_BINARY ROUNDS PVTRACE_RAYS PHOTON_PHOTONS
"""
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile

here = os.path.dirname(os.path.abspath(__file__))
root = os.path.dirname(os.path.dirname(here))


def child_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main():
    photon, rounds, rays, photons = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    ratios = []
    for k in range(rounds):
        t0 = child_cpu()
        out = subprocess.run(
            [sys.executable, os.path.join(here, "lsc_validation.py"), str(rays), str(k + 1)],
            env=env, capture_output=True, text=True, check=True,
        ).stdout.strip().splitlines()[-1]
        pv = (child_cpu() - t0) / rays
        faces = json.loads(out)["percent"]
        with tempfile.TemporaryDirectory() as d:
            t0 = child_cpu()
            subprocess.run(
                [photon, "run", os.path.join(root, "scenes", "lsc_plate.toml"), "--threads", "1",
                 "--photons", str(photons), "--seed", str(k + 1), "--out", d, "--quiet"],
                check=True,
            )
            ph = (child_cpu() - t0) / photons
        ratios.append(pv / ph)
        print(f"round {k + 1}: pvtrace {pv * 1e6:.0f} µs/ray (whole process), photon {ph * 1e9:.0f} ns/photon "
              f"(whole process), ratio {pv / ph:.0f}; pvtrace faces {faces}", flush=True)
    print(f"pvtrace / photon CPU time per ray: median {statistics.median(ratios):.0f}, "
          f"range {min(ratios):.0f}–{max(ratios):.0f} over {rounds} rounds")


if __name__ == "__main__":
    main()

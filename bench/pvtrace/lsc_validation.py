"""pvtrace's LSC validation case (examples/Validation.ipynb), run as the notebook runs it, for a
side-by-side comparison with `photon run scenes/lsc_plate.toml`: per-face exit fractions of
photons (percent of lamp photons) and pvtrace's rays per second.

    python lsc_validation.py RAYS SEED      # prints one JSON line
"""
import json
import sys
import time

import numpy as np
from pvtrace import LSC, Distribution, fluro_red, rectangular_mask


def create_waveguide():
    # Verbatim from the notebook's create_waveguide().
    x = np.arange(400, 801, dtype=float)
    size = (l, w, d) = (4.8, 1.8, 0.260)  # cm
    lsc = LSC(size, wavelength_range=x, n1=1.5)
    lsc.add_luminophore(
        "Fluro Red",
        np.column_stack((x, fluro_red.absorption(x) * 11.387815)),  # cm-1
        np.column_stack((x, fluro_red.emission(x))),
        quantum_yield=0.95,
    )
    lsc.add_absorber("PMMA", 0.02)  # cm-1

    def lamp_spectrum(x):
        def g(x, a, p, w):
            return a * np.exp(-(((p - x) / w) ** 2))

        return g(x, 0.53025700136646192, 512.91400020614333, 93.491838802960473) + g(
            x, 0.63578999789955015, 577.63100003089369, 66.031706473985736
        )

    lamp_dist = Distribution(x, lamp_spectrum(x))
    lsc.add_light(
        "Oriel Lamp + Filter",
        (0.0, 0.0, 0.5 * d + 0.01),
        rotation=(np.radians(180), (1, 0, 0)),
        wavelength=lambda: lamp_dist.sample(np.random.uniform()),
        position=lambda: rectangular_mask(l / 2, w / 2),
    )
    return lsc


def main():
    rays, seed = int(sys.argv[1]), int(sys.argv[2])
    np.random.seed(seed)
    lsc = create_waveguide()
    start = time.process_time()
    lsc.simulate(rays, emit_method="redshift")
    cpu = time.process_time() - start
    counts = lsc.counts()
    pct = 100 * counts[["Solar Out", "Luminescent Out"]].sum(axis=1) / rays
    faces = dict(zip(["left", "right", "near", "far", "top", "bottom"], pct.to_list()))
    print(json.dumps({"rays": rays, "seed": seed, "cpu_s": cpu, "rays_per_cpu_s": rays / cpu, "percent": faces}))


if __name__ == "__main__":
    main()

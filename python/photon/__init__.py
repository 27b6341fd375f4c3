"""photon: a forward Monte Carlo photon tracer, from Python.

Load a scene, run it, and read the tallies (with standard errors), the energy ledger, the image
and the maps as numpy arrays::

    import photon
    scene = photon.load("scenes/cornell_box.toml")
    result = scene.run(photons=1_000_000, seed=1)
    floor = next(r for r in result.flux if r["name"] == "floor")
    print(floor["incident_w"], "±", floor["incident_w_stderr"], "W")
    result.image.shape            # (512, 512, 3), float32, linear sRGB
    result.save("out/cornell")    # the files `photon run` writes

A sweep is a loop over `Scene.with_overrides`::

    for p in [50, 100, 200]:
        r = scene.with_overrides({"lights.light.power_w": p}).run(photons=200_000)

The same scene, seed and photon count give the same numbers as the `photon` command line, bit
for bit. See docs/reference.md ("Python") for the whole API.
"""

from ._photon import (
    Result,
    RunInterrupted,
    Scene,
    SceneError,
    __version__,
    from_dict,
    load,
    loads,
    validate,
)

__all__ = [
    "Result",
    "RunInterrupted",
    "Scene",
    "SceneError",
    "__version__",
    "from_dict",
    "load",
    "loads",
    "validate",
]

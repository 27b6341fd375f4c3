"""The Python module against the command line and closed forms.

Run by .ci/run after `pip install .` into a fresh virtual environment. PHOTON_BIN names the CLI
binary built by `cargo build --release` (default: target/release/photon of this checkout); the
tests that compare against it fail, never skip, without it.
"""

import gc
import sys
import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import photon

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
CLI = Path(os.environ.get("PHOTON_BIN", ROOT / "target" / "release" / "photon"))

# run.json's fields that measure time, not the simulation: they differ between any two runs.
TIMING = {"wall_seconds", "photons_per_second", "fom", "rays_per_second"}


def cli_run(scene, out, *args):
    assert CLI.is_file(), f"the photon binary is missing at {CLI}: cargo build --release first"
    subprocess.run([str(CLI), "run", str(scene), "--out", str(out), "--quiet", *args], check=True)


def without_timing(run_json):
    d = {k: v for k, v in run_json.items() if k not in TIMING}
    d["counters"] = {k: v for k, v in d["counters"].items() if k != "trace_seconds"}
    return d


def test_load_and_loads_give_the_same_scene():
    from_file = photon.load(SCENES / "cornell_box.toml")
    text = (SCENES / "cornell_box.toml").read_text()
    from_text = photon.loads(text, base_dir=SCENES, name="cornell_box")
    a, b = from_file.info(), from_text.info()
    a.pop("scene"), b.pop("scene")
    assert a == b
    assert a["triangles"] == 32 and a["total_power_w"] == 100.0
    assert [s["name"] for s in a["surfaces"]][:2] == ["floor", "ceiling"]
    assert from_file.name == "cornell_box" and from_text.toml == text
    assert "triangles: 32" in from_file.describe()


@pytest.mark.parametrize("scene", sorted(p.name for p in SCENES.glob("*.toml")))
def test_every_bundled_scene_runs_and_balances_its_ledger(scene):
    r = photon.load(SCENES / scene).run(photons=20_000, seed=3, image=False)
    led = r.ledger
    # The ledger is exact: only the rounding of the sums separates its two sides.
    total = led["absorbed_w"] + led["escaped_w"] + led["truncated_w"]
    assert abs(total - led["emitted_w"]) <= 1e-9 * led["emitted_w"]
    assert r.run_info["photons"] == 20_000 and r.run_info["stop_reason"] == "photons"
    for row in r.flux:
        assert all(np.isfinite(v) for v in row.values() if isinstance(v, float))
        assert row["incident_w"] >= 0 and row["incident_w_stderr"] >= 0


# BDPT with 30k camera samples leaves some glass pixels unsampled; the CLI warns alike.
@pytest.mark.filterwarnings("ignore:some pixels have 0 camera sample")
@pytest.mark.parametrize(
    "scene, args",
    [
        ("cornell_box.toml", ["--photons", "60000", "--seed", "7"]),
        ("office.toml", ["--photons", "40000", "--seed", "2", "--no-image"]),
        ("luminaire.toml", ["--photons", "40000", "--seed", "5"]),
        ("glass.toml", ["--photons", "30000", "--seed", "9", "--integrator", "bdpt"]),
    ],
)
def test_save_writes_the_cli_files_byte_for_byte(tmp_path, scene, args):
    cli_out, py_out = tmp_path / "cli", tmp_path / "py"
    cli_run(SCENES / scene, cli_out, *args)
    kw = {"photons": int(args[1]), "seed": int(args[3]), "image": "--no-image" not in args}
    if "--integrator" in args:
        kw["integrator"] = args[args.index("--integrator") + 1]
    r = photon.load(SCENES / scene).run(**kw)
    files = r.save(py_out)
    cli_files = json.loads((cli_out / "run.json").read_text())["files"]
    assert files == cli_files and r.run_info["files"] == cli_files
    for f in files:
        a, b = (cli_out / f).read_bytes(), (py_out / f).read_bytes()
        if f == "run.json":
            assert without_timing(json.loads(a)) == without_timing(json.loads(b))
        else:
            assert a == b, f"{scene}: {f} differs from the command line's"
    # The in-memory numbers are the file's numbers, bit for bit.
    assert r.flux_json == json.loads((cli_out / "flux.json").read_text())
    assert without_timing(r.run_info) == without_timing(json.loads((cli_out / "run.json").read_text()))


def test_maps_and_farfield_arrays_hold_the_files_numbers(tmp_path):
    r = photon.load(SCENES / "luminaire.toml").run(photons=40_000, seed=5)
    r.save(tmp_path)
    (name, ff), = r.farfield.items()
    rows = np.genfromtxt(tmp_path / f"farfield_{name}.csv", delimiter=",", names=True)
    n_c, n_g = ff["intensity_cd"].shape
    assert len(rows) == n_c * n_g
    # The CSV writes each f64 in its shortest exact form, so the values match exactly.
    assert np.array_equal(ff["intensity_cd"].ravel(), rows["intensity_cd"])
    assert np.array_equal(ff["intensity_w_sr_stderr"].ravel(), rows["intensity_w_sr_stderr"])
    assert np.array_equal(np.tile(ff["gamma_lo_deg"], n_c), rows["gamma_lo_deg"])
    office = photon.load(SCENES / "office.toml").run(photons=40_000, seed=2, image=False)
    desk = office.maps["desk"] if "desk" in office.maps else next(iter(office.maps.values()))
    e, area = desk["irradiance_w_m2"], desk["texel_area_m2"]
    surface = next(row for row in office.flux if row["name"] in office.maps and office.maps[row["name"]] is desk)
    # The map's texels add up to the surface's incident flux (each photon lands in one texel).
    assert np.isclose((e * area).sum(), surface["incident_w"], rtol=1e-9)
    assert np.isclose(desk["flux_w"].sum(), surface["incident_w"], rtol=1e-9)


def test_volume_detector_arrays(tmp_path):
    text = (SCENES / "tissue_slab.toml").read_text() + """
[[detectors]]
type = "volume"
name = "slab"
min = [-5, -5, -1]
max = [5, 5, 0]
resolution = [4, 3, 2]
"""
    r = photon.loads(text, base_dir=SCENES, name="tissue_volume").run(photons=20_000, seed=1)
    v = r.volumes["slab"]
    assert v["absorbed_w_m3"].shape == (2, 3, 4) and v["fluence_w_m2_stderr"].shape == (2, 3, 4)
    r.save(tmp_path)
    npy = np.load(tmp_path / "volume_slab.npy")
    assert np.array_equal(npy[0], v["absorbed_w_m3"]) and np.array_equal(npy[3], v["fluence_w_m2_stderr"])


def test_image_shape_and_normalisation_radiance_wall():
    # A Lambertian emitter of spectral radiance c filling the view reads Y = c in every pixel
    # (tests/film.rs has the same case for the CLI): mean Y within 4 standard errors of c, and a
    # non-square film has shape [H, W, 3].
    c = 0.37
    scene = photon.loads(
        f"""
[camera]
position = [0, 0, 0]
look_at = [0, 0, 1]
up = [0, 1, 0]
fov_deg = 40
resolution = [32, 24]
[[lights]]
name = "wall"
shape = {{ type = "quad", corners = [[-20, -20, 10], [-20, 20, 10], [20, 20, 10], [20, -20, 10]] }}
radiance = {c}
"""
    )
    r = scene.run(photons=400_000, seed=11)
    assert r.image.shape == (24, 32, 3) and r.image.dtype == np.float32
    assert r.y.shape == (24, 32) and r.y_var.shape == (24, 32) and r.xyz.shape == (24, 32, 3)
    assert np.shares_memory(r.y, r.xyz)  # a view, not a copy
    mean = r.y.astype(np.float64).mean()
    se = np.sqrt(r.y_var.astype(np.float64).sum()) / r.y.size
    assert abs(mean - c) < 4 * se, (mean, se)
    mean_y, se_y = r.run_info["image_mean_y"]
    assert np.isclose(mean_y, mean, rtol=1e-6) and se_y > 0
    # The image is XYZ through the sRGB matrix (IEC 61966-2-1, D65), pixel by pixel.
    m = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])
    assert np.allclose(r.image, r.xyz @ m.T, rtol=2e-3, atol=1e-6 * c)


def test_bad_scenes_raise_scene_error_with_the_line():
    text = '[simulation]\nphotons = 1000\n\n[[lights]]\nname = "a"\nshape = { type = "point", position = [0, 0, 0] }\npower_w = -5\n'
    with pytest.raises(photon.SceneError) as e:
        photon.loads(text, base_dir="/tmp", name="bad")
    assert (e.value.line, e.value.key) == (7, "lights[0].power_w")
    assert e.value.file == "/tmp/bad.toml" and "power_w" in str(e.value)
    assert isinstance(e.value, ValueError)
    with pytest.raises(photon.SceneError) as e:
        photon.loads("[simulation\n")
    assert e.value.line == 1
    with pytest.raises(photon.SceneError) as e:
        photon.load(SCENES / "no_such_scene.toml")
    assert "no_such_scene.toml" in e.value.file
    scene = photon.load(SCENES / "furnace.toml")
    with pytest.raises(ValueError, match="photons"):
        scene.run(photons=0)
    with pytest.raises(ValueError, match="integrator"):
        scene.run(integrator="raytrace")
    with pytest.raises(ValueError, match="tally"):
        scene.run(rel_error=0.01, tally=["nowhere"])
    with pytest.raises(OverflowError):
        scene.run(photons=-1)


def test_overrides_and_dict_round_trip_are_exact():
    scene = photon.load(SCENES / "cornell_box.toml")
    base = scene.run(photons=30_000, seed=4, image=False)
    same = photon.from_dict(scene.to_dict(), base_dir=SCENES, name="cornell_box").run(
        photons=30_000, seed=4, image=False
    )
    assert same.flux_json == base.flux_json
    dark = scene.with_overrides({"materials.white.reflectance": 0.2, "lights.light.power_w": 50})
    r = dark.run(photons=30_000, seed=4, image=False)
    assert r.ledger["emitted_w"] == 50.0
    floor = lambda res: next(x for x in res.flux if x["name"] == "floor")  # noqa: E731
    # A darker room sends less light back to its floor: the inter-reflected share drops.
    assert floor(r)["incident_w"] < 0.5 * floor(base)["incident_w"]
    assert scene.with_overrides({"surfaces.floor.material": "red"}).to_dict()["surfaces"][0]["material"] == "red"
    assert scene.with_overrides({"surfaces.1.name": "roof"}).info()["surfaces"][1]["name"] == "roof"
    assert "camera" not in scene.with_overrides({"camera": None}).to_dict()
    with pytest.raises(KeyError, match="nowhere"):
        scene.with_overrides({"lights.nowhere.power_w": 1})
    with pytest.raises(photon.SceneError):
        scene.with_overrides({"materials.white.reflectance": 1.5})


def test_threads_one_and_two_give_identical_arrays():
    scene = photon.load(SCENES / "cornell_box.toml")
    a = scene.run(photons=50_000, seed=8, threads=1)
    b = scene.run(photons=50_000, seed=8, threads=2)
    assert a.flux_json == b.flux_json
    assert np.array_equal(a.image, b.image) and np.array_equal(a.y_var, b.y_var)
    assert a.run_info["threads"] == 1 and b.run_info["threads"] == 2


def test_keyboard_interrupt_stops_a_long_run_within_a_second():
    scene = photon.load(SCENES / "cornell_box.toml")
    sent = []

    def interrupt():
        sent.append(time.monotonic())
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    timer = threading.Timer(1.0, interrupt)
    timer.start()
    with pytest.raises(photon.RunInterrupted) as e:
        scene.run(photons=10**10, seed=1)
    stopped = time.monotonic() - sent[0]
    timer.join()
    assert stopped < 1.0, f"the run took {stopped:.2f} s to stop"
    assert isinstance(e.value, KeyboardInterrupt)
    r = e.value.result
    assert r.interrupted and r.run_info["stop_reason"] == "interrupted"
    assert 0 < r.run_info["photons"] < 10**10
    led = r.ledger
    assert abs(led["absorbed_w"] + led["escaped_w"] + led["truncated_w"] - led["emitted_w"]) <= 1e-9 * 100


def test_keyboard_interrupt_from_another_process(tmp_path):
    # SIGINT from outside, as a Ctrl-C in a terminal sends it: the child catches RunInterrupted,
    # saves the partial result and exits 0.
    script = tmp_path / "child.py"
    script.write_text(
        f"""
import sys, time, photon
scene = photon.load({str(SCENES / "cornell_box.toml")!r})
print("ready", flush=True)
try:
    scene.run(photons=10**10)
except photon.RunInterrupted as e:
    e.result.save({str(tmp_path / "partial")!r})
    print("stopped", e.result.run_info["photons"], flush=True)
"""
    )
    child = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    child.send_signal(signal.SIGINT)
    out, _ = child.communicate(timeout=30)
    assert child.returncode == 0 and out.startswith("stopped")
    info = json.loads((tmp_path / "partial" / "run.json").read_text())
    assert info["stop_reason"] == "interrupted" and info["photons"] == int(out.split()[1])


def rss_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_memory_stays_flat_over_fifty_runs():
    scene = photon.load(SCENES / "cornell_box.toml")
    for _ in range(5):  # warm up: allocator pools, numpy, thread stacks
        scene.run(photons=16_384, seed=1)
    gc.collect()
    before = rss_bytes()
    for i in range(50):
        r = scene.run(photons=16_384, seed=i)
        assert r.image.shape == (512, 512, 3)
        del r
    gc.collect()
    grown = rss_bytes() - before
    # One result holds about 10 MB (image, xyz, y_var, film sums); a leak of one per run would
    # grow 500 MB. 40 MB leaves room for allocator fragmentation.
    assert grown < 40e6, f"resident memory grew {grown / 1e6:.1f} MB over 50 runs"


def test_progress_bar_draws_and_the_run_is_unchanged(capfd):
    scene = photon.load(SCENES / "furnace.toml")
    a = scene.run(photons=50_000, seed=2, progress=True)
    err = capfd.readouterr().err
    assert "photon" in err
    b = scene.run(photons=50_000, seed=2)
    assert a.flux_json == b.flux_json


def test_info_matches_the_cli():
    out = subprocess.run([str(CLI), "info", str(SCENES / "office.toml")], capture_output=True, text=True, check=True)
    assert photon.load(SCENES / "office.toml").describe() == out.stdout


def test_validate_quick_passes():
    v = photon.validate(quick=True)
    assert v["complete"] and v["passed"], [c["name"] for c in v["cases"] if not c["passed"]]
    assert len(v["cases"]) >= 30

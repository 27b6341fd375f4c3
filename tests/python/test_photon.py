"""The Python module against the command line and closed forms.

Run by .ci/run after `pip install .` into a fresh virtual environment. PHOTON_BIN names the CLI
binary built by `cargo build --release` (default: target/release/photon of this checkout); the
tests that compare against it fail, never skip, without it.
"""

import gc
import sys
import json
import os
import re
import signal
import subprocess
import threading
import time
import types
import warnings
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
    assert v["min"] == [-5, -5, -1] and v["max"] == [5, 5, 0]  # as written, as `info` shows them


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
    # The light tracer images a lamp in view from the camera: every pixel reads c, with no variance.
    assert abs(mean - c) <= 1e-6 * c and se == 0, (mean, se)
    mean_y, se_y = r.run_info["image_mean_y"]
    assert np.isclose(mean_y, mean, rtol=1e-6) and se_y == 0
    # BDPT weighs its camera rays' hits against light-tracing splats (MIS), so its image has a
    # standard error, and agrees within it.
    b = scene.run(photons=400_000, seed=11, integrator="bdpt")
    mean_b = b.y.astype(np.float64).mean()
    se_b = np.sqrt(b.y_var.astype(np.float64).sum()) / b.y.size
    assert se_b > 0 and abs(mean_b - c) < 4 * se_b, (mean_b, se_b)
    assert "image: mean Y" in r.summary() and "pixel noise" in r.summary()
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


@pytest.mark.parametrize(
    "kw, error, message",
    [
        ({"photons": -1}, ValueError, "photons must be a positive integer, got -1"),
        ({"photons": 0}, ValueError, "photons must be a positive integer, got 0"),
        ({"photons": 2**70}, ValueError, "photons must be a positive integer"),
        ({"photons": 1.5}, ValueError, "photons must be a positive integer, got 1.5"),
        ({"photons": float("nan")}, ValueError, "photons must be"),
        ({"photons": "1000"}, TypeError, "photons must be"),
        ({"photons": True}, TypeError, "photons must be"),
        ({"seed": -1}, ValueError, "seed must be an integer between 0 and"),
        ({"seed": 2**64}, ValueError, "seed must be"),
        ({"threads": 0}, ValueError, "threads must be an integer between 1 and 1024, got 0"),
        ({"threads": 5000}, ValueError, "threads must be"),
        ({"max_bounces": -1}, ValueError, "max_bounces must be"),
        ({"max_bounces": 2**32}, ValueError, "max_bounces must be"),
        ({"rel_error": -0.1}, ValueError, "rel_error must be a positive number, got -0.1"),
        ({"rel_error": float("inf")}, ValueError, "rel_error must be"),
        ({"time": 0}, ValueError, "time must be a positive number"),
        ({"tally": ["floor"]}, ValueError, "tally only makes sense with rel_error"),
        ({"tally": ["nowhere"], "rel_error": 0.1}, ValueError, "tally: no surface or medium"),
    ],
)
def test_bad_run_arguments_name_the_python_argument(kw, error, message):
    scene = photon.load(SCENES / "cornell_box.toml")
    with pytest.raises(error, match=re.escape(message)) as e:
        scene.run(**kw)
    assert "--" not in str(e.value), "the message names a command-line flag"


def test_integral_floats_and_numpy_ints_are_counts():
    scene = photon.load(SCENES / "furnace.toml")
    a = scene.run(photons=2e4, seed=np.uint64(3), threads=np.int32(1), max_bounces=50.0)
    b = scene.run(photons=20_000, seed=3, threads=1, max_bounces=50)
    assert a.run_info["photons"] == 20_000 and a.run_info["seed"] == 3
    assert a.flux_json == b.flux_json
    with pytest.raises(ValueError, match="threads must be") as e:
        photon.validate(threads=-2)
    assert "--" not in str(e.value)


def test_save_into_a_file_names_the_argument(tmp_path):
    r = photon.load(SCENES / "furnace.toml").run(photons=2_000, seed=1)
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="save: dir .*is a file, not a folder") as e:
        r.save(tmp_path / "file")
    assert "--out" not in str(e.value)


def test_concurrent_saves_from_two_threads_do_not_collide(tmp_path):
    results = [
        photon.load(SCENES / "cornell_box.toml").run(photons=20_000, seed=1),
        photon.load(SCENES / "luminaire.toml").run(photons=20_000, seed=5),
    ]
    singles = []
    for k, r in enumerate(results):
        singles.append((tmp_path / f"single{k}", r.save(tmp_path / f"single{k}")))
    parent = tmp_path / "together"
    parent.mkdir()
    for round_ in range(3):
        # New folders side by side: their staging folders sit together in `parent`.
        dirs = [parent / f"r{round_}_{k}" for k in range(2)]
        barrier = threading.Barrier(2)
        got, errors = [None, None], []

        def save(k):
            try:
                barrier.wait()
                got[k] = results[k].save(dirs[k])
            except BaseException as e:  # noqa: B036 - reported below
                errors.append(e)

        workers = [threading.Thread(target=save, args=(k,)) for k in range(2)]
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        assert not errors, errors
        for k, (single_dir, single_files) in enumerate(singles):
            assert got[k] == single_files
            for f in single_files:
                assert (dirs[k] / f).read_bytes() == (single_dir / f).read_bytes(), f"{f} differs"
    # Every staging folder was moved into place or removed.
    assert sorted(p.name for p in parent.iterdir()) == sorted(f"r{i}_{k}" for i in range(3) for k in range(2))


def test_self_referential_and_deep_values_raise_value_error():
    d = {"simulation": {"photons": 1000}}
    d["simulation"]["again"] = d
    with pytest.raises(ValueError, match="nested more than 64 levels") as e:
        photon.from_dict(d)
    assert str(e.value).startswith("simulation.again.simulation.again.")
    deep = []
    for _ in range(100_000):
        deep = [deep]
    with pytest.raises(ValueError, match=r"^simulation\.x\[0\]\[0\].*nested more than 64 levels"):
        photon.from_dict({"simulation": {"x": deep}})
    scene = photon.load(SCENES / "furnace.toml")
    with pytest.raises(ValueError, match=r"^simulation\.x\[0\]"):
        scene.with_overrides({"simulation.x": deep})
    # 64 levels are still fine as values go (the loader then judges the key).
    ok = {"a": 1}
    for _ in range(60):
        ok = {"t": ok}
    with pytest.raises(photon.SceneError):
        photon.from_dict({**scene.to_dict(), "extra": ok})


def test_any_mapping_is_accepted_nested_too():
    from types import MappingProxyType

    def proxied(x):
        if isinstance(x, dict):
            return MappingProxyType({k: proxied(v) for k, v in x.items()})
        if isinstance(x, list):
            return [proxied(v) for v in x]
        return x

    scene = photon.load(SCENES / "cornell_box.toml")
    plain = photon.from_dict(scene.to_dict(), base_dir=SCENES, name="cornell_box")
    mapped = photon.from_dict(proxied(scene.to_dict()), base_dir=SCENES, name="cornell_box")
    assert mapped.toml == plain.toml
    over = scene.with_overrides(MappingProxyType({"lights.light": proxied(scene.to_dict()["lights"][0])}))
    assert over.to_dict()["lights"] == scene.to_dict()["lights"]
    with pytest.raises(TypeError):
        scene.with_overrides([("simulation.photons", 5)])


def test_from_dict_drops_none_values_and_loads_checks_the_name():
    scene = photon.load(SCENES / "cornell_box.toml")
    d = scene.to_dict()
    d["camera"] = None
    assert "camera" not in photon.from_dict(d, base_dir=SCENES).to_dict()
    text = (SCENES / "furnace.toml").read_text()
    for bad in ["../escape", "a/b", "a\\b", "..", ""]:
        with pytest.raises(ValueError, match="name must be a file name"):
            photon.loads(text, base_dir=SCENES, name=bad)
        with pytest.raises(ValueError, match="name must be a file name"):
            photon.from_dict(d, base_dir=SCENES, name=bad)
    assert photon.loads(text, base_dir=SCENES, name="furnace_copy").name == "furnace_copy"


def test_nested_key_errors_read_plainly():
    scene = photon.load(SCENES / "cornell_box.toml")
    with pytest.raises(KeyError) as e:
        scene.with_overrides({"surfaces.floor.material.x": 1})
    assert e.value.args[0] == "surfaces.floor.material.x: `surfaces.floor.material` is a value, not a table"


def test_relative_scene_path_survives_a_change_of_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    scene = photon.load("scenes/luminaire.toml")  # names its IES file by a relative path
    monkeypatch.chdir(tmp_path)
    moved = scene.with_overrides({"simulation.seed": 4})
    r = moved.run(photons=5_000, seed=2, image=False)
    assert moved.path == scene.path == "scenes/luminaire.toml"
    assert r.run_info["scene"] == "scenes/luminaire.toml" and r.ledger["emitted_w"] > 0
    same = scene.run(photons=5_000, seed=2, image=False)
    assert r.flux_json == same.flux_json


def test_warnings_point_at_the_caller_and_can_be_errors():
    scene = photon.load(SCENES / "cornell_box.toml")
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        scene.run(photons=1_000, seed=1)
    (w,) = [w for w in seen if "film batches" in str(w.message)]
    assert w.category is UserWarning and w.filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="fewer than 2 film batches"):
            scene.run(photons=1_000, seed=1)


class FakeTqdm:
    """tqdm.auto.tqdm's calls as the module makes them, recorded."""

    made = []
    fail_update = None

    def __init__(self, total=None, **kw):
        self.total, self.n, self.closed = total, 0, 0
        FakeTqdm.made.append(self)

    def update(self, k):
        if FakeTqdm.fail_update is not None:
            raise FakeTqdm.fail_update
        self.n += k

    def close(self):
        self.closed += 1


@pytest.fixture
def fake_tqdm(monkeypatch):
    auto = types.ModuleType("tqdm.auto")
    auto.tqdm = FakeTqdm
    pkg = types.ModuleType("tqdm")
    pkg.auto = auto
    monkeypatch.setitem(sys.modules, "tqdm", pkg)
    monkeypatch.setitem(sys.modules, "tqdm.auto", auto)
    FakeTqdm.made, FakeTqdm.fail_update = [], None
    yield FakeTqdm
    FakeTqdm.fail_update = None


def test_progress_bar_reaches_the_final_count_and_closes(fake_tqdm):
    r = photon.load(SCENES / "furnace.toml").run(photons=50_000, seed=2, progress=True)
    (bar,) = fake_tqdm.made
    assert bar.total == 50_000 and bar.n == r.run_info["photons"] == 50_000 and bar.closed == 1


def test_keyboard_interrupt_inside_the_progress_bar_stops_the_run(fake_tqdm):
    fake_tqdm.fail_update = KeyboardInterrupt()
    start = time.monotonic()
    with pytest.raises(photon.RunInterrupted) as e:
        photon.load(SCENES / "cornell_box.toml").run(photons=10**10, seed=1, progress=True)
    assert time.monotonic() - start < 10
    assert e.value.result.interrupted and 0 < e.value.result.run_info["photons"] < 10**10
    (bar,) = fake_tqdm.made
    assert bar.closed == 1


def test_keyboard_interrupt_is_kept_when_no_result_can_be_made(fake_tqdm):
    # The bar's last update is interrupted, then the result's warning is an error: the
    # interrupt is raised, the warning its cause.
    fake_tqdm.fail_update = KeyboardInterrupt()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(photon.RunInterrupted) as e:
            photon.load(SCENES / "cornell_box.toml").run(photons=1_000, seed=1, progress=True)
    assert e.value.result is None and isinstance(e.value.__cause__, UserWarning)


def test_keyboard_interrupt_while_making_the_bar(monkeypatch, fake_tqdm):
    def interrupted(**kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(sys.modules["tqdm.auto"], "tqdm", interrupted)
    with pytest.raises(KeyboardInterrupt):
        photon.load(SCENES / "furnace.toml").run(photons=1_000, seed=1, progress=True)


def test_fallback_progress_line_ends_once(monkeypatch, capfd):
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)  # as if tqdm were not installed
    photon.load(SCENES / "furnace.toml").run(photons=20_000, seed=2, progress=True)
    err = capfd.readouterr().err
    assert "100.0%" in err and err.endswith("\n") and err.count("\n") == 1
    monkeypatch.setattr(sys, "stderr", None)  # pythonw: nowhere to draw, and no error
    r = photon.load(SCENES / "furnace.toml").run(photons=20_000, seed=2, progress=True)
    assert r.run_info["photons"] == 20_000


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
    # A runner started in the background by a shell without job control inherits SIGINT
    # ignored, and Python then installs no KeyboardInterrupt handler: install it here. time=60
    # bounds the test should the interrupt still be lost (a failure, not hours of running).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(photon.RunInterrupted) as e:
            scene.run(photons=10**10, seed=1, time=60)
    finally:
        signal.signal(signal.SIGINT, previous)
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
import signal, sys, time, photon
# Ctrl-C's default handler, even when this process inherited SIGINT ignored (a background job).
signal.signal(signal.SIGINT, signal.default_int_handler)
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

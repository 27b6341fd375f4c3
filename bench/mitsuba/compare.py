#!/usr/bin/env python3
"""Side-by-side benchmark: photon vs Mitsuba 3's `ptracer` on the measured Cornell box.

Run through `bash bench/mitsuba/run.sh` (which makes the virtual environment and builds photon).
Both renderers get the same scene, built here for Mitsuba from scenes/cornell_box.toml, its OBJ
blocks and the measured spectra in spectra/:

* geometry in metres (the TOML is in mm; photon converts the same way), the light quad 0.1 mm
  below the ceiling and facing down, emitting from its front side only;
* two-sided Lambertian walls and blocks with the measured reflectance spectra; the light's own
  surface is black (photon's default `absorber`);
* the light's spectrum S(λ) scaled to 100 W over 400-700 nm: L(λ) = Φ·S(λ)/(π·A·∫S dλ) in
  W m^-2 sr^-1 nm^-1 (a Lambertian emitter of area A);
* a pinhole (perspective) camera with the same pose, 39.3077° horizontal field of view, 512×512,
  and a box pixel filter, so every splat lands in exactly one pixel, as in photon.

Mitsuba's ptracer traces spp·width·height light paths for a sample count spp (AdjointIntegrator::
render: samples_per_pass = width·height·spp, one `sample()` = one emitted light path plus one
emitter-to-camera connection); photon is run with --photons equal to that count, with its defaults
and with `--estimator expected`. These equal-light-path runs alternate, `--repeats` times, and each
keeps its fastest (the machine may be shared). Then photon runs again with `--time` set to the
fastest Mitsuba's time: the equal-time comparison is measured, and also predicted from each
equal-path run (noise variance ∝ 1/time).

Errors are measured on luminance Y = 0.2126 R + 0.7152 G + 0.0722 B (linear sRGB, both images)
against a shared high-photon photon reference rendered with another seed. Mitsuba's image is
multiplied by one global scale factor, the ratio of the image means. The two normalise Y over
different wavelength ranges (photon by ∫ȳ over the scene's 400-700 nm, Mitsuba by ∫ȳ over
360-830 nm), so the expected factor is ∫ȳ(360-830)/∫ȳ(400-700) = 1.0006; both are printed.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import resource
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "cornell_box.toml"
HERE = Path(__file__).resolve().parent
LUMA = np.array([0.2126, 0.7152, 0.0722])


# --------------------------------------------------------------------------------------------
# Scene data shared by both renderers


def read_csv(path: Path) -> tuple[list[float], list[float]]:
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    data = [(float(a), float(b)) for a, b in rows[1:]]
    return [a for a, _ in data], [b for _, b in data]


def trapezoid(x: list[float], y: list[float], lo: float, hi: float) -> float:
    """∫ y dλ over [lo, hi] of the piecewise-linear table (zero outside its support)."""
    xs = np.linspace(lo, hi, 30001)
    return float(np.trapezoid(np.interp(xs, x, y, left=0.0, right=0.0), xs))


def load_toml(scene: Path = SCENE) -> dict:
    with open(scene, "rb") as f:
        return tomllib.load(f)


def write_quad_obj(path: Path, corners: list[list[float]], scene: Path = SCENE) -> None:
    with open(path, "w") as f:
        f.write(f"# written by bench/mitsuba/compare.py from scenes/{scene.name} (mm)\n")
        for c in corners:
            f.write("v {} {} {}\n".format(*c))
        f.write("f 1 2 3 4\n")


def quad_area(c: list[list[float]]) -> float:
    a, b, cc, d = (np.array(p, dtype=float) for p in c)
    return 0.5 * (np.linalg.norm(np.cross(b - a, cc - a)) + np.linalg.norm(np.cross(cc - a, d - a)))


def irregular(wl: list[float], val: list[float], scale: float = 1.0) -> dict:
    """A piecewise-linear Mitsuba spectrum (zero outside its table, as photon's)."""
    return {
        "type": "irregular",
        "wavelengths": ", ".join(f"{w:g}" for w in wl),
        "values": ", ".join(f"{v * scale:.9g}" for v in val),
    }


def read_nk(path: Path) -> tuple[list[float], list[float], list[float]]:
    """A bundled metal's table (wavelength_nm, n, k), as src/scene/catalog.rs reads it."""
    with open(path, newline="") as f:
        rows = [[float(x) for x in r] for r in list(csv.reader(f))[1:] if r]
    return [r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows]


def mitsuba_bsdf(m: dict, scene_dir: Path) -> dict:
    """photon's material `m` (a [materials.*] table) as a Mitsuba BSDF. The Cornell box has only
    `lambertian`; the others are for scenes/cornell_glossy.toml (bench/mitsuba/glossy.py):

    * `conductor` → `roughconductor` (GGX, visible-normal sampling) with photon's own n, k table
      (spectra/metal_<name>_nk.csv, not Mitsuba's built-in metals), in `twosided`;
    * `dielectric` → `roughdielectric`, int_ior = ior, ext_ior = outside_ior (1 by default in
      photon, where Mitsuba's default is air's 1.000277);
    * `plastic` → `roughplastic`, `nonlinear = true` (photon's diffuse_reflectance is the base's own
      albedo), ext_ior 1, in `twosided`.

    Smooth (roughness 0) materials map to `conductor`, `dielectric` and `plastic`."""

    def spectrum(v) -> dict | float:
        if isinstance(v, (int, float)):
            return float(v)
        if "file" in v:
            return irregular(*read_csv((scene_dir / v["file"]).resolve()))
        if "table" in v:
            return irregular([r[0] for r in v["table"]], [r[1] for r in v["table"]])
        raise SystemExit(f"unsupported spectrum {v}")

    def alpha(m: dict) -> float:
        a = m.get("roughness", 0.0)
        if not isinstance(a, (int, float)):
            raise SystemExit(f"anisotropic roughness is not mapped: {m}")
        return float(a)

    def number(v, what: str) -> float:
        if not isinstance(v, (int, float)):
            raise SystemExit(f"{what} must be a number here, found {v!r}")
        return float(v)

    kind = m["type"]
    if kind == "lambertian":
        # photon's Lambertian surfaces reflect on both sides
        return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": spectrum(m["reflectance"])}}
    if kind == "conductor":
        if "metal" in m:
            wl, n, k = read_nk(ROOT / "spectra" / f"metal_{m['metal']}_nk.csv")
            eta, kk = irregular(wl, n), irregular(wl, k)
        else:
            eta, kk = spectrum(m["eta"]), spectrum(m["k"])
        b = {"eta": eta, "k": kk, "specular_reflectance": number(m.get("specular_reflectance", 1.0), "specular_reflectance")}
        a = alpha(m)
        b |= {"type": "roughconductor", "distribution": "ggx", "alpha": a, "sample_visible": True} if a > 0 else {"type": "conductor"}
        return {"type": "twosided", "bsdf": b}
    if kind == "dielectric":
        assert "absorption_per_m" not in m, m
        b = {"int_ior": number(m.get("ior", 1.5), "ior"), "ext_ior": number(m.get("outside_ior", 1.0), "outside_ior")}
        a = alpha(m)
        b |= {"type": "roughdielectric", "distribution": "ggx", "alpha": a, "sample_visible": True} if a > 0 else {"type": "dielectric"}
        return b  # a dielectric boundary has two sides already
    if kind == "plastic":
        b = {"diffuse_reflectance": spectrum(m.get("diffuse_reflectance", 0.5)), "int_ior": number(m.get("ior", 1.5), "ior"),
             "ext_ior": 1.0, "nonlinear": True}
        a = alpha(m)
        b |= {"type": "roughplastic", "distribution": "ggx", "alpha": a, "sample_visible": True} if a > 0 else {"type": "plastic"}
        return {"type": "twosided", "bsdf": b}  # photon's plastic reflects alike from both sides
    raise SystemExit(f"material type {kind} is not mapped to Mitsuba")


def mitsuba_scene_dict(mi, toml: dict, work: Path, spp: int, max_depth: int, scene: Path = SCENE) -> tuple[dict, dict]:
    """The Mitsuba scene as a dict for mi.load_dict, and facts about it for the report."""
    assert toml["scene"]["unit"] == "mm"
    unit_m = 1e-3
    lo, hi = toml["simulation"]["wavelength_range_nm"]
    to_m = mi.ScalarTransform4f().scale(unit_m)

    def spectrum(path: Path, scale: float = 1.0) -> dict:
        return irregular(*read_csv(path), scale)

    scene_dir = scene.parent
    bsdfs = {name: mitsuba_bsdf(m, scene_dir) for name, m in toml["materials"].items()}

    d: dict = {"type": "scene"}
    for i, s in enumerate(toml["surfaces"]):
        shape = s["shape"]
        if shape["type"] == "quad":
            obj = work / f"{s['name']}.obj"
            write_quad_obj(obj, shape["corners"], scene)
        elif shape["type"] == "mesh":
            obj = (scene_dir / shape["file"]).resolve()
        else:
            raise SystemExit(f"unsupported shape {shape['type']}")
        d[f"s{i}_{s['name']}"] = {
            "type": "obj",
            "filename": str(obj),
            "face_normals": True,
            "to_world": to_m,
            "bsdf": dict(bsdfs[s["material"]]),
        }

    assert len(toml["lights"]) == 1
    light = toml["lights"][0]
    assert light["shape"]["type"] == "quad" and light.get("distribution", "lambertian") == "lambertian"
    corners = light["shape"]["corners"]
    area_m2 = quad_area(corners) * unit_m**2
    wl, sv = read_csv((scene_dir / light["spectrum"]["file"]).resolve())
    s_int = trapezoid(wl, sv, lo, hi)
    power = float(light["power_w"])
    # Lambertian: Φ = π A ∫L dλ, so L(λ) = Φ S(λ) / (π A ∫S dλ).
    k = power / (math.pi * area_m2 * s_int)
    obj = work / "light.obj"
    write_quad_obj(obj, corners, scene)
    # Mitsuba's area light emits on the side of the shape normal; the OBJ keeps photon's corner
    # order, whose normal (b − a) × (c − a) points down (−y) into the box.
    n = np.cross(np.subtract(corners[1], corners[0]), np.subtract(corners[2], corners[0]))
    assert n[1] < 0, "light quad should face down"
    d["light"] = {
        "type": "obj",
        "filename": str(obj),
        "face_normals": True,
        "to_world": to_m,
        "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}},  # absorber
        "emitter": {"type": "area", "radiance": spectrum((scene_dir / light["spectrum"]["file"]).resolve(), k)},
    }

    cam = toml["camera"]
    w, h = cam["resolution"]
    d["sensor"] = {
        "type": "perspective",
        "fov": float(cam["fov_deg"]),
        "fov_axis": "x",
        "near_clip": 1e-3,
        "far_clip": 100.0,
        "to_world": mi.ScalarTransform4f().look_at(
            origin=[c * unit_m for c in cam["position"]],
            target=[c * unit_m for c in cam["look_at"]],
            up=cam["up"],
        ),
        "sampler": {"type": "independent", "sample_count": spp},
        "film": {
            "type": "hdrfilm",
            "width": w,
            "height": h,
            "pixel_format": "rgb",
            "component_format": "float32",
            "rfilter": {"type": "box"},
        },
    }
    d["integrator"] = {"type": "ptracer", "max_depth": max_depth, "hide_emitters": False}
    facts = {
        "area_m2": area_m2,
        "light_spectrum_integral": s_int,
        "radiance_scale": k,
        "radiance_peak": k * max(sv),
        "resolution": (w, h),
    }
    return d, facts


# --------------------------------------------------------------------------------------------
# Rendering


def luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., :3] @ LUMA


def read_exr_rgb(mi, path: Path) -> np.ndarray:
    """photon's image.exr (channels R, G, B, Y, Y_var) → (h, w, 3) linear sRGB."""
    bmp = mi.Bitmap(str(path))
    names = [f.name for f in bmp.struct_()]
    arr = np.array(bmp, copy=True)
    idx = [names.index(c) for c in ("R", "G", "B")]
    return arr[..., idx].astype(np.float64), (arr[..., names.index("Y_var")].astype(np.float64) if "Y_var" in names else None)


# photon configurations: its defaults (`--estimator auto` picks analog survival in this box), and
# expected-value absorption (more scatterings per photon: fewer photons per second, less noise each).
PHOTON_CONFIGS = {"default": [], "--estimator expected": ["--estimator", "expected"]}


def run_photon(binary: Path, out: Path, photons: int | None, seed: int, time_s: float | None = None,
               extra: list[str] = (), scene: Path = SCENE) -> dict:
    cmd = [str(binary), "run", str(scene), "--out", str(out), "--seed", str(seed), "--quiet", *extra]
    if time_s is not None:
        # --time stops at the first batch boundary after the budget; the scene's own photon count
        # would otherwise cap it, so give a cap that is never reached.
        cmd += ["--time", f"{time_s:.3f}", "--photons", str(10**13)]
    else:
        cmd += ["--photons", str(photons)]
    t0 = time.perf_counter()
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    info = json.loads((out / "run.json").read_text())
    info["process_seconds"] = time.perf_counter() - t0
    # CPU time of the whole process (load, trace, write): the machine may be shared, so the
    # table reports light paths per CPU-second beside the wall-clock rate.
    info["cpu_seconds"] = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return info


def quiet_mitsuba_logger(mi) -> None:
    """Warnings and errors only, and no progress bar (Mitsuba draws it whatever the log level)."""

    class Quiet(mi.Appender):
        def append(self, level, text):
            if level >= mi.LogLevel.Warn:
                print(text, file=sys.stderr)

        def log_progress(self, progress, name, formatted, eta, ptr=None):
            pass

    logger = mi.logger()
    logger.clear_appenders()
    logger.add_appender(Quiet())
    logger.set_log_level(mi.LogLevel.Warn)


class MitsubaRun:
    """One Mitsuba variant with the scene loaded once; `render` may be called repeatedly."""

    def __init__(self, variant: str, toml: dict, work: Path, spp: int, max_depth: int, scene: Path = SCENE):
        import mitsuba as mi

        self.mi, self.variant, self.spp = mi, variant, spp
        mi.set_variant(variant)
        quiet_mitsuba_logger(mi)
        t0 = time.perf_counter()
        scene_dict, self.facts = mitsuba_scene_dict(mi, toml, work, spp, max_depth, scene)
        self.scene = mi.load_dict(scene_dict)
        self.load_seconds = time.perf_counter() - t0
        w, h = self.facts["resolution"]
        self.paths = spp * w * h
        self.work = work

    def render(self, seed: int = 1) -> dict:
        mi = self.mi
        mi.set_variant(self.variant)
        t0, c0 = time.perf_counter(), time.process_time()
        img = mi.render(self.scene, spp=self.spp, seed=seed)
        rgb = np.array(img, dtype=np.float64)  # forces evaluation in the JIT variants
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        mi.Bitmap(img).write(str(self.work / f"mitsuba_{self.variant}.exr"))
        return {"rgb": rgb, "seconds": wall, "cpu_seconds": cpu}


# --------------------------------------------------------------------------------------------
# Error and pictures


def rel_rmse(y: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(np.mean((y - ref) ** 2)) / np.mean(ref))


def fit_scale(y: np.ndarray, ref: np.ndarray) -> float:
    """One global factor s with s·y ≈ ref: the ratio of the image means. (A least-squares fit,
    Σ y·ref / Σ y², is biased low by y's own noise, which inflates Σ y², and would shrink the
    noisier image toward zero.)"""
    return float(np.sum(ref) / np.sum(y))


def tile_check(y: np.ndarray, ref: np.ndarray, tile: int = 32) -> tuple[float, float, tuple[int, int]]:
    """Relative difference of tile means (tile×tile pixels) against the reference, over tiles with
    light in them: (RMS over tiles, worst |difference|, worst tile's (row, col)). Averaging over a
    tile beats the per-pixel noise down, so a systematic difference between the renderers (a
    shadow, an edge, a colour) stands out against two images of the same renderer."""
    h, w = ref.shape
    a = y[: h // tile * tile, : w // tile * tile].reshape(h // tile, tile, w // tile, tile).mean(axis=(1, 3))
    b = ref[: h // tile * tile, : w // tile * tile].reshape(h // tile, tile, w // tile, tile).mean(axis=(1, 3))
    lit = b > 0.05 * b.mean()
    d = np.where(lit, (a - b) / np.where(lit, b, 1.0), 0.0)
    k = np.unravel_index(np.argmax(np.abs(d)), d.shape)
    return float(np.sqrt(np.mean(d[lit] ** 2))), float(d[k]), (int(k[0]), int(k[1]))


def write_png(path: Path, rgb: np.ndarray, exposure: float) -> None:
    """Fixed-exposure preview (same exposure for every image so they compare by eye)."""
    import mitsuba as mi

    x = np.clip(rgb * exposure, 0.0, None)
    x = x / (1.0 + x)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    u8 = np.clip(np.round(x * 255.0), 0, 255).astype(np.uint8)
    mi.Bitmap(u8, mi.Bitmap.PixelFormat.RGB).write(str(path))


def cie_y_ratio() -> float:
    """∫ȳ over 360-830 nm / ∫ȳ over 400-700 nm from the CIE table photon uses."""
    with open(ROOT / "spectra" / "cie1931_2deg_xyz.csv", newline="") as f:
        rows = [r for r in csv.reader(f)][1:]
    wl = np.array([float(r[0]) for r in rows])
    yb = np.array([float(r[2]) for r in rows])
    full = np.trapezoid(yb, wl)
    m = (wl >= 400) & (wl <= 700)
    return float(full / np.trapezoid(yb[m], wl[m]))


# --------------------------------------------------------------------------------------------


def usable_variants(mi) -> list[str]:
    """Spectral CPU variants that can render here. Each is tried in a child process: a JIT
    variant whose LLVM cannot compile Dr.Jit's kernels aborts the whole process (LLVM ERROR)."""
    found = []
    for v in ("scalar_spectral", "llvm_ad_spectral"):
        if v not in mi.variants():
            continue
        probe = (
            "import mitsuba as mi, numpy as np\n"
            f"mi.set_variant('{v}')\n"
            "s = mi.load_dict({'type': 'scene', 'e': {'type': 'constant'},"
            " 'sensor': {'type': 'perspective', 'film': {'type': 'hdrfilm', 'width': 4, 'height': 4}},"
            " 'integrator': {'type': 'ptracer'}})\n"
            "np.array(mi.render(s, spp=1))\n"
        )
        r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
        if r.returncode == 0:
            found.append(v)
        else:
            msg = (r.stderr.strip().splitlines() or ["?"])[0]
            print(f"note: skipping {v}, it cannot render here: {msg}", file=sys.stderr)
    return found


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--photon", type=Path, default=ROOT / "target" / "release" / "photon")
    ap.add_argument("--out", type=Path, default=HERE / "out")
    ap.add_argument("--spp", type=int, default=16, help="Mitsuba samples per pixel; light paths = spp·512·512")
    ap.add_argument("--ref-photons", type=int, default=80_000_000)
    ap.add_argument("--repeats", type=int, default=3,
                    help="equal-light-path runs of each renderer, alternated; the fastest is kept")
    ap.add_argument("--ref-seed", type=int, default=424242)
    ap.add_argument("--max-depth", type=int, default=-1, help="Mitsuba max_depth (-1: unbounded, like photon)")
    ap.add_argument("--variants", default="auto", help="comma-separated Mitsuba variants, or auto")
    ap.add_argument("--reuse-reference", action="store_true",
                    help="keep OUT/reference if it was made with the same photon count and seed")
    ap.add_argument("--results", type=Path, default=HERE / "results.md")
    args = ap.parse_args()

    import mitsuba as mi

    t_start = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    work = args.out / "scene"
    work.mkdir(exist_ok=True)
    # A private copy of the binary, so that a concurrent rebuild cannot swap it mid-benchmark.
    (args.out / "bin").mkdir(exist_ok=True)
    binary = args.out / "bin" / "photon"
    shutil.copy2(args.photon, binary)
    variants = usable_variants(mi) if args.variants == "auto" else args.variants.split(",")
    if not variants:
        raise SystemExit("no Mitsuba spectral CPU variant can render here")

    toml = load_toml()
    w, h = toml["camera"]["resolution"]
    paths = args.spp * w * h
    load_before = os.getloadavg()[0]

    # 1. The shared reference (another seed than the runs it judges).
    print(f"reference: photon, {args.ref_photons:,} photons, seed {args.ref_seed} ...", flush=True)
    old = args.out / "reference" / "run.json"
    old_info = json.loads(old.read_text()) if args.reuse_reference and old.exists() else {}
    if (old_info.get("photons"), old_info.get("seed")) == (args.ref_photons, args.ref_seed):
        ref_info = old_info
        print("  (reused)")
    else:
        ref_info = run_photon(binary, args.out / "reference", args.ref_photons, args.ref_seed)
    ref_rgb, ref_yvar = read_exr_rgb(mi, args.out / "reference" / "image.exr")
    ref = luminance(ref_rgb)
    # The reference's own noise, from photon's per-pixel variance of Y; it adds in quadrature to
    # every error measured against it.
    ref_noise = float(np.sqrt(np.mean(ref_yvar)) / np.mean(ref))
    # Pixels that see the lamp itself, some 50× brighter than the walls: the masked column is the
    # error over the lit room alone.
    lamp = ref > 20.0 * np.mean(ref)
    keep = ~lamp
    ref_noise_nolamp = float(np.sqrt(np.mean(ref_yvar[keep])) / np.mean(ref[keep]))
    print(f"  {ref_info['wall_seconds']:.1f} s; its own relative RMS noise: {ref_noise:.4f} "
          f"(lamp masked: {ref_noise_nolamp:.4f})", flush=True)

    rows = []

    # 2. photon and Mitsuba at the same number of light paths, alternately, `--repeats` times;
    # each keeps its fastest run (the machine may be shared). All repeats of one renderer use the
    # same seed, so they make the same image.
    mitsuba_runs = [MitsubaRun(v, toml, work, args.spp, args.max_depth) for v in variants]
    best: dict[str, dict] = {}
    times: dict[str, list[float]] = {}

    def keep_best(key: str, run: dict) -> None:
        times.setdefault(key, []).append(run["seconds"])
        if key not in best or run["seconds"] < best[key]["seconds"]:
            best[key] = run

    def photon_dir(cfg: str, suffix: str = "") -> Path:
        return args.out / ("photon" + ("" if cfg == "default" else "_expected") + suffix)

    for rep in range(args.repeats):
        for cfg, extra in PHOTON_CONFIGS.items():
            print(f"[{rep + 1}/{args.repeats}] photon {cfg}: {paths:,} photons ...", flush=True)
            p = run_photon(binary, photon_dir(cfg), paths, 1, extra=extra)
            p["seconds"] = p["wall_seconds"]
            print(f"  {p['seconds']:.1f} s", flush=True)
            keep_best(f"photon {cfg}", p)
        for m in mitsuba_runs:
            print(f"[{rep + 1}/{args.repeats}] mitsuba {mi.__version__} {m.variant}: spp {args.spp} = "
                  f"{m.paths:,} light paths ...", flush=True)
            r = m.render(seed=1)
            print(f"  {r['seconds']:.1f} s", flush=True)
            keep_best(m.variant, r)

    photon_rgb = {}
    for cfg in PHOTON_CONFIGS:
        p = best[f"photon {cfg}"]
        photon_rgb[cfg], _ = read_exr_rgb(mi, photon_dir(cfg) / "image.exr")
        rows.append({"renderer": "photon", "variant": cfg, "paths": p["photons"], "seconds": p["seconds"],
                     "cpu": p["cpu_seconds"], "rgb": photon_rgb[cfg], "scale": 1.0, "what": "equal light paths"})
    for m in mitsuba_runs:
        r = best[m.variant]
        m.seconds = r["seconds"]
        m.scale = fit_scale(luminance(r["rgb"]), ref)
        rows.append({"renderer": f"Mitsuba {mi.__version__}", "variant": m.variant, "paths": m.paths,
                     "seconds": r["seconds"], "cpu": r["cpu_seconds"], "rgb": r["rgb"], "scale": m.scale,
                     "what": "equal light paths"})

    # 3. photon at equal time with the fastest Mitsuba variant: real second runs with --time.
    fastest = min(mitsuba_runs, key=lambda m: m.seconds)
    for cfg, extra in PHOTON_CONFIGS.items():
        print(f"photon {cfg}: --time {fastest.seconds:.1f} s (equal time with {fastest.variant}) ...", flush=True)
        q = run_photon(binary, photon_dir(cfg, "_equal_time"), None, 1, time_s=fastest.seconds, extra=extra)
        q_rgb, _ = read_exr_rgb(mi, photon_dir(cfg, "_equal_time") / "image.exr")
        if cfg == "default":
            photon_rgb["equal_time"] = q_rgb
        rows.append({"renderer": "photon", "variant": cfg, "paths": q["photons"], "seconds": q["wall_seconds"],
                     "cpu": q["cpu_seconds"], "rgb": q_rgb, "scale": 1.0,
                     "what": f"equal time with {fastest.variant} (`--time`)"})
    load_after = os.getloadavg()[0]
    total_s = time.perf_counter() - t_start

    # 5. The table.
    m_rate = max(r["paths"] / r["seconds"] for r in rows if r["renderer"] != "photon")
    m_cpu_rate = max(r["paths"] / r["cpu"] for r in rows if r["renderer"] != "photon")
    for r in rows:
        y = luminance(r["rgb"]) * r["scale"]
        r["err"] = rel_rmse(y, ref)
        r["err_nolamp"] = rel_rmse(y[keep], ref[keep])
        r["rate"] = r["paths"] / r["seconds"]
        r["cpu_rate"] = r["paths"] / r["cpu"]
        # The same image's error had it run for the fastest Mitsuba's time: its own noise variance
        # scales as 1/time, the reference's (ref_noise) does not.
        own = max(r["err"] ** 2 - ref_noise**2, 0.0)
        r["err_t"] = math.sqrt(own * r["seconds"] / fastest.seconds + ref_noise**2)
    header = ["renderer", "variant", "light paths", "seconds", "light paths/s", "÷ fastest Mitsuba",
              "paths per CPU-s", "÷ fastest Mitsuba (CPU)", "rel. RMSE (Y)", "rel. RMSE, lamp masked",
              "rel. RMSE scaled to equal time", "run"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        ratio = f"{r['rate'] / m_rate:.2f}×"
        cpu_ratio = f"{r['cpu_rate'] / m_cpu_rate:.2f}×"
        lines.append(
            f"| {r['renderer']} | {r['variant']} | {r['paths']:,} | {r['seconds']:.1f} | {r['rate']:,.0f} | {ratio} | "
            f"{r['cpu_rate']:,.0f} | {cpu_ratio} | {r['err']:.4f} | {r['err_nolamp']:.4f} | {r['err_t']:.4f} | "
            f"{r['what']} |"
        )
    table = "\n".join(lines)
    f = mitsuba_runs[0].facts
    default_binary = args.photon.resolve() == (ROOT / "target" / "release" / "photon").resolve()
    photon_rev = f" (commit {os.environ['PHOTON_REV']})" if default_binary and os.environ.get("PHOTON_REV") else ""
    notes = [
        f"photon {ref_info['version']}{photon_rev}: `photon run` with its defaults (hero wavelengths, `--estimator auto`, "
        "which picks analog survival here), and with `--estimator expected` (expected-value absorption with albedo roulette); "
        f"Mitsuba {mi.__version__} `ptracer`, max_depth {args.max_depth}, rr_depth 5, independent sampler, box filter.",
        "seconds: photon's `wall_seconds` (tracing only) and Mitsuba's `mi.render` wall time; CPU-s: the whole "
        "photon process, and the Python process during `mi.render`.",
        f"Reference: photon, {ref_info['photons']:,} photons, seed {args.ref_seed}, {ref_info['wall_seconds']:.0f} s. "
        f"Its own relative RMS noise (from its Y_var) is {ref_noise:.4f} ({ref_noise_nolamp:.4f} lamp masked); "
        "it is included, in quadrature, in every error above.",
        "rel. RMSE = sqrt(mean((Y − Y_ref)²)) / mean(Y_ref) over all 512×512 pixels, Y = 0.2126 R + 0.7152 G + 0.0722 B "
        f"from each image's linear sRGB; 'lamp masked' leaves out the {int(lamp.sum())} pixels that see the lamp. "
        f"'Scaled to equal time': sqrt((E² − e_ref²)·s/{fastest.seconds:.1f} + e_ref²), the error E that row would "
        f"have after the fastest Mitsuba's {fastest.seconds:.1f} s (noise variance ∝ 1/time; e_ref the reference's "
        "own noise); the `--time` rows measure the same thing directly.",
        "Mitsuba's image is multiplied by one global scale factor, mean(Y_ref)/mean(Y_mitsuba): "
        + ", ".join(f"{m.variant} {m.scale:.4f}" for m in mitsuba_runs)
        + f"; expected ∫ȳ(360–830 nm)/∫ȳ(400–700 nm) = {cie_y_ratio():.4f} (Mitsuba normalises Y over 360–830 nm, "
        "photon over the scene's 400–700 nm).",
        f"Lamp: A = {f['area_m2']:.5f} m², ∫S dλ = {f['light_spectrum_integral']:.0f}, "
        f"L(λ) = {f['radiance_scale']:.4f}·S(λ) W m⁻² sr⁻¹ nm⁻¹ (100 W, Lambertian, front side only).",
        "Equal-light-path runs, alternated, fastest kept (s): "
        + "; ".join(f"{k} " + ", ".join(f"{t:.1f}" for t in v) for k, v in times.items())
        + " (Dr.Jit caches compiled kernels, so only a first llvm run ever includes compilation).",
        f"Machine: {os.cpu_count()} cores ({platform.machine()}); load average {load_before:.1f} before, "
        f"{load_after:.1f} after; whole benchmark {total_s:.0f} s.",
    ]
    checks = []
    for r in rows:
        if r["what"] != "equal light paths":
            continue
        rms, worst, (tr, tc) = tile_check(luminance(r["rgb"]) * r["scale"], ref)
        checks.append(f"{r['renderer'].split()[0]} {r['variant']} {rms:.4f} (worst {worst:+.4f} at tile row {tr}, col {tc})")
    notes.append("Systematic differences: relative difference of 32×32-pixel tile means from the reference, RMS over "
                 "lit tiles: " + "; ".join(checks) + ". Equal values mean the renderers differ by noise only.")
    text = table + "\n\n" + "\n".join(f"* {n}" for n in notes) + "\n"
    print()
    print(text)
    args.results.write_text("# photon vs Mitsuba 3 ptracer (`bash bench/mitsuba/run.sh`)\n\n" + text)

    # 6. Pictures, all at one fixed exposure (from the reference) so that they compare by eye.
    exposure = 0.18 / float(np.exp(np.mean(np.log(ref[keep & (ref > 0)]))))
    write_png(args.out / "reference.png", ref_rgb, exposure)
    write_png(args.out / "photon.png", photon_rgb["default"], exposure)
    write_png(args.out / "photon_expected.png", photon_rgb["--estimator expected"], exposure)
    write_png(args.out / "photon_equal_time.png", photon_rgb["equal_time"], exposure)
    for m in mitsuba_runs:
        write_png(args.out / f"mitsuba_{m.variant}.png", best[m.variant]["rgb"] * m.scale, exposure)
    panels = [np.array(mi.Bitmap(str(args.out / n)), dtype=np.uint8)
              for n in ["photon.png", f"mitsuba_{mitsuba_runs[0].variant}.png", "reference.png"]]
    gap = np.zeros((panels[0].shape[0], 8, 3), dtype=np.uint8)
    strip = np.concatenate([panels[0], gap, panels[1], gap, panels[2]], axis=1)
    mi.Bitmap(np.ascontiguousarray(strip), mi.Bitmap.PixelFormat.RGB).write(str(args.out / "side_by_side.png"))
    print(f"images: {args.out}/*.png (side_by_side.png: photon | Mitsuba | reference); table: {args.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

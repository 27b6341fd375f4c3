#!/usr/bin/env python3
"""photon vs Mitsuba 3's `ptracer` on the glossy Cornell box: agreement within noise, tile by tile.

    bash bench/mitsuba/run.sh --scene glossy [options below, e.g. --runs 16 --spp 8]

(run.sh makes the virtual environment, builds photon and then runs this script instead of
compare.py). The scene is scenes/cornell_glossy.toml, built for Mitsuba by compare.py's
`mitsuba_scene_dict` (the same geometry, lamp, camera, film and box filter as the Lambertian
benchmark) with these materials (compare.py's `mitsuba_bsdf`):

* tall block, `conductor` metal "Al", GGX α 0.2 → `twosided` `roughconductor` (ggx, α 0.2,
  sample_visible), `eta` and `k` the same n, k table photon uses (spectra/metal_Al_nk.csv, an
  `irregular` spectrum; not Mitsuba's own "Al"), specular_reflectance 1;
* short block (the closed mesh scenes/meshes/cornell_short_block_closed.obj), `dielectric` ior 1.5,
  α 0.1 → `roughdielectric` (ggx, α 0.1, int_ior 1.5, ext_ior 1.0: photon's outside is exactly 1,
  Mitsuba's default air 1.000277);
* back wall, `plastic` (Cornell white under a coat of index 1.5, α 0.1) → `twosided` `roughplastic`
  (ggx, α 0.1, int_ior 1.5, ext_ior 1.0, nonlinear = true: photon's diffuse_reflectance is the
  base's own albedo, ρ/(1 − ρF̄));
* the other walls two-sided `diffuse`; every shape an OBJ with face_normals = true.

Both renderers trace the same number of light paths: `--runs` independent Mitsuba renders at
`--spp` (spp·512·512 paths each, seeds 1..runs) and as many photon runs of that many photons
(seeds 1..runs, its defaults). For every tile (`--tile`, 32×32 pixels by default) the mean
luminance Y = 0.2126 R + 0.7152 G + 0.0722 B of each run is taken; the difference of the two
renderers' run-averaged tile means, photon − c·Mitsuba, over its standard error from the spread of
the runs' tile means (σ² = s_p²/n_p + c² s_m²/n_m) is the tile's z. c = ∫ȳ(360–830)/∫ȳ(400–700)
= 1.0006 is the known difference of the two luminance normalisations (Mitsuba over 360–830 nm,
photon over the scene's 400–700 nm); the fitted global scale mean(photon)/mean(Mitsuba) is
reported beside it, so an energy mismatch shows in both.

Regions. A tile belongs to a glossy surface when more than half of its pixels see that surface
first (rays cast from the camera here, 2×2 per pixel): the aluminium block, the glass block, the
plastic back wall. Of the rest, "lamp" tiles see some of the lamp, "Lambertian only" tiles no
glossy surface at all, "mixed" tiles some glossy surface without a majority. Each region reports
its tiles, RMS z, max |z| and where, the fraction with |z| > 3, χ²/dof = mean z², and the ratio of
its summed Y, photon/(c·Mitsuba), with its standard error from the runs' spread.

What noise alone gives: with σ estimated from a finite number of runs, z follows Student's t
(Welch–Satterthwaite degrees of freedom) rather than a normal, and the glossy tiles' splats are
heavy-tailed besides. So each region also reports the t law's χ²/dof and |z| > 3 share and an
empirical null: each renderer's odd-numbered runs against its even-numbered ones.

A second table goes surface by surface, polygon by polygon (each quad, each face of the blocks,
the lamp): the ratio of the summed Y over the pixels wholly on it, and for the rough metal what
the two masking-shadowing functions alone predict (photon's height-correlated Smith G2, Mitsuba's
separable G1·G1, which part at grazing angles). The notes give the two rough plastics' coat
constants and the difference they predict (plastic_coat.py).

`--swap OLD=NEW` is a control: it makes every surface of material OLD of material NEW in both
renderers (e.g. `--swap white_plastic=white`: the back wall Lambertian, so that the plastic's
known difference, and the light it sends on, leave the conductor and the dielectric alone);
its table goes to results_glossy_swapped.md, its images to out/glossy_swapped/.

Writes bench/mitsuba/results_glossy.md (`--results`) and, under bench/mitsuba/out/glossy/, the
run-averaged images (photon.png, mitsuba.png at one exposure), the z map (zmap.png: red photon
brighter, blue darker, saturated at |z| = 4), the region map (regions.png), side_by_side.png
(photon | Mitsuba | z map, half resolution; `--docs-image` copies it) and runs.npz (every run's
luminance image and tile means, and what each pixel sees), for a closer look.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import compare  # noqa: E402  (the Lambertian benchmark: scene building, photon runs, images)
import plastic_coat  # noqa: E402  (the two rough plastics' coat constants)

ROOT = compare.ROOT
HERE = compare.HERE
SCENE = ROOT / "scenes" / "cornell_glossy.toml"
LAMBERTIAN = "Lambertian only"  # tiles that see no glossy surface (nor the lamp) at all
LAMP = "lamp"  # tiles that see some of the lamp: its direct emission, no BSDF
MIXED = "mixed"  # some glossy surface, none with a majority
ALL = "all lit tiles"


def glossy_regions(toml: dict) -> dict[str, str]:
    """surface name → region name, for every surface whose material is not Lambertian."""
    mats = toml["materials"]
    return {s["name"]: f"{s['name'].replace('_', ' ')}: {s['material']} ({mats[s['material']]['type']})"
            for s in toml["surfaces"] if mats[s["material"]]["type"] != "lambertian"}


def swapped_scene(swaps: list[str], out: Path) -> tuple[Path, dict]:
    """The scene with `--swap OLD=NEW` applied (every surface made of material OLD made of NEW),
    written to OUT/scene/ with its file paths made absolute; and its parsed table."""
    text = SCENE.read_text()
    for sw in swaps:
        old, new = sw.split("=")
        n = len(re.findall(rf'^material = "{re.escape(old)}"', text, flags=re.M))
        if n == 0:
            raise SystemExit(f"--swap {sw}: no surface is made of {old}")
        text = re.sub(rf'^material = "{re.escape(old)}"', f'material = "{new}"', text, flags=re.M)
    text = re.sub(r'file = "([^"]+)"', lambda m: f'file = "{(SCENE.parent / m.group(1)).resolve()}"', text)
    path = out / "scene" / f"{SCENE.stem}_swapped.toml"
    path.write_text(f"# {SCENE.name} with --swap {' '.join(swaps)} (bench/mitsuba/glossy.py)\n" + text)
    toml = compare.load_toml(path)
    if not set(toml["materials"]) >= {s["material"] for s in toml["surfaces"]}:
        raise SystemExit("--swap names a material the scene does not define")
    return path, toml


# --------------------------------------------------------------------------------------------
# What each pixel sees: a ray cast from photon's camera through the scene's triangles


def scene_triangles(toml: dict, scene_dir: Path) -> tuple[np.ndarray, list[str], list[int]]:
    """All triangles (n, 3, 3) in mm and, per triangle, the surface (or "lamp") it belongs to and
    the number of its polygon (a quad, or a face of an OBJ file) within that surface."""
    tris, names, polys = [], [], []

    def add_polygon(pts: list, name: str, k_poly: int) -> None:
        for k in range(1, len(pts) - 1):  # fan, as both renderers triangulate a quad
            tris.append([pts[0], pts[k], pts[k + 1]])
            names.append(name)
            polys.append(k_poly)

    for s in toml["surfaces"]:
        shape = s["shape"]
        if shape["type"] == "quad":
            add_polygon(shape["corners"], s["name"], 0)
        else:
            verts, n_face = [], 0
            for line in open((scene_dir / shape["file"]).resolve()):
                f = line.split()
                if not f:
                    continue
                if f[0] == "v":
                    verts.append([float(x) for x in f[1:4]])
                elif f[0] == "f":
                    add_polygon([verts[int(x.split("/")[0]) - 1] for x in f[1:]], s["name"], n_face)
                    n_face += 1
    for light in toml["lights"]:
        add_polygon(light["shape"]["corners"], "lamp", 0)
    return np.array(tris, dtype=np.float64), names, polys


class Hits:
    """What each of sub×sub camera rays per pixel hits first, for the scene's pinhole camera
    (horizontal field of view): `surf` (h, w, sub²) indexes `names` (−1: nothing), `poly` the
    polygon within that surface, `cos` |cosθ| between the ray and the polygon's normal."""

    def __init__(self, toml: dict, scene_dir: Path, sub: int = 2):
        cam = toml["camera"]
        w, h = cam["resolution"]
        o = np.array(cam["position"], dtype=np.float64)
        fwd = np.array(cam["look_at"], dtype=np.float64) - o
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, np.array(cam["up"], dtype=np.float64))
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        t = math.tan(math.radians(cam["fov_deg"]) / 2)
        offs = (np.arange(sub) + 0.5) / sub
        jj = np.arange(w)[None, :, None, None] + offs[None, None, None, :]  # column + x offset
        ii = np.arange(h)[:, None, None, None] + offs[None, None, :, None]  # row + y offset
        x = (2 * jj / w - 1) * t
        y = (1 - 2 * ii / h) * t * h / w
        x, y = np.broadcast_arrays(x, y)
        d = fwd + x[..., None] * right + y[..., None] * up
        d = d.reshape(-1, 3)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        tris, names, polys = scene_triangles(toml, scene_dir)
        best_t = np.full(len(d), np.inf)
        best = np.full(len(d), -1)
        for k, (a, b, c) in enumerate(tris):  # Möller–Trumbore, all rays at once
            e1, e2 = b - a, c - a
            p = np.cross(d, e2)
            det = p @ e1
            ok = np.abs(det) > 1e-12
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            s = o - a
            u = (p @ s) * inv
            q = np.cross(s, e1)
            v = (d @ q) * inv
            tt = (q @ e2) * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (tt > 1e-6) & (tt < best_t)
            best_t[hit] = tt[hit]
            best[hit] = k
        normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        self.names = sorted(set(names))
        surf = np.array([self.names.index(n) for n in names] + [-1])  # best = −1 → −1
        poly = np.array(polys + [-1])
        shape = (h, w, sub * sub)
        self.surf = surf[best].reshape(shape)
        self.poly = poly[best].reshape(shape)
        self.cos = np.where(best >= 0, np.abs(np.sum(normals[best] * d, axis=1)), 0.0).reshape(shape)

    def pure(self, surface: str, poly: int | None = None) -> np.ndarray:
        """(h, w) pixels whose every ray hits `surface` (and its polygon `poly`)."""
        m = self.surf == self.names.index(surface)
        if poly is not None:
            m &= self.poly == poly
        return m.all(axis=2)


def tile_regions(toml: dict, hits: Hits, tile: int) -> np.ndarray:
    """(h/tile, w/tile) array of region names. A tile belongs to a glossy surface when more than
    half of its pixels see it first; else to LAMP when some pixel sees the lamp; to LAMBERTIAN
    when none of its pixels sees any glossy surface; else to MIXED."""
    h, w, _ = hits.surf.shape
    ty, tx = h // tile, w // tile
    out = np.full((ty, tx), LAMBERTIAN, dtype=object)
    any_glossy = np.zeros((ty, tx))
    for surf, region in glossy_regions(toml).items():
        seen = hits.surf[: ty * tile, : tx * tile] == hits.names.index(surf)
        share = seen.reshape(ty, tile, tx, tile, -1).mean(axis=(1, 3, 4))
        any_glossy += share
        out[share > 0.5] = region
    out[(any_glossy > 0) & (out == LAMBERTIAN)] = MIXED
    lamp = (hits.surf[: ty * tile, : tx * tile] == hits.names.index("lamp")).reshape(ty, tile, tx, tile, -1).any(axis=(1, 3, 4))
    out[lamp & np.isin(out, [LAMBERTIAN, MIXED])] = LAMP
    return out


# --------------------------------------------------------------------------------------------
# Statistics


def tiles_of(y: np.ndarray, tile: int) -> np.ndarray:
    h, w = y.shape
    return y[: h // tile * tile, : w // tile * tile].reshape(h // tile, tile, w // tile, tile).mean(axis=(1, 3))


def t_tail(nu: float, x: float) -> float:
    """P(|T| > x) for Student's t with nu degrees of freedom (numerically; nu may be fractional)."""
    if not math.isfinite(nu) or nu > 1e4:
        return math.erfc(x / math.sqrt(2))
    logc = math.lgamma((nu + 1) / 2) - math.lgamma(nu / 2) - 0.5 * math.log(nu * math.pi)
    # ∫_x^∞ (1 + s²/ν)^(−(ν+1)/2) ds with s = x/u, u in (0, 1]: ds = x/u² du.
    u = (np.arange(200000) + 0.5) / 200000
    s = x / u
    f = np.exp(logc - (nu + 1) / 2 * np.log1p(s * s / nu)) * x / (u * u)
    return float(2 * f.mean())


def region_stats(z: np.ndarray, mask: np.ndarray, nu: np.ndarray) -> dict:
    zz = z[mask]
    n = int(mask.sum())
    if n == 0:
        return {"tiles": 0}
    k = np.unravel_index(np.argmax(np.where(mask, np.abs(z), -1)), z.shape)
    nu_m = float(np.median(nu[mask]))
    tail3 = np.mean([t_tail(v, 3.0) for v in nu[mask]])
    zmax = float(abs(z[k]))
    p_max = 1.0 - math.prod(1.0 - t_tail(v, zmax) for v in nu[mask])  # P(some tile ≥ |z|max)
    return {
        "tiles": n,
        "rms_z": float(np.sqrt(np.mean(zz**2))),
        "max_z": float(z[k]),
        "where": (int(k[0]), int(k[1])),
        "frac3": float(np.mean(np.abs(zz) > 3)),
        "chi2": float(np.mean(zz**2)),
        "nu": nu_m,
        "expect_chi2": float(np.mean([v / (v - 2) if v > 2 else np.inf for v in nu[mask]])),
        "expect_frac3": float(tail3),
        "p_max": float(p_max),
    }


def ratio_with_error(p_sums: np.ndarray, m_sums: np.ndarray, c: float) -> tuple[float, float]:
    """photon/(c·Mitsuba) of a region's summed Y, with its standard error from the runs' spread."""
    p, m = p_sums.mean(), m_sums.mean()
    vp = p_sums.var(ddof=1) / len(p_sums)
    vm = m_sums.var(ddof=1) / len(m_sums)
    r = p / (c * m)
    return float(r), float(r * math.sqrt(vp / p**2 + vm / m**2))


def smith_ratio(alpha: float, cos_o: np.ndarray, metal: str, wavelength: float = 550.0) -> float:
    """photon/Mitsuba of a rough metal's directional albedo, averaged over view cosines `cos_o`:
    E = ∫ f cosθ_i dω_i by visible-normal sampling (a 128×128 grid of the sampler's unit square),
    whose weight is F(ω_o·m)·G2/G1(ω_o) in photon (height-correlated) and F(ω_o·m)·G1(ω_i) in
    Mitsuba (separable). F from the bundled n, k at `wavelength`."""
    wl, n_, k_ = compare.read_nk(ROOT / "spectra" / f"metal_{metal}_nk.csv")
    eta = complex(np.interp(wavelength, wl, n_), np.interp(wavelength, wl, k_))
    u1, u2 = np.meshgrid((np.arange(128) + 0.5) / 128, (np.arange(128) + 0.5) / 128)
    u1, u2 = u1.ravel(), u2.ravel()

    def lam(w: np.ndarray) -> np.ndarray:
        return (np.sqrt(1 + alpha**2 * (w[:, 0] ** 2 + w[:, 1] ** 2) / w[:, 2] ** 2) - 1) / 2

    def fresnel(ci: np.ndarray) -> np.ndarray:
        ct = np.sqrt(1 - (1 - ci**2) / eta**2 + 0j)
        rp = (eta * ci - ct) / (eta * ci + ct)
        rs = (ci - eta * ct) / (ci + eta * ct)
        return 0.5 * (np.abs(rp) ** 2 + np.abs(rs) ** 2)

    def albedos(mu: float) -> tuple[float, float]:
        wo = np.array([math.sqrt(1 - mu * mu), 0.0, mu])
        wh = np.array([alpha * wo[0], 0.0, wo[2]])
        wh /= np.linalg.norm(wh)
        t1 = np.cross([0.0, 0.0, 1.0], wh)
        t1 = t1 / np.linalg.norm(t1) if np.linalg.norm(t1) > 1e-9 else np.array([1.0, 0.0, 0.0])
        t2 = np.cross(wh, t1)
        r, phi = np.sqrt(u1), 2 * np.pi * u2
        px, py = r * np.cos(phi), r * np.sin(phi)
        sv = 0.5 * (1 + wh[2])
        py = (1 - sv) * np.sqrt(np.maximum(0, 1 - px * px)) + sv * py
        pz = np.sqrt(np.maximum(0, 1 - px * px - py * py))
        nh = px[:, None] * t1 + py[:, None] * t2 + pz[:, None] * wh
        m = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 1e-6)], 1)
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        com = m @ wo
        wi = 2 * com[:, None] * m - wo
        up = wi[:, 2] > 1e-9
        wi_s = np.where(up[:, None], wi, [0.0, 0.0, 1.0])
        f = fresnel(com)
        lo, li = lam(wo[None, :]), lam(wi_s)
        e_p = np.where(up, f * (1 + lo) / (1 + lo + li), 0.0).mean()
        e_m = np.where(up, f / (1 + li), 0.0).mean()
        return float(e_p), float(e_m)

    mus = np.clip(np.asarray(cos_o, dtype=float), 0.02, 1.0)
    grid = np.linspace(0.02, 1.0, 50)
    table = np.array([albedos(x) for x in grid])
    e_p, e_m = np.interp(mus, grid, table[:, 0]), np.interp(mus, grid, table[:, 1])
    return float(e_p.sum() / e_m.sum())


# --------------------------------------------------------------------------------------------
# Pictures


def zmap_rgb(z: np.ndarray, tile: int, lit: np.ndarray) -> np.ndarray:
    """Tile z as colour: white 0, red positive (photon brighter), blue negative, saturated at 4;
    grey where unlit. (h, w, 3) in [0, 1] (display values, not linear)."""
    a = np.clip(z / 4.0, -1.0, 1.0)
    rgb = np.ones(z.shape + (3,))
    pos, neg = a > 0, a < 0
    rgb[pos, 1] -= a[pos]
    rgb[pos, 2] -= a[pos]
    rgb[neg, 0] += a[neg]
    rgb[neg, 1] += a[neg]
    rgb[~lit] = 0.5
    big = np.repeat(np.repeat(rgb, tile, axis=0), tile, axis=1)
    big[::tile, :] = 0.85  # tile grid
    big[:, ::tile] = 0.85
    return big


def to_u8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.round(x * 255.0), 0, 255).astype(np.uint8)


def tonemap(rgb: np.ndarray, exposure: float) -> np.ndarray:
    x = np.clip(rgb * exposure, 0.0, None)
    x = x / (1.0 + x)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def write_u8(mi, path: Path, img: np.ndarray) -> None:
    mi.Bitmap(np.ascontiguousarray(to_u8(img)), mi.Bitmap.PixelFormat.RGB).write(str(path))


# --------------------------------------------------------------------------------------------


def z_of(P: np.ndarray, M: np.ndarray, c: float, lit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tile z of run sets P (photon) and M (Mitsuba, times c), and the Welch–Satterthwaite ν."""
    n_p, n_m = len(P), len(M)
    a = P.var(axis=0, ddof=1) / n_p
    b = c * c * M.var(axis=0, ddof=1) / n_m
    sigma = np.sqrt(a + b)
    ok = lit & (sigma > 0)
    z = np.where(ok, (P.mean(axis=0) - c * M.mean(axis=0)) / np.where(ok, sigma, 1.0), 0.0)
    nu = (a + b) ** 2 / np.maximum(a**2 / (n_p - 1) + b**2 / (n_m - 1), 1e-300)
    return z, nu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--photon", type=Path, default=ROOT / "target" / "release" / "photon")
    ap.add_argument("--out", type=Path, default=None, help="default bench/mitsuba/out/glossy (…/glossy_swapped with --swap)")
    ap.add_argument("--spp", type=int, default=8, help="Mitsuba samples per pixel of each render; light paths per run = spp·512·512")
    ap.add_argument("--runs", type=int, default=16, help="independent runs of each renderer (seeds 1..runs)")
    ap.add_argument("--tile", type=int, default=32, help="tile size in pixels")
    ap.add_argument("--max-depth", type=int, default=-1, help="Mitsuba max_depth (-1: unbounded, like photon)")
    ap.add_argument("--variant", default="scalar_spectral", help="Mitsuba variant")
    ap.add_argument("--swap", action="append", default=[], metavar="OLD=NEW",
                    help="a control: surfaces of material OLD made of material NEW in both renderers "
                         "(e.g. white_plastic=white); repeatable")
    ap.add_argument("--results", type=Path, default=None,
                    help="default bench/mitsuba/results_glossy.md (results_glossy_swapped.md with --swap)")
    ap.add_argument("--docs-image", type=Path, default=None,
                    help="also copy side_by_side.png here (e.g. docs/mitsuba_glossy.png)")
    ap.add_argument("--conventions", choices=["photon", "mitsuba"], default="photon",
                    help="mitsuba: the --photon binary was built with the mitsuba-conventions feature "
                         "(separable Smith G, Mitsuba's rough-coat tables; run.sh --mitsuba-conventions)")
    args = ap.parse_args()
    if args.runs < 4:
        raise SystemExit("--runs must be at least 4 (the standard errors come from the runs' spread)")
    suffix = ("_swapped" if args.swap else "") + ("_mitsuba_conventions" if args.conventions == "mitsuba" else "")
    args.out = args.out or HERE / "out" / f"glossy{suffix}"
    args.results = args.results or HERE / f"results_glossy{suffix}.md"

    import mitsuba as mi

    t_start = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    work = args.out / "scene"
    work.mkdir(exist_ok=True)
    (args.out / "bin").mkdir(exist_ok=True)
    binary = args.out / "bin" / "photon"
    shutil.copy2(args.photon, binary)  # a private copy: a concurrent rebuild cannot swap it
    scene_file, toml = swapped_scene(args.swap, args.out) if args.swap else (SCENE, compare.load_toml(SCENE))
    w, h = toml["camera"]["resolution"]
    paths = args.spp * w * h
    load_before = os.getloadavg()[0]
    c = compare.cie_y_ratio()

    hits = Hits(toml, SCENE.parent)
    regions = tile_regions(toml, hits, args.tile)
    ty, tx = regions.shape
    region_order = list(glossy_regions(toml).values()) + [LAMBERTIAN, LAMP, MIXED, ALL]
    # Every surface polygon by polygon (a quad, an OBJ face, the lamp): the pixels wholly on it,
    # where there are at least 200.
    faces = []
    for surf in [x["name"] for x in toml["surfaces"]] + ["lamp"]:
        for k in sorted(set(hits.poly[hits.surf == hits.names.index(surf)].ravel())):
            mask = hits.pure(surf, k)
            if mask.sum() >= 200:
                faces.append({"surface": surf, "poly": int(k), "mask": mask, "pixels": int(mask.sum()),
                              "cos": float(hits.cos[mask].mean()), "cos_all": hits.cos[mask].ravel()})

    # Mitsuba's scene from the (possibly swapped) table; its files resolve against scenes/.
    m = compare.MitsubaRun(args.variant, toml, work, args.spp, args.max_depth, SCENE)
    runs: dict[str, dict] = {key: {"tiles": [], "faces": [], "y": [], "rgb": 0.0, "sec": [], "cpu": []}
                             for key in ("photon", "mitsuba")}

    def record(key: str, rgb: np.ndarray, sec: float, cpu: float) -> None:
        r = runs[key]
        y = compare.luminance(rgb)
        r["tiles"].append(tiles_of(y, args.tile))
        r["faces"].append([float(y[f["mask"]].sum()) for f in faces])
        r["y"].append(y.astype(np.float32))
        r["rgb"] = r["rgb"] + rgb / args.runs
        r["sec"].append(sec)
        r["cpu"].append(cpu)

    # Alternate the two renderers so that a change of the shared machine's load hits both alike.
    for k in range(1, args.runs + 1):
        print(f"[{k}/{args.runs}] photon: {paths:,} photons, seed {k} ...", end=" ", flush=True)
        p = compare.run_photon(binary, args.out / "photon_run", paths, k, scene=scene_file)
        rgb, _ = compare.read_exr_rgb(mi, args.out / "photon_run" / "image.exr")
        record("photon", rgb, p["wall_seconds"], p["cpu_seconds"])
        photon_version = p["version"]
        print(f"{p['wall_seconds']:.1f} s; mitsuba {mi.__version__} {args.variant}: spp {args.spp}, seed {k} ...",
              end=" ", flush=True)
        r = m.render(seed=k)
        record("mitsuba", r["rgb"], r["seconds"], r["cpu_seconds"])
        print(f"{r['seconds']:.1f} s", flush=True)
    load_after = os.getloadavg()[0]

    # Tile statistics.
    P = np.array(runs["photon"]["tiles"])  # (runs, ty, tx)
    M = np.array(runs["mitsuba"]["tiles"])
    p_mean, m_mean = P.mean(axis=0), M.mean(axis=0)
    lit = p_mean > 0.05 * p_mean.mean()
    z, nu = z_of(P, M, c, lit)
    fitted = float(p_mean.sum() / m_mean.sum())  # = mean(Y_photon)/mean(Y_mitsuba): tiles are equal in size
    z_fit, _ = z_of(P, M, fitted, lit)  # the same with the fitted scale instead of c
    # The empirical null: each renderer against itself, odd runs against even runs.
    z_pp, nu_half = z_of(P[0::2], P[1::2], 1.0, lit)
    z_mm, _ = z_of(M[0::2], M[1::2], 1.0, lit)
    # Everything measured, for a closer look: per-run tile means and luminance images.
    np.savez_compressed(args.out / "runs.npz", photon=P, mitsuba=M, z=z, nu=nu, lit=lit, regions=regions.astype(str),
                        c=c, photon_y=np.array(runs["photon"]["y"]), mitsuba_y=np.array(runs["mitsuba"]["y"]),
                        surf=hits.surf, poly=hits.poly, cos=hits.cos, names=np.array(hits.names))

    masks = {name: lit & (regions == name) for name in region_order if name != ALL}
    masks[ALL] = lit
    stats = {}
    for name in region_order:
        mask = masks[name]
        s = region_stats(z, mask, nu)
        if s["tiles"]:
            s["ratio"], s["ratio_se"] = ratio_with_error(P[:, mask].sum(axis=1), M[:, mask].sum(axis=1), c)
            s["ratio_z"] = (s["ratio"] - 1.0) / s["ratio_se"]
            s["chi2_fit"] = float(np.mean(z_fit[mask] ** 2))
            s["null_pp"] = region_stats(z_pp, mask, nu_half)
            s["null_mm"] = region_stats(z_mm, mask, nu_half)
        stats[name] = s
    g_ratio, g_se = ratio_with_error(P.sum(axis=(1, 2)), M.sum(axis=(1, 2)), c)
    FP, FM = np.array(runs["photon"]["faces"]), np.array(runs["mitsuba"]["faces"])
    mat_of = {x["name"]: x["material"] for x in toml["surfaces"]}
    face_lines = ["| surface | material | polygon | pixels | camera cosθ | mean Y ratio photon/Mitsuba | z | "
                  "G alone predicts |", "|---|---|---|---|---|---|---|---|"]
    for i, f in enumerate(faces):
        r, se = ratio_with_error(FP[:, i], FM[:, i], c)
        mname = mat_of.get(f["surface"], "(emitter)")
        mat = toml["materials"].get(mname, {})
        g = ""
        if mat.get("type") == "conductor" and "metal" in mat and mat.get("roughness", 0) > 0 \
                and args.conventions == "photon":
            g = f"{smith_ratio(float(mat['roughness']), f['cos_all'], mat['metal']):.4f}"
        face_lines.append(f"| {f['surface']} | {mname} | {f['poly']} | {f['pixels']} | {f['cos']:.2f} | "
                          f"{r:.4f} ± {se:.4f} | {(r - 1) / se:+.1f} | {g} |")
    face_table = "\n".join(face_lines)
    ps, ms = runs["photon"], runs["mitsuba"]
    header = ["region", "lit tiles", "RMS z", "max \\|z\\| (tile row, col)", "\\|z\\| > 3", "χ²/dof",
              "mean Y ratio photon/Mitsuba", "noise alone (t): χ²/dof, \\|z\\| > 3",
              "photon vs photon: χ²/dof, max \\|z\\|", "Mitsuba vs Mitsuba: χ²/dof, max \\|z\\|"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for name in region_order:
        s = stats[name]
        if not s["tiles"]:
            lines.append(f"| {name} | 0 |" + " |" * (len(header) - 2))
            continue
        npp, nmm = s["null_pp"], s["null_mm"]
        lines.append(
            f"| {name} | {s['tiles']} | {s['rms_z']:.2f} | {abs(s['max_z']):.2f} ({s['max_z']:+.2f} at {s['where'][0]}, "
            f"{s['where'][1]}) | {s['frac3']:.1%} | {s['chi2']:.2f} | "
            f"{s['ratio']:.4f} ± {s['ratio_se']:.4f} (z {s['ratio_z']:+.1f}) | "
            f"{s['expect_chi2']:.2f}, {s['expect_frac3']:.1%} | "
            f"{npp['chi2']:.2f}, {abs(npp['max_z']):.2f} | {nmm['chi2']:.2f}, {abs(nmm['max_z']):.2f} |"
        )
    table = "\n".join(lines)
    rev = os.environ.get("PHOTON_REV")
    built_here = [ROOT / "target" / "release" / "photon", ROOT / "target" / "mitsuba-conventions" / "release" / "photon"]
    default_binary = any(args.photon.resolve() == b.resolve() for b in built_here)
    photon_rev = f" (commit {rev})" if default_binary and rev else ""
    a_all = stats[ALL]
    swapped = f" with --swap {' '.join(args.swap)} in both renderers" if args.swap else ""
    notes = [
        f"Scene scenes/cornell_glossy.toml{swapped}; photon {photon_version}{photon_rev} with its defaults (`photon "
        f"run`, hero wavelengths, `--estimator auto`), {args.runs} runs × {paths:,} photons, seeds 1–{args.runs}; "
        f"Mitsuba {mi.__version__} `{args.variant}` `ptracer` (max_depth {args.max_depth}, rr_depth 5, independent "
        f"sampler, box filter), {args.runs} renders × spp {args.spp} = {paths:,} light paths, seeds 1–{args.runs}: "
        f"{args.runs * paths:,} light paths each in all.",
        f"Tiles {args.tile}×{args.tile} pixels ({ty}×{tx}); lit: photon's tile mean above 5 % of the image mean. "
        "z = (Ȳ_photon − c·Ȳ_Mitsuba)/σ per tile, σ² the sum of both run-averages' squared standard errors from the "
        f"spread of the {args.runs} runs' tile means; c = ∫ȳ(360–830 nm)/∫ȳ(400–700 nm) = {c:.4f}. χ²/dof = mean z² "
        "over the region's tiles.",
        "Regions: a tile belongs to a glossy surface when more than half of its pixels (2×2 camera rays each, cast "
        f"here through the scene's triangles) see that surface first; '{LAMBERTIAN}' tiles see no glossy surface at "
        f"all (walls, floor, ceiling); '{LAMP}' tiles see some of the lamp (whose emission outweighs the rest); "
        f"'{MIXED}' tiles some glossy surface, none with a majority. The ratio column is the region's summed Y, "
        "photon/(c·Mitsuba), with its standard error from the runs' spread.",
        f"What noise alone gives. With σ estimated from {args.runs} runs, z is Student-t with the Welch–Satterthwaite "
        f"degrees of freedom (median {a_all['nu']:.0f} here), so χ²/dof is expected near ν/(ν − 2), not 1, and "
        "|z| > 3 more often than a normal's 0.27 %: the '(t)' column. The glossy tiles' splats are heavy-tailed, "
        "which the t law does not capture; the last two columns are the empirical null: each renderer's odd-numbered "
        "runs against its even-numbered ones (half the runs each, ν about half). The chance that t noise gives some "
        "tile a |z| at least the largest seen: "
        + ", ".join(f"{k} {stats[k]['p_max']:.2f}" for k in region_order if stats[k]["tiles"]) + ".",
        "Surface by surface (the second table): the pixels wholly on one polygon (all 2×2 rays), their summed Y, "
        "photon/(c·Mitsuba), with its standard error from the runs' spread. 'G alone predicts', for a rough metal: "
        "the ratio of its directional albedo at those pixels' camera angles, photon's height-correlated Smith G2 = "
        "1/(1 + Λ_o + Λ_i) against Mitsuba's separable G1(ω_o)·G1(ω_i) (the only form Mitsuba 3 has), equal near "
        "the normal, photon up to a few % brighter where both directions are grazing. The lamp's pixels see its "
        "emission alone: their ratio checks c.",
        f"Global: mean Y photon/(c·Mitsuba) = {g_ratio:.4f} ± {g_se:.4f}; the fitted global scale mean(Y_photon)/"
        f"mean(Y_Mitsuba) = {fitted:.4f} against the expected c = {c:.4f}. With the fitted scale instead of c, "
        "χ²/dof is " + ", ".join(f"{k} {stats[k]['chi2_fit']:.2f}" for k in region_order if stats[k]["tiles"]) + ".",
        f"Seconds per run: photon {np.mean(ps['sec']):.1f} (wall, tracing; {sum(ps['sec']):.0f} in all, "
        f"{args.runs * paths / sum(ps['sec']):,.0f} paths/s), Mitsuba {np.mean(ms['sec']):.1f} (`mi.render`; "
        f"{sum(ms['sec']):.0f} in all, {args.runs * paths / sum(ms['sec']):,.0f} paths/s).",
        f"Machine: {os.cpu_count()} cores ({platform.machine()}); load average {load_before:.1f} before, "
        f"{load_after:.1f} after; whole benchmark {time.perf_counter() - t_start:.0f} s.",
    ]
    used = {s["material"] for s in toml["surfaces"]}
    plastics = [v for k, v in toml["materials"].items() if v["type"] == "plastic" and k in used and v.get("roughness", 0) > 0]
    if args.conventions == "mitsuba":
        notes.insert(1, "photon here is built with `--features mitsuba-conventions` (bench only): Mitsuba 3's "
                     "separable Smith G1(ω_o)·G1(ω_i) instead of its height-correlated G2, and Mitsuba's rough-coat "
                     "tables for the plastic (its transmittance ∫D_vis(1 − F)G1(ω_t), which loses the refracted "
                     "ray's masking, and F̄_int = 2·mean(E μ)), so that the two renderers evaluate the same BSDFs "
                     "and any difference left is transport.")
    elif plastics:
        pl = plastics[0]
        coat = plastic_coat.predict(float(pl.get("ior", 1.5)), float(pl["roughness"]))
        notes.insert(5, "The two rough plastics differ by construction (bench/mitsuba/plastic_coat.py): "
                     + plastic_coat.summary(coat) + ". So photon's plastic should come out brighter in its diffuse "
                     f"light, by {(coat['f_int_share'] - 1):.1%} from F̄_int and up to {(coat['base_ratio'] - 1):.1%} "
                     "with t(θ_i) (whose ratio grows toward grazing light), less the share of the coat's own "
                     "reflection; and the light it sends on brightens the rest of the room a little.")
    text = table + "\n\n" + face_table + "\n\n" + "\n".join(f"* {x}" for x in notes) + "\n"
    print()
    print(text)
    title = "photon vs Mitsuba 3 ptracer on the glossy Cornell box" \
        + (", photon built with Mitsuba's microfacet conventions" if args.conventions == "mitsuba" else "")
    cmd = "bash bench/mitsuba/run.sh --scene glossy" + "".join(f" --swap {sw}" for sw in args.swap) \
        + (" --mitsuba-conventions" if args.conventions == "mitsuba" else "")
    args.results.write_text(f"# {title}{swapped} (`{cmd}`)\n\n" + text)

    # Pictures, at one exposure.
    y_ref = compare.luminance(ps["rgb"])
    lamp = y_ref > 20.0 * np.mean(y_ref)
    keep = ~lamp & (y_ref > 0)
    exposure = 0.18 / float(np.exp(np.mean(np.log(y_ref[keep]))))
    ph = tonemap(ps["rgb"], exposure)
    mt = tonemap(ms["rgb"] * c, exposure)
    zm = zmap_rgb(z, args.tile, lit)
    write_u8(mi, args.out / "photon.png", ph)
    write_u8(mi, args.out / "mitsuba.png", mt)
    write_u8(mi, args.out / "zmap.png", zm)
    colours = [(0.75, 0.75, 0.8), (0.4, 0.8, 0.9), (0.95, 0.9, 0.6), (0.9, 0.6, 0.9)]
    reg_img = np.full((h, w, 3), 0.3)
    first = hits.surf[..., 0]
    for (sname, _), col in zip(glossy_regions(toml).items(), colours):
        reg_img[first == hits.names.index(sname)] = col
    reg_img[first == hits.names.index("lamp")] = 1.0
    reg_tiles = np.repeat(np.repeat(regions, args.tile, axis=0), args.tile, axis=1)
    reg_img[::args.tile, :] = 0
    reg_img[:, ::args.tile] = 0
    reg_img[(reg_tiles == MIXED) & ((np.indices((h, w)).sum(axis=0) % 8) == 0)] = 0.0  # hatch the mixed tiles
    write_u8(mi, args.out / "regions.png", reg_img)

    def half(x: np.ndarray) -> np.ndarray:
        return x.reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3))

    gap = np.ones((h // 2, 4, 3))
    strip = np.concatenate([half(ph), gap, half(mt), gap, half(zm)], axis=1)
    write_u8(mi, args.out / "side_by_side.png", strip)
    if args.docs_image:
        shutil.copy2(args.out / "side_by_side.png", args.docs_image)
    print(f"images: {args.out}/*.png (side_by_side.png: photon | Mitsuba | z map); table: {args.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

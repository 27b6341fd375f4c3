#!/usr/bin/env python3
"""The rough plastic's coat constants in photon and in Mitsuba 3, and the difference they predict.

    bench/mitsuba/.venv/bin/python bench/mitsuba/plastic_coat.py [--ior 1.5 --alpha 0.1]

Both models are f = f_s + ρ/(1 − ρF̄_int) · t(θ_i) t(θ_o) / (π η²) (`roughplastic`, nonlinear), but
their tables differ:

* photon (src/bsdf/plastic.rs, re-done here in numpy): t(μ) = 1 − E_r(μ), E_r the directional
  albedo of the coat's GGX reflection (height-correlated G2); F̄_int = 2∫E_r,int(μ) μ dμ and
  1 − F̄_ext = 2∫t μ dμ by the trapezoid rule on the 64 points μ = k/63.
* Mitsuba 3.9.1 (read here from its own `roughplastic` through `eval` of the diffuse component):
  T(μ) = ∫ D_vis (1 − F) G1(refracted) dm, so the refracted ray's masking counts as a loss;
  F̄_int = 2·mean(E_int(μ_k) μ_k) over the 64 points, which weights the end points fully and so
  comes out about 1/64 low.

The base's share, A(ρ) = ρ (1 − F̄_ext)/(η² (1 − ρ F̄_int)), is printed for both, per wavelength of
the Cornell white and averaged with the lamp's spectrum times ȳ as weight.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import compare  # noqa: E402

TABLE = 64


def fresnel(c: np.ndarray, eta_i: float, eta_t: float) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    s2 = (eta_i / eta_t) ** 2 * (1 - c * c)
    ct = np.sqrt(np.maximum(0.0, 1 - s2))
    with np.errstate(invalid="ignore", divide="ignore"):
        rs = (eta_i * c - eta_t * ct) / (eta_i * c + eta_t * ct)
        rp = (eta_t * c - eta_i * ct) / (eta_t * c + eta_i * ct)
    return np.where(s2 >= 1, 1.0, 0.5 * (rs * rs + rp * rp))


def photon_coat(eta: float, alpha: float) -> dict:
    """photon's coat: the tables and averages of plastic.rs (`rough_reflectance`, `Coat::rough`)."""

    def lam(w: np.ndarray) -> np.ndarray:
        return (np.sqrt(1 + alpha**2 * (w[..., 0] ** 2 + w[..., 1] ** 2) / w[..., 2] ** 2) - 1) / 2

    def rough_reflectance(mu: float, eta_i: float, eta_t: float, nv: int = 256, nphi: int = 64) -> float:
        wo = np.array([math.sqrt(max(0.0, 1 - mu * mu)), 0.0, mu])
        v = (np.arange(nv) + 0.5) / nv
        tan = alpha * np.sqrt(v / (1 - v))
        cm = 1 / np.sqrt(1 + tan * tan)
        sm = tan * cm
        phi = 2 * np.pi * (np.arange(nphi) + 0.5) / nphi
        m = np.stack([sm[:, None] * np.cos(phi), sm[:, None] * np.sin(phi), np.broadcast_to(cm[:, None], (nv, nphi))], -1)
        com = m @ wo
        wi = 2 * com[..., None] * m - wo
        ok = (com > 0) & (wi[..., 2] > 0)
        g2 = 1 / (1 + lam(wo) + lam(np.where(ok[..., None], wi, np.array([0.0, 0.0, 1.0]))))
        f = fresnel(np.minimum(com, 1.0), eta_i, eta_t)
        return float(np.where(ok, f * g2 * com / (cm[:, None] * mu), 0.0).sum() / (nv * nphi))

    mu = np.maximum(np.arange(TABLE) / (TABLE - 1), 1e-6)
    t = np.array([1 - rough_reflectance(x, 1.0, eta) for x in mu])
    e_int = np.array([rough_reflectance(x, eta, 1.0) for x in mu])
    return {"mu": mu, "t": t, "f_int": trapezoid_average(e_int), "one_minus_f_ext": trapezoid_average(t),
            "f_int_mitsuba_rule": float(2 * np.mean(e_int * mu))}


def trapezoid_average(g: np.ndarray) -> float:
    """2∫g(μ) μ dμ by the trapezoid rule on μ = k/63 (plastic.rs)."""
    h = 1 / (TABLE - 1)
    w = np.ones(TABLE)
    w[0] = w[-1] = 0.5
    return float((g * np.arange(TABLE) * h * w).sum() * 2 * h)


def mitsuba_coat(eta: float, alpha: float) -> dict:
    """Mitsuba's coat, read back from `roughplastic.eval` of its diffuse component:
    f_d(μ_i, μ_o) = ρ/(1 − ρ F̄_int) T(μ_i) T(μ_o) / (π η²) at two ρ gives F̄_int, then T."""
    import mitsuba as mi

    mi.set_variant("scalar_spectral")
    ctx = mi.BSDFContext()
    ctx.component = 1  # the diffuse component only

    def bsdf(rho: float):
        return mi.load_dict({"type": "roughplastic", "distribution": "ggx", "alpha": alpha, "int_ior": eta,
                             "ext_ior": 1.0, "nonlinear": True, "diffuse_reflectance": {"type": "uniform", "value": rho}})

    def f(b, ci: float, co: float) -> float:
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(math.sqrt(max(0.0, 1 - ci * ci)), 0, ci)
        si.wavelengths = mi.Spectrum([550.0] * 4)
        wo = mi.Vector3f(-math.sqrt(max(0.0, 1 - co * co)), 0, co)
        return float(np.array(b.eval(ctx, si, wo))[0]) / co  # eval includes cosθ_o

    b1, b2 = bsdf(0.5), bsdf(0.9)
    f1, f2 = f(b1, 1, 1), f(b2, 1, 1)
    f_int = (f2 / 0.9 - 2 * f1) / (f2 - f1)  # from f1 (1 − 0.5F)/0.5 = f2 (1 − 0.9F)/0.9
    k = f1 * (1 - 0.5 * f_int) / 0.5 * math.pi * eta**2  # T(1)²
    t1 = math.sqrt(k)
    mu = np.maximum(np.arange(TABLE) / (TABLE - 1), 1e-6)
    t = np.array([f(b1, max(x, 1e-4), 1) * (1 - 0.5 * f_int) / 0.5 * math.pi * eta**2 / t1 for x in mu])
    return {"mu": mu, "t": t, "f_int": float(f_int), "one_minus_f_ext": trapezoid_average(t)}


def base_albedo(rho: np.ndarray, c: dict, eta: float) -> np.ndarray:
    return rho * c["one_minus_f_ext"] / (eta**2 * (1 - rho * c["f_int"]))


def predict(eta: float = 1.5, alpha: float = 0.1) -> dict:
    """Both coats and the ratio photon/Mitsuba of the base's share A(ρ) for the Cornell white,
    weighted over 400–700 nm by the lamp's spectrum times ȳ."""
    p, m = photon_coat(eta, alpha), mitsuba_coat(eta, alpha)
    wl = np.arange(400.0, 701.0)
    rho = np.interp(wl, *compare.read_csv(compare.ROOT / "spectra" / "cornell_white.csv"))
    lamp = np.interp(wl, *compare.read_csv(compare.ROOT / "spectra" / "cornell_light.csv"))
    cie = np.loadtxt(compare.ROOT / "spectra" / "cie1931_2deg_xyz.csv", delimiter=",", skiprows=1)
    ybar = np.interp(wl, cie[:, 0], cie[:, 2])
    wgt = lamp * ybar
    ratio = float((base_albedo(rho, p, eta) * wgt).sum() / (base_albedo(rho, m, eta) * wgt).sum())
    fint_ratio = float(((1 - rho * m["f_int"]) / (1 - rho * p["f_int"]) * wgt).sum() / wgt.sum())
    return {"photon": p, "mitsuba": m, "base_ratio": ratio, "f_int_share": fint_ratio,
            "f_ext_share": p["one_minus_f_ext"] / m["one_minus_f_ext"]}


def summary(r: dict) -> str:
    p, m = r["photon"], r["mitsuba"]
    k = {x: int(np.argmin(np.abs(p["mu"] - x))) for x in (1.0, 0.5, 0.25)}
    return (
        f"F̄_int photon {p['f_int']:.4f}, Mitsuba {m['f_int']:.4f} (photon's own table under Mitsuba's rule "
        f"2·mean(E μ): {p['f_int_mitsuba_rule']:.4f}); 1 − F̄_ext photon {p['one_minus_f_ext']:.4f}, Mitsuba "
        f"{m['one_minus_f_ext']:.4f}; t(μ) photon/Mitsuba "
        + ", ".join(f"{p['t'][i] / m['t'][i]:.4f} at μ = {p['mu'][i]:.2f}" for i in k.values())
        + f". The base's share A(ρ) of the Cornell white, photon/Mitsuba: {r['base_ratio']:.4f} "
        f"(1/(1 − ρF̄_int) {r['f_int_share']:.4f} × 1 − F̄_ext {r['f_ext_share']:.4f})"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ior", type=float, default=1.5)
    ap.add_argument("--alpha", type=float, default=0.1)
    args = ap.parse_args()
    print(summary(predict(args.ior, args.alpha)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

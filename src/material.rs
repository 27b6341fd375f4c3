//! What happens at a hit: absorb, or scatter into a new direction. Analog decisions: the photon
//! survives with probability equal to the albedo, so each photon's power ends in one place.

use glam::Vec3A;

use crate::sampling::{cosine_hemisphere, Sampler};
use crate::scene::Material;

pub enum Interaction {
    Absorbed,
    Scattered(Vec3A),
}

/// Unpolarised Fresnel reflectance of a smooth boundary, (R_s + R_p)/2 with
/// r_s = (η_i cosθ_i − η_t cosθ_t)/(η_i cosθ_i + η_t cosθ_t), r_p = (η_t cosθ_i − η_i cosθ_t)/(η_t cosθ_i + η_i cosθ_t);
/// 1 beyond the critical angle. Returns (R, cosθ_t).
#[inline]
pub fn fresnel_dielectric(cos_i: f64, eta_i: f64, eta_t: f64) -> (f64, f64) {
    let sin_i2 = (1.0 - cos_i * cos_i).max(0.0);
    let sin_t2 = (eta_i / eta_t).powi(2) * sin_i2;
    if sin_t2 >= 1.0 {
        return (1.0, 0.0);
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    let rp = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    (0.5 * (rs * rs + rp * rp), cos_t)
}

/// Mirror reflection of `d` about the plane with normal `n`: d − 2(d·n)n.
#[inline]
pub fn reflect(d: Vec3A, n: Vec3A) -> Vec3A {
    (d - 2.0 * d.dot(n) * n).normalize()
}

/// Decides the photon's fate at a hit. `d` is the travel direction, `n` the unit geometric normal.
#[inline]
pub fn interact(m: &Material, lambda_nm: f64, d: Vec3A, n: Vec3A, s: &mut Sampler) -> Interaction {
    // Normal on the side the photon arrives from.
    let cos_dn = d.dot(n);
    let n_in = if cos_dn < 0.0 { n } else { -n };
    match m {
        Material::Absorber => Interaction::Absorbed,
        Material::Lambertian { reflectance, transmittance } => {
            let rho = reflectance.eval(lambda_nm);
            let tau = transmittance.eval(lambda_nm);
            let u = s.uniform();
            if u < rho {
                Interaction::Scattered(cosine_hemisphere(n_in, s.uniform_f32(), s.uniform_f32()))
            } else if u < rho + tau {
                Interaction::Scattered(cosine_hemisphere(-n_in, s.uniform_f32(), s.uniform_f32()))
            } else {
                Interaction::Absorbed
            }
        }
        Material::Mirror { reflectance } => {
            if s.uniform() < reflectance.eval(lambda_nm) {
                Interaction::Scattered(reflect(d, n))
            } else {
                Interaction::Absorbed
            }
        }
        Material::Dielectric { ior, outside_ior, .. } => {
            let (n_out, n_inside) = (outside_ior.eval(lambda_nm), ior.eval(lambda_nm));
            let (eta_i, eta_t) = if cos_dn < 0.0 { (n_out, n_inside) } else { (n_inside, n_out) };
            let cos_i = (cos_dn.abs() as f64).min(1.0);
            let (r, cos_t) = fresnel_dielectric(cos_i, eta_i, eta_t);
            if s.uniform() < r {
                Interaction::Scattered(reflect(d, n))
            } else {
                // Snell refraction: t = η d + (η cosθ_i − cosθ_t) n_in, η = η_i/η_t.
                let eta = (eta_i / eta_t) as f32;
                let t = eta * d + (eta * cos_i as f32 - cos_t as f32) * n_in;
                Interaction::Scattered(t.normalize())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_normal_incidence_and_tir() {
        // R(0) = ((n−1)/(n+1))², 0.04 for n = 1.5.
        let (r, _) = fresnel_dielectric(1.0, 1.0, 1.5);
        assert!((r - 0.04).abs() < 1e-12);
        // Beyond the critical angle asin(1/1.5) = 41.8° from glass to air: total reflection.
        let (r, _) = fresnel_dielectric(45f64.to_radians().cos(), 1.5, 1.0);
        assert_eq!(r, 1.0);
    }
}

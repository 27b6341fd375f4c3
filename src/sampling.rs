//! Random numbers and the sampling routines every estimator shares. Each routine names the pdf
//! it realises, so an estimator's f/p can be read off.

use glam::Vec3A;
use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rand_xoshiro::{SplitMix64, Xoshiro256PlusPlus};

use crate::geometry::basis;

/// The random stream of one batch: Xoshiro256++ seeded from (run seed, batch index) through
/// SplitMix64, so each batch's photons are the same whichever thread runs it.
pub struct Sampler {
    rng: Xoshiro256PlusPlus,
}

/// Each integrator's stream of a batch (`Sampler::for_stream`), so no two share random numbers
/// and at one seed their images are independent estimates.
pub const PARTICLE_STREAM: u64 = 0;
pub const PATH_STREAM: u64 = 1;
pub const BDPT_STREAM: u64 = 2;

impl Sampler {
    /// The particle tracer's stream of a batch.
    pub fn for_batch(seed: u64, batch: u64) -> Self {
        Self::for_stream(seed, PARTICLE_STREAM, batch)
    }

    /// Stream `stream` of a batch (`PARTICLE_STREAM`, `PATH_STREAM`, `BDPT_STREAM`).
    pub fn for_stream(seed: u64, stream: u64, batch: u64) -> Self {
        let mut mix = SplitMix64::seed_from_u64(seed);
        let key =
            mix.next_u64() ^ batch.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03);
        Sampler { rng: Xoshiro256PlusPlus::seed_from_u64(key) }
    }

    /// Uniform in [0, 1) with 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [0, 1) as f32 (24 random bits), for directions and positions.
    #[inline]
    pub fn uniform_f32(&mut self) -> f32 {
        (self.rng.next_u64() >> 40) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

/// (sin 2πu, cos 2πu) for u in [0, 1], the azimuth of every direction sampler here, without a
/// call to libm (which cost ~80 instructions a call, 5 calls a photon). The quarter turn
/// nearest 4u is exact in f32 (q = round(4u), r = 4u − q in [−½, ½]); sin and cos of (π/2)r
/// are least-squares polynomials on that interval (|error| < 1e-7 evaluated in f32); q quarter
/// turns then swap and negate them bit-wise, so a random quadrant mispredicts no branch.
#[inline]
pub fn sin_cos_turn(u: f32) -> (f32, f32) {
    // S[0] is the fit's own coefficient, one f32 ulp below π/2 (what clippy takes it for).
    #[allow(clippy::approx_constant)]
    const S: [f32; 4] = [1.570_796_3, -0.645_963_5, 0.079_680_22, -0.004_602_153];
    const C: [f32; 4] = [-1.233_700_5, 0.253_669_24, -0.020_860_264, 0.000_903_974_7];
    let four_u = 4.0 * u;
    // u ≥ 0, so truncation rounds down.
    let q = (four_u + 0.5) as i32 as u32;
    let r = four_u - q as f32;
    let x = r * r;
    let s = r * (S[0] + x * (S[1] + x * (S[2] + x * S[3])));
    let c = 1.0 + x * (C[0] + x * (C[1] + x * (C[2] + x * C[3])));
    // By quarter turns (s, c) → (c, −s) → (−s, −c) → (−c, s): swap when q is odd, negate the
    // sine for q = 2, 3 and the cosine for q = 1, 2.
    let swap = 0u32.wrapping_sub(q & 1);
    let (sb, cb) = (s.to_bits(), c.to_bits());
    let sin = (sb & !swap) | (cb & swap);
    let cos = (cb & !swap) | (sb & swap);
    (f32::from_bits(sin ^ ((q & 2) << 30)), f32::from_bits(cos ^ (((q + 1) & 2) << 30)))
}

/// Point `index` of a scrambled 2-D Sobol sequence (the (0,2)-sequence: van der Corput's radical
/// inverse and Sobol's second dimension), each coordinate Owen-scrambled by `seed` with the hash
/// of Burley 2020 ("Practical Hash-based Owen Scrambling", after Laine and Karras 2011). Each point
/// is uniform on [0,1)² over the seeds, and the first 2^m points of one seed put one point in every
/// cell of each 2^a × 2^(m−a) grid: a pixel's successive samples cover its footprint evenly.
#[inline]
pub fn owen_sobol_2d(index: u32, seed: u32) -> (f32, f32) {
    let x = index.reverse_bits();
    // Sobol's second dimension: direction numbers v₀ = 2³¹, v_{i+1} = v_i ^ (v_i >> 1).
    let (mut y, mut v, mut bits) = (0u32, 1u32 << 31, index);
    while bits != 0 {
        if bits & 1 != 0 {
            y ^= v;
        }
        v ^= v >> 1;
        bits >>= 1;
    }
    // A coordinate's leading bits are scrambled by its seed's low bits: each coordinate's seed is
    // a full-avalanche hash of `seed`, so those bits are unrelated between x and y (seeds that
    // shared low bits put every point of a seed set on 16 of 256 cells).
    let unit = |bits: u32| (bits >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
    (unit(owen_scramble(x, mix32(seed))), unit(owen_scramble(y, mix32(seed ^ 0x5BD1_E995))))
}

/// A 32-bit integer hash in which every input bit affects every output bit (Wellons's lowbias32).
#[inline]
fn mix32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// Nested uniform scrambling of the bits of `x`, most significant first (each bit flipped by a
/// hash of the bits above it): the Laine–Karras hash on the reversed bits (Burley 2020, fig. 4).
#[inline]
fn owen_scramble(x: u32, seed: u32) -> u32 {
    let mut v = x.reverse_bits().wrapping_add(seed);
    v ^= v.wrapping_mul(0x6c50_b47c);
    v ^= v.wrapping_mul(0xb82f_1e52);
    v ^= v.wrapping_mul(0xc7af_e638);
    v ^= v.wrapping_mul(0x8d22_f6e6);
    v.reverse_bits()
}

/// Cosine-weighted direction about unit `n`: p(ω) = cosθ/π (Malley's method via the concentric-free
/// polar map: r = √u1, φ = 2πu2, z = √(1−u1)).
#[inline]
pub fn cosine_hemisphere(n: Vec3A, u1: f32, u2: f32) -> Vec3A {
    let r = u1.sqrt();
    let (sin_phi, cos_phi) = sin_cos_turn(u2);
    let z = (1.0 - u1).max(0.0).sqrt();
    local_to_world(n, r * cos_phi, r * sin_phi, z)
}

/// Direction with p(ω) = (n+1)/(2π)·cosⁿθ about `axis`: cosθ = u1^(1/(n+1)).
#[inline]
pub fn cosine_power_lobe(axis: Vec3A, exponent: f32, u1: f32, u2: f32) -> Vec3A {
    let cos_t = u1.powf(1.0 / (exponent + 1.0));
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let (sin_phi, cos_phi) = sin_cos_turn(u2);
    local_to_world(axis, sin_t * cos_phi, sin_t * sin_phi, cos_t)
}

/// Uniform over the hemisphere about `n`: p(ω) = 1/(2π), cosθ = u1.
#[inline]
pub fn uniform_hemisphere(n: Vec3A, u1: f32, u2: f32) -> Vec3A {
    let cos_t = u1;
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let (sin_phi, cos_phi) = sin_cos_turn(u2);
    local_to_world(n, sin_t * cos_phi, sin_t * sin_phi, cos_t)
}

/// Uniform over the sphere: p(ω) = 1/(4π), z = 1 − 2u1.
#[inline]
pub fn uniform_sphere(u1: f32, u2: f32) -> Vec3A {
    let z = 1.0 - 2.0 * u1;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (sin_phi, cos_phi) = sin_cos_turn(u2);
    Vec3A::new(r * cos_phi, r * sin_phi, z)
}

/// The direction (x, y, z) of a frame whose z axis is unit `n`, in world coordinates. The frame
/// is orthonormal to rounding and every caller passes a unit (x, y, z), so the result is unit to a
/// few ulp without normalising: that sqrt and division sat on each bounce's critical path.
#[inline]
pub fn local_to_world(n: Vec3A, x: f32, y: f32, z: f32) -> Vec3A {
    let (t, s) = basis(n);
    x * t + y * s + z * n
}

/// Uniform point on a triangle: barycentrics (1−√u1, √u1(1−u2), √u1·u2), p = 1/area.
#[inline]
pub fn uniform_triangle(u1: f32, u2: f32) -> [f32; 3] {
    let su = u1.sqrt();
    let b1 = su * (1.0 - u2);
    let b2 = su * u2;
    [1.0 - b1 - b2, b1, b2]
}

/// A discrete distribution over indices, sampled by inverse CDF (binary search).
#[derive(Clone, Debug)]
pub struct Discrete {
    cdf: Vec<f64>,
}

impl Discrete {
    /// `weights` non-negative with a positive sum.
    pub fn new(weights: &[f64]) -> Self {
        let total: f64 = weights.iter().sum();
        let mut acc = 0.0;
        let cdf = weights
            .iter()
            .map(|w| {
                acc += w;
                acc / total
            })
            .collect();
        Discrete { cdf }
    }

    /// Index i with probability weights[i]/Σweights.
    #[inline]
    pub fn sample(&self, u: f64) -> usize {
        self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_turn_matches_libm() {
        // Every u = k/2^20 (all quadrants, their boundaries and both ends) against f64 sin/cos:
        // the polynomials err by < 1e-7 and f32 evaluation adds about one rounding (6e-8).
        let mut worst = 0.0f64;
        for k in 0..=(1u32 << 20) {
            let u = k as f32 / (1u32 << 20) as f32;
            let (s, c) = sin_cos_turn(u);
            let phi = std::f64::consts::TAU * u as f64;
            worst = worst.max((s as f64 - phi.sin()).abs()).max((c as f64 - phi.cos()).abs());
        }
        assert!(worst < 2e-7, "worst error {worst}");
        // The quadrant rotation's signs and swaps, where a wrong one would be far off.
        for (u, s, c) in [(0.0, 0.0, 1.0), (0.25, 1.0, 0.0), (0.5, 0.0, -1.0), (0.75, -1.0, 0.0), (1.0, 0.0, 1.0)] {
            let (ps, pc) = sin_cos_turn(u);
            assert!((ps - s).abs() < 1e-7 && (pc - c).abs() < 1e-7, "u {u}: ({ps}, {pc})");
        }
    }

    /// The first 2^m points of a seed fill every cell of every 2^a × 2^(m−a) grid once (the
    /// (0,2)-sequence's net property, which nested scrambling keeps), for m up to 8 and many seeds.
    #[test]
    fn scrambled_sobol_prefixes_are_nets() {
        for seed in [0u32, 1, 7, 0xDEAD_BEEF, 12345] {
            for m in 0..=8u32 {
                let points: Vec<(f32, f32)> = (0..1u32 << m).map(|i| owen_sobol_2d(i, seed)).collect();
                for a in 0..=m {
                    let (nx, ny) = (1usize << a, 1usize << (m - a));
                    let mut seen = vec![0u32; nx * ny];
                    for &(x, y) in &points {
                        assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
                        seen[(y * ny as f32) as usize * nx + (x * nx as f32) as usize] += 1;
                    }
                    assert!(seen.iter().all(|&c| c == 1), "seed {seed}, 2^{m} points, {nx}×{ny} grid: {seen:?}");
                }
            }
        }
    }

    #[test]
    fn batches_have_distinct_reproducible_streams() {
        let a: Vec<f64> = {
            let mut s = Sampler::for_batch(1, 0);
            (0..4).map(|_| s.uniform()).collect()
        };
        let b: Vec<f64> = {
            let mut s = Sampler::for_batch(1, 0);
            (0..4).map(|_| s.uniform()).collect()
        };
        let c: Vec<f64> = {
            let mut s = Sampler::for_batch(1, 1);
            (0..4).map(|_| s.uniform()).collect()
        };
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn cosine_hemisphere_mean_cosine_is_two_thirds() {
        // E[cosθ] under p = cosθ/π is ∫cos²θ dω/π = 2/3; Var[cosθ] = 1/2 − 4/9 = 1/18.
        let n = Vec3A::new(0.3, -0.5, 0.8).normalize();
        let mut s = Sampler::for_batch(7, 0);
        let count = 200_000;
        let mean: f64 =
            (0..count).map(|_| cosine_hemisphere(n, s.uniform_f32(), s.uniform_f32()).dot(n) as f64).sum::<f64>()
                / count as f64;
        let stderr = (1.0f64 / 18.0 / count as f64).sqrt();
        assert!(((mean - 2.0 / 3.0) / stderr).abs() < 4.0, "mean cosine {mean}");
    }

    #[test]
    fn discrete_picks_in_proportion() {
        let d = Discrete::new(&[1.0, 0.0, 3.0]);
        assert_eq!(d.sample(0.0), 0);
        assert_eq!(d.sample(0.2499), 0);
        assert_eq!(d.sample(0.25), 2);
        assert_eq!(d.sample(0.9999), 2);
    }
}

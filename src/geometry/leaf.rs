//! A BVH leaf's triangles laid out for one 4-lane watertight test: the triangles' vertex
//! coordinates as rows of four lanes, so the t_max-free part of `ShearedRay::intersect` (shear,
//! edge functions, determinant, distance and its error bound) runs for the whole leaf at once,
//! without a branch per triangle. What depends on the running t_max is then decided lane by lane
//! in triangle order (`ShearedRay::decide`), exactly as the one-triangle test does, so a leaf
//! gives the same hit, bit for bit, as testing its triangles one after another.

use glam::Vec3A;

#[cfg(target_arch = "x86_64")]
use super::bvh::Avx2;
use super::bvh::Portable;
use super::{gamma, ShearedRay};

/// A leaf test for each node test: the portable one lane by lane, AVX2's all lanes at once.
pub trait TestLeaf {
    fn test(leaf: &LeafTris, ray: &ShearedRay, t_max: f32, skip: u32) -> LeafHits;
}

impl TestLeaf for Portable {
    #[inline(always)]
    fn test(leaf: &LeafTris, ray: &ShearedRay, t_max: f32, skip: u32) -> LeafHits {
        test_portable(leaf, ray, t_max, skip)
    }
}

#[cfg(target_arch = "x86_64")]
impl TestLeaf for Avx2 {
    #[inline(always)]
    fn test(leaf: &LeafTris, ray: &ShearedRay, t_max: f32, skip: u32) -> LeafHits {
        // SAFETY: `Avx2` is used only inside `#[target_feature(enable = "avx2,fma")]` functions,
        // reached only where the CPU has both.
        unsafe { test_avx2(leaf, ray, t_max, skip) }
    }
}

/// Triangles a leaf holds at most (obvhs's compressed leaves hold three).
pub const LANES: usize = 4;

/// Up to four triangles: `rows[3·v + axis]` holds vertex v's coordinate on `axis` for each lane.
/// Lanes past `count` repeat lane 0 (finite, and masked out by `mask`).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct LeafTris {
    rows: [[f32; LANES]; 9],
    /// The first triangle's id; lane k is triangle `first + k`.
    pub first: u32,
    /// Bit k set for each lane holding a triangle.
    mask: u32,
}

impl LeafTris {
    /// The leaf of triangles `first..first + tris.len()` (1 to 4 of them).
    pub fn new(first: u32, tris: &[[Vec3A; 3]]) -> Self {
        assert!((1..=LANES).contains(&tris.len()));
        let mut rows = [[0f32; LANES]; 9];
        for lane in 0..LANES {
            let tri = tris.get(lane).unwrap_or(&tris[0]);
            for (v, p) in tri.iter().enumerate() {
                for axis in 0..3 {
                    rows[3 * v + axis][lane] = p[axis];
                }
            }
        }
        LeafTris { rows, first, mask: (1 << tris.len()) - 1 }
    }

    /// Triangle `lane`'s vertices.
    #[inline(always)]
    pub fn verts(&self, lane: usize) -> [Vec3A; 3] {
        std::array::from_fn(|v| {
            Vec3A::new(self.rows[3 * v][lane], self.rows[3 * v + 1][lane], self.rows[3 * v + 2][lane])
        })
    }
}

/// The t_max-free part of the watertight test for a leaf's lanes, and which lanes hit within
/// the t_max it was given (`candidates`, after skipping the excluded triangle).
#[derive(Clone, Copy, Debug, Default)]
pub struct LeafHits {
    pub candidates: u32,
    /// Lanes whose f32 distance bound cannot prove t > 0 (decided again in f64).
    pub fallback: u32,
    pub det: [f32; LANES],
    pub t_scaled: [f32; LANES],
    pub t: [f32; LANES],
    pub b: [[f32; LANES]; 3],
}

/// The one-triangle test's arithmetic, lane by lane (the reference for the SIMD version, and the
/// path on CPUs without AVX2).
#[inline(always)]
pub fn test_portable(leaf: &LeafTris, ray: &ShearedRay, t_max: f32, skip: u32) -> LeafHits {
    let mut out = LeafHits::default();
    let mut live = leaf.mask;
    while live != 0 {
        let k = live.trailing_zeros() as usize;
        live &= live - 1;
        if leaf.first + k as u32 == skip {
            continue;
        }
        let Some(c) = ray.prepare(&leaf.verts(k)) else { continue };
        out.det[k] = c.det;
        out.t_scaled[k] = c.t_scaled;
        out.t[k] = c.t;
        for v in 0..3 {
            out.b[v][k] = c.b[v];
        }
        out.fallback |= (c.fallback as u32) << k;
        out.candidates |= (ShearedRay::within(c.det, c.t_scaled, c.t, t_max) as u32) << k;
    }
    out
}

/// All lanes at once in SSE/AVX (the edge functions in four f64 lanes, as the one-triangle
/// test takes them in f64), operation for operation the one-triangle test's arithmetic.
///
/// # Safety
/// The CPU must have AVX2 and FMA (callers are `#[target_feature(enable = "avx2,fma")]`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn test_avx2(leaf: &LeafTris, ray: &ShearedRay, t_max: f32, skip: u32) -> LeafHits {
    use std::arch::x86_64::*;
    let row = |i: usize| _mm_load_ps(leaf.rows[i].as_ptr());
    let [kx, ky, kz] = ray.axes;
    let (ox, oy, oz) = (_mm_set1_ps(ray.o_perm[0]), _mm_set1_ps(ray.o_perm[1]), _mm_set1_ps(ray.o_perm[2]));
    let (sx, sy, sz) = (_mm_set1_ps(ray.sx), _mm_set1_ps(ray.sy), _mm_set1_ps(ray.sz));
    let zero = _mm_setzero_ps();
    let abs = |v: __m128| _mm_andnot_ps(_mm_set1_ps(-0.0), v);
    let mut px = [zero; 3];
    let mut py = [zero; 3];
    let mut pz = [zero; 3];
    for v in 0..3 {
        let z = _mm_sub_ps(row(3 * v + kz), oz);
        // x + sx·z as two roundings (the one-triangle test does not fuse them).
        px[v] = _mm_add_ps(_mm_sub_ps(row(3 * v + kx), ox), _mm_mul_ps(sx, z));
        py[v] = _mm_add_ps(_mm_sub_ps(row(3 * v + ky), oy), _mm_mul_ps(sy, z));
        pz[v] = z;
    }
    // a·b − c·d with exact f64 products, one rounding, then narrowed (`difference_of_products`).
    let dop = |a: __m128, b: __m128, c: __m128, d: __m128| {
        let ab = _mm256_mul_pd(_mm256_cvtps_pd(a), _mm256_cvtps_pd(b));
        let cd = _mm256_mul_pd(_mm256_cvtps_pd(c), _mm256_cvtps_pd(d));
        _mm256_cvtpd_ps(_mm256_sub_pd(ab, cd))
    };
    let e0 = dop(px[1], py[2], py[1], px[2]);
    let e1 = dop(px[2], py[0], py[2], px[0]);
    let e2 = dop(px[0], py[1], py[0], px[1]);
    let lt0 = |v: __m128| _mm_cmp_ps::<_CMP_LT_OQ>(v, zero);
    let gt0 = |v: __m128| _mm_cmp_ps::<_CMP_GT_OQ>(v, zero);
    let neg = _mm_or_ps(_mm_or_ps(lt0(e0), lt0(e1)), lt0(e2));
    let pos = _mm_or_ps(_mm_or_ps(gt0(e0), gt0(e1)), gt0(e2));
    let det = _mm_add_ps(_mm_add_ps(e0, e1), e2);
    for z in &mut pz {
        *z = _mm_mul_ps(*z, sz);
    }
    let t_scaled = _mm_add_ps(_mm_add_ps(_mm_mul_ps(e0, pz[0]), _mm_mul_ps(e1, pz[1])), _mm_mul_ps(e2, pz[2]));
    let inv_det = _mm_div_ps(_mm_set1_ps(1.0), det);
    let t = _mm_mul_ps(t_scaled, inv_det);
    // Rejected whatever t_max: mixed edge signs, det = 0, t on the wrong side of the origin.
    let det_neg = lt0(det);
    let det_pos = gt0(det);
    let reject = _mm_or_ps(
        _mm_or_ps(_mm_and_ps(neg, pos), _mm_cmp_ps::<_CMP_EQ_OQ>(det, zero)),
        _mm_or_ps(
            _mm_and_ps(det_neg, _mm_cmp_ps::<_CMP_GE_OQ>(t_scaled, zero)),
            _mm_and_ps(det_pos, _mm_cmp_ps::<_CMP_LE_OQ>(t_scaled, zero)),
        ),
    );
    // `ShearedRay::within` at this t_max.
    let t_max_det = _mm_mul_ps(_mm_set1_ps(t_max), det);
    let beyond = _mm_or_ps(
        _mm_and_ps(det_neg, _mm_cmp_ps::<_CMP_LT_OQ>(t_scaled, t_max_det)),
        _mm_and_ps(det_pos, _mm_cmp_ps::<_CMP_GT_OQ>(t_scaled, t_max_det)),
    );
    let within = _mm_andnot_ps(beyond, _mm_cmp_ps::<_CMP_LT_OQ>(t, _mm_set1_ps(t_max)));
    let mut live = leaf.mask;
    let skipped = skip.wrapping_sub(leaf.first);
    if skipped < LANES as u32 {
        live &= !(1 << skipped);
    }
    let candidates = _mm_movemask_ps(_mm_andnot_ps(reject, within)) as u32 & live;
    let mut out = LeafHits { candidates, ..LeafHits::default() };
    if candidates == 0 {
        return out;
    }
    // The error bound on t (pbrt-v4 §6.8.4), as `ShearedRay::prepare` orders it.
    let max3 = |a: __m128, b: __m128, c: __m128| _mm_max_ps(_mm_max_ps(abs(a), abs(b)), abs(c));
    let max_zt = max3(pz[0], pz[1], pz[2]);
    let max_xt = max3(px[0], px[1], px[2]);
    let max_yt = max3(py[0], py[1], py[2]);
    let g = |n: i32| _mm_set1_ps(gamma(n));
    let delta_z = _mm_mul_ps(g(3), max_zt);
    let delta_x = _mm_mul_ps(g(5), _mm_add_ps(max_xt, max_zt));
    let delta_y = _mm_mul_ps(g(5), _mm_add_ps(max_yt, max_zt));
    let delta_e = _mm_mul_ps(
        _mm_set1_ps(2.0),
        _mm_add_ps(
            _mm_add_ps(_mm_mul_ps(_mm_mul_ps(g(2), max_xt), max_yt), _mm_mul_ps(delta_y, max_xt)),
            _mm_mul_ps(delta_x, max_yt),
        ),
    );
    let max_e = max3(e0, e1, e2);
    let delta_t = _mm_mul_ps(
        _mm_mul_ps(
            _mm_set1_ps(3.0),
            _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(_mm_mul_ps(g(3), max_e), max_zt), _mm_mul_ps(delta_e, max_zt)),
                _mm_mul_ps(delta_z, max_e),
            ),
        ),
        abs(inv_det),
    );
    out.fallback = _mm_movemask_ps(_mm_cmp_ps::<_CMP_LE_OQ>(t, delta_t)) as u32;
    _mm_storeu_ps(out.det.as_mut_ptr(), det);
    _mm_storeu_ps(out.t_scaled.as_mut_ptr(), t_scaled);
    _mm_storeu_ps(out.t.as_mut_ptr(), t);
    _mm_storeu_ps(out.b[0].as_mut_ptr(), _mm_mul_ps(e0, inv_det));
    _mm_storeu_ps(out.b[1].as_mut_ptr(), _mm_mul_ps(e1, inv_det));
    _mm_storeu_ps(out.b[2].as_mut_ptr(), _mm_mul_ps(e2, inv_det));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_xoshiro::rand_core::{Rng, SeedableRng};

    /// The AVX2 leaf test gives the portable one's lanes bit for bit: the same candidates, the
    /// same fallback lanes among them and the same det, t_scaled, t and barycentrics, also for
    /// rays that start on a triangle (where the f32 bound fails and the f64 test decides),
    /// edge-on triangles and shared edges.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx2_lanes_equal_portable_lanes() {
        if !super::super::bvh::simd_available() {
            return;
        }
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(11);
        let mut u = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let (mut candidates, mut fallbacks) = (0, 0);
        for case in 0..200_000 {
            let count = 1 + case % 4;
            let base = Vec3A::new(u(), u(), u()) * 10.0;
            let tris: Vec<[Vec3A; 3]> = (0..count)
                .map(|k| {
                    let a = base + Vec3A::new(u(), u(), u());
                    let b = if k > 0 && case % 3 == 0 { base } else { base + Vec3A::new(u(), u(), u()) };
                    // Every fifth case an edge-on (degenerate) triangle.
                    let c = if case % 5 == 0 { a + (b - a) * 0.5 } else { base + Vec3A::new(u(), u(), u()) };
                    [a, b, c]
                })
                .collect();
            let leaf = LeafTris::new(100, &tris);
            // Half the rays start on a triangle's plane (t ≈ 0), half anywhere.
            let o = if case % 2 == 0 {
                let [a, b, c] = tris[0];
                let (s, t) = (u(), u());
                a + (b - a) * s * 0.5 + (c - a) * t * 0.5
            } else {
                base + Vec3A::new(u(), u(), u()) * 2.0 - 0.5
            };
            let d = (Vec3A::new(u(), u(), u()) - 0.5).normalize();
            let ray = ShearedRay::new(o, d);
            let t_max = if case % 7 == 0 { 0.3 } else { f32::INFINITY };
            let skip = if case % 11 == 0 { 101 } else { u32::MAX };
            let p = test_portable(&leaf, &ray, t_max, skip);
            // SAFETY: simd_available() checked AVX2 and FMA.
            let v = unsafe { test_avx2(&leaf, &ray, t_max, skip) };
            assert_eq!(p.candidates, v.candidates, "case {case}");
            for k in 0..LANES {
                if p.candidates & (1 << k) == 0 {
                    continue;
                }
                let lane = |h: &LeafHits| {
                    (
                        h.fallback >> k & 1,
                        h.det[k].to_bits(),
                        h.t_scaled[k].to_bits(),
                        h.t[k].to_bits(),
                        h.b.map(|b| b[k].to_bits()),
                    )
                };
                assert_eq!(lane(&p), lane(&v), "case {case} lane {k}");
                candidates += 1;
                fallbacks += p.fallback >> k & 1;
            }
        }
        // The cases reach both kinds of lanes.
        assert!(candidates > 10_000 && fallbacks > 100, "{candidates} candidates, {fallbacks} fallbacks");
    }
}

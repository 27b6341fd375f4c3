//! Triangles, the BVH (`bvh`: 8-wide nodes with full-precision boxes, filled by `wide_tree` from
//! obvhs's binary tree, or by `small_tree` for a few dozen triangles; `leaf4`: a leaf's
//! triangles in AVX2 lanes) and robust ray queries: a watertight ray–triangle test and ray
//! origins offset by the hit point's own floating-point error bound, so that scattering works at
//! millimetre and kilometre scales alike with no fixed epsilon.

use std::time::Duration;

mod bvh;
mod coplanar;
#[cfg(target_arch = "x86_64")]
mod leaf4;
mod small_tree;
mod wide_tree;

use bvh::Bvh8;
/// The most triangles a scene's geometry can hold (the tree indexes them in 29 bits).
pub use bvh::MAX_TRIANGLES;
use glam::{Vec3A, Vec3Swizzles};
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::{Boundable, BvhBuildParams};

/// No primitive: used as "skip nothing".
pub const NO_PRIM: u32 = u32::MAX;

/// γ(n) = nε/(1 − nε), ε = f32 unit roundoff (pbrt-v4 §6.8.1): bounds of accumulated rounding.
#[inline]
pub fn gamma(n: i32) -> f32 {
    let e = f32::EPSILON * 0.5;
    (n as f32 * e) / (1.0 - n as f32 * e)
}

/// Share of a shadow segment's length left untested at each end (see `Geometry::visible`).
pub const SHADOW_MARGIN: f32 = 1e-5;

/// One end of a shadow segment: a point, its rounding bound, the unit geometric normal of the
/// surface it lies on and that surface's primitive (zero normal and NO_PRIM for a point in free
/// space: the camera, a point light).
#[derive(Clone, Copy, Debug)]
pub struct RayEnd {
    pub p: Vec3A,
    pub err: Vec3A,
    pub n: Vec3A,
    pub prim: u32,
}

impl RayEnd {
    pub fn free(p: Vec3A) -> Self {
        RayEnd { p, err: Vec3A::ZERO, n: Vec3A::ZERO, prim: NO_PRIM }
    }

    #[inline]
    fn offset_toward(&self, dir: Vec3A) -> Vec3A {
        if self.n == Vec3A::ZERO {
            self.p
        } else {
            offset_ray_origin(self.p, self.err, self.n, dir)
        }
    }
}

/// The stretch `Geometry::visible` tests between `a` and `b`: (origin, unit direction, length),
/// each end offset off its own surface and the segment trimmed by `SHADOW_MARGIN` of its length
/// at both ends alike, so that a → b and b → a test the same stretch. None if it is empty.
#[inline]
pub fn shadow_segment(a: RayEnd, b: RayEnd) -> Option<(Vec3A, Vec3A, f32)> {
    let dir = (b.p - a.p).normalize();
    let from = a.offset_toward(dir);
    let to = b.offset_toward(-dir);
    let seg = to - from;
    let len = seg.length();
    if !(len > 0.0) {
        return None;
    }
    let dir = seg / len;
    Some((from + dir * (len * SHADOW_MARGIN), dir, len * (1.0 - 2.0 * SHADOW_MARGIN)))
}

/// A ray for `Geometry::intersect_many`: as `intersect_leaving`'s arguments.
#[derive(Clone, Copy, Debug)]
pub struct RayQuery {
    pub origin: Vec3A,
    pub dir: Vec3A,
    pub t_max: f32,
    /// The triangle the ray leaves (NO_PRIM for none).
    pub leaving: u32,
}

/// Rays `Geometry::intersect_many` walks at once.
pub const INTERLEAVE: usize = 32;

/// A closest hit: distance along the (unit) ray, primitive, barycentrics of the vertices.
/// `repr(C)`: `intersect_avx2` writes the first 16 bytes with one store.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
    pub b: [f32; 3],
}

/// A triangle as the BVH sees it: its bounds padded so that the BVH's single-precision slab
/// tests are conservative. A planar face has a flat box, whose entry and exit distances coincide;
/// rounding can then put entry after exit and cull the node, and a photon slips out through an
/// edge. The padding is 2·f32::EPSILON in absolute terms and 1e-5 of the coordinates' magnitude
/// in relative terms (far above the slab test's few-ulp rounding; far below any feature worth
/// tracing).
struct PaddedTriangle([Vec3A; 3]);

impl Boundable for PaddedTriangle {
    fn aabb(&self) -> Aabb {
        let [a, b, c] = self.0;
        let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
        let pad = Vec3A::splat(2.0 * f32::EPSILON).max(1e-5 * lo.abs().max(hi.abs()));
        Aabb::new(lo - pad, hi + pad)
    }
}

/// What a hit on a triangle reads, in one 64-byte cache line: its vertices, its unit normal,
/// its surface, its least height and its unit tangent. In a million-triangle mesh every hit is a
/// cache miss; one line per triangle makes it one miss, not one per table (vertices, normals,
/// surfaces). The height and the tangent fill the three words the vec3s leave over: the tangent
/// as its two components along the first edge ê₀ and along n × ê₀ (it lies in the plane).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct PackedTriangle {
    a: [f32; 3],
    surface: u32,
    b: [f32; 3],
    /// The least of the three heights (twice the area over the longest edge), rounded down:
    /// a point with barycentrics β lies at least min(β)·height from every edge (`spawn_from`).
    least_height: f32,
    c: [f32; 3],
    tangent_along_edge: f32,
    normal: [f32; 3],
    tangent_across_edge: f32,
}

impl PackedTriangle {
    fn new(v: &[Vec3A; 3], surface: u32, tangent: Vec3A) -> Self {
        let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
        // In the triangle's plane, unit; zero where the given direction has no part in it.
        let t = tangent - n * n.dot(tangent);
        let t = if t.length_squared() > 1e-12 * tangent.length_squared() && t.length_squared() > 0.0 {
            t.normalize()
        } else {
            Vec3A::ZERO
        };
        let (edge, across) = edge_frame(v[0], v[1], n);
        let (along, across) = (t.dot(edge), t.dot(across));
        let (along, across) = if along.is_finite() && across.is_finite() { (along, across) } else { (0.0, 0.0) };
        let [a, b, c] = v.map(|p| p.to_array());
        let normal = n.to_array();
        PackedTriangle {
            a,
            surface,
            b,
            least_height: least_height(v),
            c,
            tangent_along_edge: along,
            normal,
            tangent_across_edge: across,
        }
    }

    #[inline(always)]
    fn verts(&self) -> [Vec3A; 3] {
        [Vec3A::from_array(self.a), Vec3A::from_array(self.b), Vec3A::from_array(self.c)]
    }
}

/// The unit first edge ê₀ = (v₁ − v₀)/|v₁ − v₀| and n × ê₀: the tangent's frame in the plane,
/// computed alike when the tangent is stored and when it is read.
#[inline]
fn edge_frame(v0: Vec3A, v1: Vec3A, n: Vec3A) -> (Vec3A, Vec3A) {
    let edge = (v1 - v0).normalize();
    (edge, n.cross(edge))
}

/// The triangle's least height, 2·area / longest edge, in f64 and rounded down to f32; 0 for a
/// degenerate one (so that no hit on it counts as inside).
fn least_height(v: &[Vec3A; 3]) -> f32 {
    let [a, b, c] = v.map(|p| p.as_dvec3());
    let twice_area = (b - a).cross(c - a).length();
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    let h = twice_area / longest;
    if !(h > 0.0 && h.is_finite()) {
        return 0.0;
    }
    let rounded = h as f32;
    if rounded as f64 > h {
        rounded.next_down()
    } else {
        rounded
    }
}

/// All triangles of a scene in BVH order, each knowing its surface.
pub struct Geometry {
    /// Each triangle's vertices, normal and surface, one cache line each.
    tris: Vec<PackedTriangle>,
    /// Each triangle's surface (also inside `tris`; this copy serves whole-scene scans).
    pub surface: Vec<u32>,
    /// Each triangle's index among its own surface's triangles (in the order they were given).
    pub local: Vec<u32>,
    bvh: Option<Bvh8>,
    /// Whether the node test runs in AVX2 (`bvh::simd_available`); both give the same bits.
    simd: bool,
    /// Whether the tree's leaves may hold more than 4 triangles (`wide_tree`'s do).
    big_leaves: bool,
    /// Per triangle, the first triangle of its leaf where all that leaf's triangles lie exactly
    /// in one plane, else NO_PRIM (`intersect_leaving`); small scenes' trees only (empty else).
    flat_leaf: Vec<u32>,
    /// Each triangle's unit vertex normals for smooth shading, zero for a flat triangle; empty
    /// when no triangle has any (`shading_normal`).
    shading: Vec<[Vec3A; 3]>,
}

impl Geometry {
    /// Builds the BVH and reorders triangles into its leaf order, so a BVH primitive id indexes
    /// the arrays directly.
    /// Fails (with a message for the user) only on a tree too deep to trace, or more than 2^28
    /// triangles.
    pub fn build(tris: Vec<[Vec3A; 3]>, surface: Vec<u32>) -> Result<Self, String> {
        let tangents = tris.iter().map(|t| t[1] - t[0]).collect();
        Self::build_with_tangents(tris, surface, tangents)
    }

    /// As `build`, with each triangle's surface tangent (the u axis of an anisotropic
    /// material; `tangent`): `build` takes each triangle's first edge.
    pub fn build_with_tangents(tris: Vec<[Vec3A; 3]>, surface: Vec<u32>, tangents: Vec<Vec3A>) -> Result<Self, String> {
        Self::build_with_shading(tris, surface, tangents, Vec::new())
    }

    /// As `build_with_tangents`, with each triangle's vertex normals for smooth shading (zero for
    /// a flat one), or none at all (empty).
    pub fn build_with_shading(
        tris: Vec<[Vec3A; 3]>,
        surface: Vec<u32>,
        tangents: Vec<Vec3A>,
        shading: Vec<[Vec3A; 3]>,
    ) -> Result<Self, String> {
        assert_eq!(tris.len(), surface.len());
        assert_eq!(tris.len(), tangents.len());
        assert!(shading.is_empty() || shading.len() == tris.len());
        if tris.is_empty() {
            return Ok(Geometry {
                tris: vec![],
                surface: vec![],
                local: vec![],
                bvh: None,
                simd: false,
                big_leaves: false,
                flat_leaf: vec![],
                shading: vec![],
            });
        }
        let triangle_bytes = tris.len() * std::mem::size_of::<PackedTriangle>();
        let ((order, tree), big_leaves) = match small_tree::build(&tris, triangle_bytes) {
            Some(small) => (small, false),
            None => (Self::large_tree(&tris, triangle_bytes)?, true),
        };
        // `wide_tree` refuses trees deeper than the traversal's stack; a small scene's cannot be:
        // each level below its root takes 7 or more of its 64 triangles.
        let verts: Vec<[Vec3A; 3]> = order.iter().map(|&i| tris[i]).collect();
        // Triangles of one surface are given together, so each one's local index counts up.
        let mut seen: std::collections::HashMap<u32, u32> = std::collections::HashMap::new();
        let local_given: Vec<u32> = surface
            .iter()
            .map(|&s| {
                let k = seen.entry(s).or_insert(0);
                *k += 1;
                *k - 1
            })
            .collect();
        let local: Vec<u32> = order.iter().map(|&i| local_given[i]).collect();
        let surface: Vec<u32> = order.iter().map(|&i| surface[i]).collect();
        let tris: Vec<PackedTriangle> = verts
            .iter()
            .zip(&surface)
            .zip(&order)
            .map(|((v, &s), &i)| PackedTriangle::new(v, s, tangents[i]))
            .collect();
        let shading = if shading.is_empty() { shading } else { order.iter().map(|&i| shading[i]).collect() };
        // A small scene's walls are flat leaves (`small_tree` keeps a quad's two triangles one
        // leaf). A large tree's would cost each ray a lookup in a table of its size.
        let mut flat_leaf = vec![];
        if !big_leaves {
            flat_leaf = vec![NO_PRIM; tris.len()];
            for (first, count) in tree.leaves() {
                let leaf = first as usize..(first + count) as usize;
                let points: Vec<[f32; 3]> = tris[leaf.clone()].iter().flat_map(|t| [t.a, t.b, t.c]).collect();
                if coplanar::coplanar(&points) {
                    flat_leaf[leaf].fill(first);
                }
            }
        }
        Ok(Geometry {
            tris,
            surface,
            local,
            bvh: Some(tree),
            simd: bvh::simd_available(),
            big_leaves,
            flat_leaf,
            shading,
        })
    }

    /// obvhs's binary tree over `tris` collapsed into our 8-wide one (`wide_tree`), and the
    /// triangles' leaf order.
    fn large_tree(tris: &[[Vec3A; 3]], triangle_bytes: usize) -> Result<(Vec<usize>, Bvh8), String> {
        if tris.len() >= bvh::MAX_TRIANGLES {
            return Err(format!(
                "the scene has {} triangles, and photon traces at most {}",
                tris.len(),
                bvh::MAX_TRIANGLES - 1
            ));
        }
        let padded: Vec<PaddedTriangle> = tris.iter().map(|t| PaddedTriangle(*t)).collect();
        // One triangle a leaf: `wide_tree` makes the leaves itself.
        let params = BvhBuildParams { max_prims_per_leaf: 1, ..BvhBuildParams::medium_build() };
        let binary = build_bvh2(&padded, params, &mut Duration::default());
        wide_tree::build(&binary, triangle_bytes).map_err(|levels| too_deep(tris.len(), levels))
    }

    /// Whether any triangle has vertex normals for smooth shading.
    pub fn has_shading_normals(&self) -> bool {
        !self.shading.is_empty()
    }

    /// The shading normal of triangle `prim` at barycentrics `b`: its vertex normals
    /// interpolated (b₀n₀ + b₁n₁ + b₂n₂, unit), turned to the geometric normal's side (which
    /// decides sides and leaks everywhere); the geometric normal for a flat triangle.
    #[inline]
    pub fn shading_normal(&self, prim: usize, b: [f32; 3]) -> Vec3A {
        let ng = self.normal(prim);
        let Some(v) = self.shading.get(prim) else { return ng };
        if v[0] == Vec3A::ZERO {
            return ng;
        }
        let ns = (v[0] * b[0] + v[1] * b[1] + v[2] * b[2]).normalize_or_zero();
        match ns.dot(ng) {
            d if d > 0.0 => ns,
            d if d < 0.0 => -ns,
            _ => ng,
        }
    }

    pub fn len(&self) -> usize {
        self.tris.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The vertices of triangle `prim`.
    #[inline(always)]
    pub fn verts(&self, prim: usize) -> [Vec3A; 3] {
        self.tris[prim].verts()
    }

    /// Unit geometric normal (v1−v0)×(v2−v0) of triangle `prim`.
    #[inline(always)]
    pub fn normal(&self, prim: usize) -> Vec3A {
        Vec3A::from_array(self.tris[prim].normal)
    }

    /// Unit tangent of triangle `prim` in its plane, the u axis of an anisotropic material
    /// (how each shape defines it: `scene::shapes::triangulate`); zero where none is defined,
    /// and then any perpendicular to the normal serves.
    #[inline(always)]
    pub fn tangent(&self, prim: usize) -> Vec3A {
        let t = &self.tris[prim];
        let (edge, across) = edge_frame(Vec3A::from_array(t.a), Vec3A::from_array(t.b), Vec3A::from_array(t.normal));
        let tangent = edge * t.tangent_along_edge + across * t.tangent_across_edge;
        if tangent.is_finite() {
            tangent
        } else {
            Vec3A::ZERO
        }
    }

    /// The surface that triangle `prim` belongs to.
    #[inline(always)]
    pub fn surface_of(&self, prim: usize) -> u32 {
        self.tris[prim].surface
    }

    pub fn area(&self, prim: usize) -> f64 {
        let [a, b, c] = self.verts(prim).map(|v| v.as_dvec3());
        0.5 * (b - a).cross(c - a).length()
    }

    /// How often a ray from `start` (on primitive `skip`, or NO_PRIM) along a fixed direction
    /// crosses each surface: odd for the closed surfaces that enclose `start` (ray parity). The
    /// direction is one unlikely to run along an edge or face of a modelled scene.
    pub fn crossings(&self, start: Vec3A, skip: u32, surfaces: usize) -> Vec<u32> {
        let dir = Vec3A::new(0.5407, 0.6238, 0.5643).normalize();
        let mut crossings = vec![0u32; surfaces];
        let (mut from, mut skip) = (start, skip);
        // Every step moves past a hit, so the walk ends; the cap only guards against a pathology.
        for _ in 0..1_000_000 {
            let Some(hit) = self.intersect(from, dir, f32::INFINITY, skip) else { break };
            crossings[self.surface_of(hit.prim as usize) as usize] += 1;
            let (p, err) = self.hit_point(&hit);
            from = self.spawn_from(p, err, hit.prim, hit.b, dir);
            skip = hit.prim;
        }
        crossings
    }

    /// Closest hit along `origin + t·dir`, t in (0, t_max), ignoring primitive `skip` (the one the
    /// ray leaves: a flat triangle can never be hit again by a ray leaving it).
    #[inline(always)]
    pub fn intersect(&self, origin: Vec3A, dir: Vec3A, t_max: f32, skip: u32) -> Option<Hit> {
        self.intersect_passing(origin, dir, t_max, skip, NO_PRIM)
    }

    /// `intersect` for a ray spawned off triangle `leaving` (`spawn`, `spawn_from`: its origin
    /// off the plane, on the side `dir` leaves by), which can meet no triangle lying exactly in
    /// that plane: the leaf of `leaving`, where all its triangles do (`flat_leaf`, a small
    /// scene's wall), is not tested. The same hit as `intersect`, without the leaf that nearly
    /// every ray from a wall entered first (raybench's Cornell box: 80 → 69 ns a closest hit).
    /// Not for rays that look for what lies in a surface's plane (a lamp flush with a ceiling).
    #[inline(always)]
    pub fn intersect_leaving(&self, origin: Vec3A, dir: Vec3A, t_max: f32, leaving: u32) -> Option<Hit> {
        let own_leaf = self.flat_leaf.get(leaving as usize).copied().unwrap_or(NO_PRIM);
        self.intersect_passing(origin, dir, t_max, leaving, own_leaf)
    }

    /// `intersect`, the leaf that starts at triangle `pass` (or none: NO_PRIM) left untested.
    #[inline(always)]
    fn intersect_passing(&self, origin: Vec3A, dir: Vec3A, t_max: f32, skip: u32, pass: u32) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            let mut hit = std::mem::MaybeUninit::<Hit>::uninit();
            // SAFETY: `simd` is set only where the CPU has AVX2 and FMA; `hit` is written
            // whole when the call returns true.
            return unsafe {
                let out = hit.as_mut_ptr();
                let found = if self.big_leaves {
                    self.intersect_avx2::<true>(origin, dir, t_max, skip, pass, out)
                } else {
                    self.intersect_avx2::<false>(origin, dir, t_max, skip, pass, out)
                };
                found.then(|| hit.assume_init())
            };
        }
        // The portable test's scalar loop covers a leaf of any count: the flag, which only
        // compiles in the lanes' second pass, has no effect there.
        self.intersect_with::<bvh::Portable, true>(origin, dir, t_max, skip, pass)
    }

    /// The closest hit written to `out` (true), or none (false). Returned as an `Option<Hit>`,
    /// the hit came back through memory written field by field, and the caller's 16-byte load
    /// of it could not be forwarded from those stores (a stall on every ray, ~2 % of the grey
    /// loop); one 16-byte store of t, prim, b₀, b₁ forwards to any load inside it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn intersect_avx2<const BIG_LEAVES: bool>(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        t_max: f32,
        skip: u32,
        pass: u32,
        out: *mut Hit,
    ) -> bool {
        use std::arch::x86_64::{_mm_setr_ps, _mm_storeu_ps};
        let Some(h) = self.intersect_with::<bvh::Avx2, BIG_LEAVES>(origin, dir, t_max, skip, pass) else {
            return false;
        };
        // SAFETY: `out` is valid for a Hit, whose repr(C) layout starts with t, prim, b.
        unsafe {
            _mm_storeu_ps(out.cast::<f32>(), _mm_setr_ps(h.t, f32::from_bits(h.prim), h.b[0], h.b[1]));
            (*out).b[2] = h.b[2];
        }
        true
    }

    #[inline(always)]
    fn intersect_with<T: bvh::NodeTest, const BIG_LEAVES: bool>(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        t_max: f32,
        skip: u32,
        pass: u32,
    ) -> Option<Hit> {
        let bvh = self.bvh.as_ref()?;
        let sheared = ShearedRay::new(origin, dir);
        let mut best: Option<Hit> = None;
        // Inlined into both of the traversal's walks (a closure called from two was left out of
        // line: +24 % instructions a ray).
        bvh.closest::<T>(
            origin,
            dir,
            t_max,
            |first, count| self.prefetch_leaf(first, count),
            #[inline(always)]
            |first, count, t_max| {
                self.leaf_closest::<T, BIG_LEAVES>(&sheared, first, count, skip, pass, t_max, &mut best)
            },
        );
        best
    }

    /// A closest-hit walk's leaf: triangles `first..first + count` but `skip` (none where the
    /// leaf starts at `pass`), each hit before `t_max` lowering it and becoming `best` in
    /// triangle order; the new t_max.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn leaf_closest<T: bvh::NodeTest, const BIG_LEAVES: bool>(
        &self,
        sheared: &ShearedRay,
        first: u32,
        count: u32,
        skip: u32,
        pass: u32,
        mut t_max: f32,
        best: &mut Option<Hit>,
    ) -> f32 {
        if first == pass {
            return t_max;
        }
        // A leaf's triangles in AVX2 lanes, the same bits (`leaf4`). Shadow rays keep the
        // scalar loop, which stops at the first blocker: with lanes they ran slower.
        #[cfg(target_arch = "x86_64")]
        if T::LEAF_LANES {
            debug_assert!(BIG_LEAVES || count <= 4, "a leaf of {count} in a small scene's tree");
            // SAFETY: `LEAF_LANES` is the AVX2 node test's, run only under AVX2 and FMA;
            // the tree's leaves index `tris`.
            unsafe {
                t_max = self.leaf_lanes(sheared, first, count.min(4), skip, t_max, best);
                // A large scene's leaf of more than 4 takes a second pass, in order. Only
                // its trees have such leaves; compiled in for the small ones too, the
                // pass (never taken) cost their photons 4 % (grey Cornell box).
                if BIG_LEAVES && count > 4 {
                    t_max = self.leaf_lanes_after_four(sheared, first + 4, count - 4, skip, t_max, best);
                }
            }
            return t_max;
        }
        for id in first..first + count {
            if id != skip {
                if let Some((t, b)) = sheared.intersect(t_max, &self.verts(id as usize)) {
                    if t < t_max {
                        t_max = t;
                        *best = Some(Hit { t, prim: id, b });
                    }
                }
            }
        }
        t_max
    }

    /// The closest hit of each of `rays` into `hits` (as long): `intersect_leaving`'s, bit for
    /// bit. In a tree that outgrows the caches, up to `INTERLEAVE` rays are walked at once, a
    /// node or leaf of each in turn, so that while one ray's next node comes from memory
    /// (prefetched) the others' steps run; a single ray's walk there mostly waits (raybench's
    /// 1.3 M-triangle sphere: 0.6–0.75× the time a closest hit). A tree that fits takes the rays
    /// one by one: the turns' bookkeeping cost more than the waits they hide (Cornell box 1.3×).
    pub fn intersect_many(&self, rays: &[RayQuery], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len(), "a hit for each ray");
        #[cfg(target_arch = "x86_64")]
        if self.simd && self.bvh.as_ref().is_some_and(|b| b.is_large()) {
            for (rays, hits) in rays.chunks(INTERLEAVE).zip(hits.chunks_mut(INTERLEAVE)) {
                // SAFETY: `simd` is set only where the CPU has AVX2 and FMA.
                unsafe {
                    if self.big_leaves {
                        self.intersect_many_avx2::<true>(rays, hits)
                    } else {
                        self.intersect_many_avx2::<false>(rays, hits)
                    }
                }
            }
            return;
        }
        for (r, hit) in rays.iter().zip(hits) {
            *hit = self.intersect_leaving(r.origin, r.dir, r.t_max, r.leaving);
        }
    }

    /// `intersect_many` for up to `INTERLEAVE` rays.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn intersect_many_avx2<const BIG_LEAVES: bool>(&self, rays: &[RayQuery], hits: &mut [Option<Hit>]) {
        hits.fill(None);
        let Some(bvh) = self.bvh.as_ref() else { return };
        let n = rays.len().min(INTERLEAVE);
        if n == 0 {
            return;
        }
        let mut stacks = [bvh::WALK_STACK_UNSET; INTERLEAVE];
        let mut stacks = stacks.iter_mut();
        // Slots past n repeat the last ray and are never stepped.
        let mut walks: [_; INTERLEAVE] = std::array::from_fn(|k| {
            let r = &rays[k.min(n - 1)];
            let pass = self.flat_leaf.get(r.leaving as usize).copied().unwrap_or(NO_PRIM);
            let stack = stacks.next().expect("a stack a slot");
            (bvh.closest_start(r.origin, r.dir, r.t_max, stack), ShearedRay::new(r.origin, r.dir), pass)
        });
        let mut going: u64 = (1u64 << n) - 1;
        while going != 0 {
            let mut turn = going;
            while turn != 0 {
                let k = turn.trailing_zeros() as usize;
                turn &= turn - 1;
                let (walk, sheared, pass) = &mut walks[k];
                let (skip, pass, best) = (rays[k].leaving, *pass, &mut hits[k]);
                let more = bvh.closest_step::<bvh::Avx2>(
                    walk,
                    &|first, count| self.prefetch_leaf(first, count),
                    // Inlined, as in `intersect_with` (a leaf closure left out of line cost +24 %).
                    #[inline(always)]
                    |first, count, t_max| {
                        self.leaf_closest::<bvh::Avx2, BIG_LEAVES>(sheared, first, count, skip, pass, t_max, best)
                    },
                );
                if !more {
                    going &= !(1 << k);
                }
            }
        }
    }

    /// Triangles `first..first + count` (count 1..=4, not `skip`) in one pass of AVX2 lanes
    /// (`leaf4`: the scalar test's bits), each hit before `t_max` lowering it and becoming `best`
    /// in triangle order; the new t_max.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, and the triangles must be in `tris`.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn leaf_lanes(
        &self,
        sheared: &ShearedRay,
        first: u32,
        count: u32,
        skip: u32,
        mut t_max: f32,
        best: &mut Option<Hit>,
    ) -> f32 {
        let valid = lanes_but(first, count, skip);
        // SAFETY: the caller's contract.
        let lanes = unsafe { leaf4::test(sheared, &self.tris, first, count, valid, t_max) };
        let mut candidates = lanes.candidates;
        while candidates != 0 {
            let k = candidates.trailing_zeros();
            candidates &= candidates - 1;
            let id = first + k;
            if let Some((t, b)) = lanes.hit(k as usize, t_max, sheared, &self.tris[id as usize]) {
                t_max = t;
                *best = Some(Hit { t, prim: id, b });
            }
        }
        t_max
    }

    /// `leaf_lanes` out of line, for a leaf's triangles after its first four (the sphere's
    /// cast measured 0.96× against the pass inlined).
    ///
    /// # Safety
    /// As `leaf_lanes`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    unsafe fn leaf_lanes_after_four(
        &self,
        sheared: &ShearedRay,
        first: u32,
        count: u32,
        skip: u32,
        t_max: f32,
        best: &mut Option<Hit>,
    ) -> f32 {
        // SAFETY: the caller's contract.
        unsafe { self.leaf_lanes(sheared, first, count, skip, t_max, best) }
    }

    /// True when nothing blocks the open segment from `origin` to `origin + t_max·dir`, ignoring
    /// the primitives `skip` (those the segment starts and ends on; NO_PRIM for none).
    #[inline]
    pub fn unoccluded(&self, origin: Vec3A, dir: Vec3A, t_max: f32, skip: [u32; 2]) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            // SAFETY: `simd` is set only where the CPU has AVX2 and FMA.
            return unsafe {
                if self.big_leaves {
                    self.unoccluded_avx2::<true>(origin, dir, t_max, skip)
                } else {
                    self.unoccluded_avx2::<false>(origin, dir, t_max, skip)
                }
            };
        }
        self.unoccluded_with::<bvh::Portable, false>(origin, dir, t_max, skip)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn unoccluded_avx2<const BIG_LEAVES: bool>(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        t_max: f32,
        skip: [u32; 2],
    ) -> bool {
        self.unoccluded_with::<bvh::Avx2, BIG_LEAVES>(origin, dir, t_max, skip)
    }

    #[inline(always)]
    fn unoccluded_with<T: bvh::NodeTest, const BIG_LEAVES: bool>(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        t_max: f32,
        skip: [u32; 2],
    ) -> bool {
        let Some(bvh) = self.bvh.as_ref() else {
            return true;
        };
        let sheared = ShearedRay::new(origin, dir);
        !bvh.any::<T>(
            origin,
            dir,
            t_max,
            |first, count| self.prefetch_leaf(first, count),
            // As in `intersect_with`; a plain loop, as `Iterator::any` stayed out of line.
            #[inline(always)]
            |first, count, t_max| {
                // A large tree's leaves (up to 8) in lanes; a small tree's (up to 4) one by one,
                // stopping at the first blocker, which measured faster there.
                #[cfg(target_arch = "x86_64")]
                if T::LEAF_LANES && BIG_LEAVES {
                    // SAFETY: `LEAF_LANES` is the AVX2 node test's, run only under AVX2 and FMA;
                    // the tree's leaves index `tris`.
                    return unsafe { self.leaf_lanes_blocked(&sheared, first, count, skip, t_max) };
                }
                for id in first..first + count {
                    if !skip.contains(&id) && sheared.intersect(t_max, &self.verts(id as usize)).is_some() {
                        return true;
                    }
                }
                false
            },
        )
    }

    /// Whether any of triangles `first..first + count` (not those in `skip`) meets the ray before
    /// `t_max`: `ShearedRay::intersect`'s answer for each, four lanes at a time.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, and the triangles must be in `tris`.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn leaf_lanes_blocked(
        &self,
        sheared: &ShearedRay,
        first: u32,
        count: u32,
        skip: [u32; 2],
        t_max: f32,
    ) -> bool {
        let mut start = first;
        while start < first + count {
            let n = (first + count - start).min(4);
            let valid = lanes_but(start, n, skip[0]) & lanes_but(start, n, skip[1]);
            // SAFETY: the caller's contract.
            let lanes = unsafe { leaf4::test(sheared, &self.tris, start, n, valid, t_max) };
            let mut candidates = lanes.candidates;
            while candidates != 0 {
                let k = candidates.trailing_zeros();
                candidates &= candidates - 1;
                if lanes.hit(k as usize, t_max, sheared, &self.tris[(start + k) as usize]).is_some() {
                    return true;
                }
            }
            start += n;
        }
        false
    }

    /// Starts loading the cache lines of triangles `first..first + count` (one line each).
    #[inline(always)]
    fn prefetch_leaf(&self, first: u32, count: u32) {
        if let Some(leaf) = self.tris.get(first as usize..(first + count) as usize) {
            for t in leaf {
                bvh::prefetch(t as *const PackedTriangle as *const u8);
            }
        }
    }

    /// True when nothing lies strictly between two points, each offset off its own surface.
    /// The offsets cover only each point's own rounding, while a ray's hit distance errs by up to
    /// ~1e-6 of its length (pbrt-v4 §6.8.4). A long ray ending on a surface near the origin, where
    /// the offset is tiny, could then hit that surface short of its end, so the end's primitive
    /// is skipped and the segment stops `SHADOW_MARGIN` of its length short of each end (pbrt-v4: 1e-4).
    /// Without this, 1 in 1000 lamp-to-block connections in the Cornell box came out occluded one
    /// way and visible the other.
    pub fn visible(&self, a: RayEnd, b: RayEnd) -> bool {
        match shadow_segment(a, b) {
            Some((origin, dir, len)) => self.unoccluded(origin, dir, len, [a.prim, b.prim]),
            None => false,
        }
    }

    /// Origin of a ray leaving primitive `prim` at `p` (error bound `err`) along `dir`. A hit
    /// within rounding of an edge can be rounded onto the edge, or past it; where a wall meets
    /// that edge in a concave corner, a ray leaving toward the wall would then start on or
    /// behind the wall's plane and slip out of a closed room. So `p` is first pulled toward the
    /// triangle's centroid by 8 rounding bounds (a few 1e-6 of the coordinates), putting it
    /// inside the triangle again, then offset off the plane by `offset_ray_origin`.
    /// `spawn_from` does the same for a point whose barycentrics are known, more cheaply.
    #[inline]
    pub fn spawn(&self, p: Vec3A, err: Vec3A, prim: u32, dir: Vec3A) -> Vec3A {
        let [a, b, c] = self.verts(prim as usize);
        let to_centroid = (a + b + c) / 3.0 - p;
        let distance = to_centroid.length();
        let e = err.max_element();
        let pull = (8.0 * e).min(0.5 * distance);
        let (p, err) = if pull > 0.0 {
            let q = p + to_centroid * (pull / distance);
            // The move adds its own rounding: one ulp of each coordinate.
            (q, err + q.abs() * f32::EPSILON)
        } else {
            (p, err)
        };
        offset_ray_origin(p, err, self.normal(prim as usize), dir)
    }

    /// As `spawn`, for the point `p` = Σ βᵢ vᵢ of primitive `prim` (barycentrics `b`, as
    /// `hit_point` makes it). That point lies within its bound of Σ βᵢ vᵢ / Σ βᵢ, which lies
    /// min(β)·(least height) or more from every edge: where that is over twice the pull (16
    /// bounds), the pull could not bring the point further inside than it already is, and the
    /// offset alone is taken. Most hits are such; this saves the centroid's arithmetic there.
    #[inline]
    pub fn spawn_from(&self, p: Vec3A, err: Vec3A, prim: u32, b: [f32; 3], dir: Vec3A) -> Vec3A {
        let t = &self.tris[prim as usize];
        // All three at once (f32::min's NaN handling cost twice as much); a NaN is not inside.
        let reach = Vec3A::from_array(b) * t.least_height;
        if reach.cmpgt(Vec3A::splat(16.0 * err.max_element())).all() {
            return offset_ray_origin(p, err, Vec3A::from_array(t.normal), dir);
        }
        self.spawn(p, err, prim, dir)
    }

    /// Hit point from barycentrics with its absolute error bound (pbrt-v4 §6.8.5):
    /// |error| ≤ γ(7)·(|b0·p0| + |b1·p1| + |b2·p2|) per component.
    #[inline]
    pub fn hit_point(&self, hit: &Hit) -> (Vec3A, Vec3A) {
        let [p0, p1, p2] = self.verts(hit.prim as usize);
        let [b0, b1, b2] = hit.b;
        let p = b0 * p0 + b1 * p1 + b2 * p2;
        let err = gamma(7) * ((b0 * p0).abs() + (b1 * p1).abs() + (b2 * p2).abs());
        (p, err)
    }
}

/// Why a scene is refused whose tree would be `levels` deep or more (`bvh::MOST_LEVELS`).
fn too_deep(triangles: usize, levels: usize) -> String {
    format!(
        "the scene's {triangles} triangles make a ray-tracing tree {levels} or more levels deep, and photon traces \
         at most {}: this comes from many long, thin triangles overlapping (a disk or fan of very many segments); \
         use fewer segments or a better-shaped mesh",
        bvh::MOST_LEVELS
    )
}

/// The lanes of a leaf's triangles `first..first + count` that a ray tests: all but `skip`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lanes_but(first: u32, count: u32, skip: u32) -> u32 {
    let k = skip.wrapping_sub(first);
    ((1u32 << count) - 1) & !(if k < count { 1 << k } else { 0 })
}

/// Moves `p` off the surface along the normal, to the side `dir` leaves by, far enough that the
/// rounding error `err` of `p` cannot put the new origin on the wrong side (pbrt-v4 OffsetRayOrigin).
#[inline]
pub fn offset_ray_origin(p: Vec3A, err: Vec3A, n: Vec3A, dir: Vec3A) -> Vec3A {
    let d = n.abs().dot(err);
    let mut offset = d * n;
    if dir.dot(n) < 0.0 {
        offset = -offset;
    }
    // Round away from p so the offset survives the addition's own rounding.
    step_away(p + offset, offset)
}

/// Each component of `x` one ulp further in the direction of `offset`'s: `next_up` where it is
/// positive, `next_down` where negative, unchanged where ±0 or NaN.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn step_away(mut x: Vec3A, offset: Vec3A) -> Vec3A {
    for i in 0..3 {
        if offset[i] > 0.0 {
            x[i] = x[i].next_up();
        } else if offset[i] < 0.0 {
            x[i] = x[i].next_down();
        }
    }
    x
}

/// The same bits without a branch (SSE2): which components an offset moves, and which way,
/// depends on the surface hit, at random from bounce to bounce.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn step_away(x: Vec3A, offset: Vec3A) -> Vec3A {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64.
    unsafe {
        let (off, zero) = (__m128::from(offset), _mm_setzero_ps());
        let (up, down) = (_mm_castps_si128(_mm_cmpgt_ps(off, zero)), _mm_castps_si128(_mm_cmplt_ps(off, zero)));
        let bits = _mm_castps_si128(x.into());
        let negative = _mm_srai_epi32::<31>(bits);
        let magnitude = _mm_and_si128(bits, _mm_set1_epi32(0x7FFF_FFFF));
        let moving = _mm_or_si128(up, down);
        // The magnitude grows going up from a positive x or down from a negative one.
        let grows = _mm_and_si128(moving, _mm_xor_si128(negative, up));
        // Masks are 0 or −1: +1 where the magnitude grows, −1 where it shrinks.
        let stepped = _mm_add_epi32(_mm_sub_epi32(bits, grows), _mm_andnot_si128(grows, moving));
        // From ±0 the step is to the least subnormal of the direction's sign.
        let is_zero = _mm_and_si128(_mm_cmpeq_epi32(magnitude, _mm_setzero_si128()), moving);
        let from_zero = _mm_or_si128(_mm_and_si128(down, _mm_set1_epi32(i32::MIN)), _mm_set1_epi32(1));
        let stepped = _mm_or_si128(_mm_andnot_si128(is_zero, stepped), _mm_and_si128(is_zero, from_zero));
        // NaN stays, and so does an infinity stepping outward.
        let inf = _mm_set1_epi32(0x7F80_0000);
        let keep = _mm_or_si128(_mm_cmpgt_epi32(magnitude, inf), _mm_and_si128(_mm_cmpeq_epi32(magnitude, inf), grows));
        let out = _mm_or_si128(_mm_andnot_si128(keep, stepped), _mm_and_si128(keep, bits));
        Vec3A::from(_mm_castsi128_ps(out))
    }
}

#[inline]
fn max_dim(v: Vec3A) -> usize {
    if v.x > v.y {
        if v.x > v.z {
            0
        } else {
            2
        }
    } else if v.y > v.z {
        1
    } else {
        2
    }
}

/// a·b − c·d rounded once: f32 products are exact in f64, so only the subtraction and the
/// final narrowing round (as accurate as Kahan's FMA form, and no FMA instruction needed).
#[inline]
fn difference_of_products(a: f32, b: f32, c: f32, d: f32) -> f32 {
    (a as f64 * b as f64 - c as f64 * d as f64) as f32
}

/// Watertight ray–triangle intersection (Woop, Benthin, Wald 2013; pbrt-v4 §6.5.3): the ray is
/// translated to the origin and sheared onto +z, then the three edge functions decide inside
/// consistently on shared edges, so no ray slips between two triangles. Returns (t, barycentrics)
/// for 0 < t < t_max, with t > 0 proven by a conservative error bound.
#[inline]
pub fn intersect_triangle(o: Vec3A, d: Vec3A, t_max: f32, tri: &[Vec3A; 3]) -> Option<(f32, [f32; 3])> {
    ShearedRay::new(o, d).intersect(t_max, tri)
}

/// A ray's part of the watertight test, computed once per ray rather than once per triangle:
/// which axis becomes z (the largest |dᵢ|) and the shear (sx, sy, sz) that maps d onto +z.
#[derive(Clone, Copy)]
pub struct ShearedRay {
    o: Vec3A,
    d: Vec3A,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl ShearedRay {
    #[inline]
    pub fn new(o: Vec3A, d: Vec3A) -> Self {
        let kz = max_dim(d.abs());
        // Selected, not branched on: kz is random from ray to ray, and a branch on it here
        // mispredicted about every other ray.
        let (k0, k1) = (glam::BVec3A::splat(kz == 0), glam::BVec3A::splat(kz == 1));
        let pd = Vec3A::select(k0, d.yzx(), Vec3A::select(k1, d.zxy(), d));
        // One vector division for the three (each lane rounds as the scalar division would):
        // three dependent scalar ones delayed every ray's first triangle test.
        let s = Vec3A::new(-pd.x, -pd.y, 1.0) / Vec3A::splat(pd.z);
        ShearedRay { o, d, kz, sx: s.x, sy: s.y, sz: s.z }
    }

    /// (v[kx], v[ky], v[kz]) with kx, ky the two axes after kz, cyclically.
    #[inline(always)]
    fn permute_for(kz: usize, v: Vec3A) -> Vec3A {
        match kz {
            0 => v.yzx(),
            1 => v.zxy(),
            _ => v,
        }
    }

    #[inline(always)]
    pub fn intersect(&self, t_max: f32, tri: &[Vec3A; 3]) -> Option<(f32, [f32; 3])> {
        let (o, kz, sx, sy, sz) = (self.o, self.kz, self.sx, self.sy, self.sz);
        let mut p0 = Self::permute_for(kz, tri[0] - o);
        let mut p1 = Self::permute_for(kz, tri[1] - o);
        let mut p2 = Self::permute_for(kz, tri[2] - o);
        p0.x += sx * p0.z;
        p0.y += sy * p0.z;
        p1.x += sx * p1.z;
        p1.y += sy * p1.z;
        p2.x += sx * p2.z;
        p2.y += sy * p2.z;

        let e0 = difference_of_products(p1.x, p2.y, p1.y, p2.x);
        let e1 = difference_of_products(p2.x, p0.y, p2.y, p0.x);
        let e2 = difference_of_products(p0.x, p1.y, p0.y, p1.x);
        if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
            return None;
        }
        let det = e0 + e1 + e2;
        if det == 0.0 {
            return None;
        }
        p0.z *= sz;
        p1.z *= sz;
        p2.z *= sz;
        let t_scaled = e0 * p0.z + e1 * p1.z + e2 * p2.z;
        if det < 0.0 && (t_scaled >= 0.0 || t_scaled < t_max * det) {
            return None;
        }
        if det > 0.0 && (t_scaled <= 0.0 || t_scaled > t_max * det) {
            return None;
        }
        let inv_det = 1.0 / det;
        let t = t_scaled * inv_det;
        if !(t < t_max) {
            return None;
        }

        // Conservative bound on t's error, so that t > 0 is certain (pbrt-v4 §6.8.4).
        let max_zt = p0.z.abs().max(p1.z.abs()).max(p2.z.abs());
        let delta_z = gamma(3) * max_zt;
        let max_xt = p0.x.abs().max(p1.x.abs()).max(p2.x.abs());
        let max_yt = p0.y.abs().max(p1.y.abs()).max(p2.y.abs());
        let delta_x = gamma(5) * (max_xt + max_zt);
        let delta_y = gamma(5) * (max_yt + max_zt);
        let delta_e = 2.0 * (gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
        let max_e = e0.abs().max(e1.abs()).max(e2.abs());
        let delta_t = 3.0 * (gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * inv_det.abs();
        if t <= delta_t {
            // The f32 bound cannot prove t > 0. Near a concave edge a genuine hit can sit closer than
            // that bound (it grows with the triangle's size), and rejecting it would let the photon
            // leak: decide again in f64, whose bound is 2^29 times tighter.
            return intersect_triangle_f64(o, self.d, t_max, tri);
        }
        Some((t, [e0 * inv_det, e1 * inv_det, e2 * inv_det]))
    }
}

/// γ(n) for f64 arithmetic.
fn gamma64(n: i32) -> f64 {
    let e = f64::EPSILON * 0.5;
    (n as f64 * e) / (1.0 - n as f64 * e)
}

/// The same watertight test carried out in f64 (the f32 inputs are exact in f64).
#[cold]
fn intersect_triangle_f64(o: Vec3A, d: Vec3A, t_max: f32, tri: &[Vec3A; 3]) -> Option<(f32, [f32; 3])> {
    use glam::DVec3;
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    let kz = max_dim(d.abs().as_vec3a());
    let kx = if kz == 2 { 0 } else { kz + 1 };
    let ky = if kx == 2 { 0 } else { kx + 1 };
    let perm = |v: DVec3| DVec3::new(v[kx], v[ky], v[kz]);
    let d = perm(d);
    let mut p = tri.map(|v| perm(v.as_dvec3() - o));
    let (sx, sy, sz) = (-d.x / d.z, -d.y / d.z, 1.0 / d.z);
    for q in &mut p {
        q.x += sx * q.z;
        q.y += sy * q.z;
    }
    let e0 = p[1].x * p[2].y - p[1].y * p[2].x;
    let e1 = p[2].x * p[0].y - p[2].y * p[0].x;
    let e2 = p[0].x * p[1].y - p[0].y * p[1].x;
    if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
        return None;
    }
    let det = e0 + e1 + e2;
    if det == 0.0 {
        return None;
    }
    for q in &mut p {
        q.z *= sz;
    }
    let t_scaled = e0 * p[0].z + e1 * p[1].z + e2 * p[2].z;
    let t_max = t_max as f64;
    if (det < 0.0 && (t_scaled >= 0.0 || t_scaled < t_max * det))
        || (det > 0.0 && (t_scaled <= 0.0 || t_scaled > t_max * det))
    {
        return None;
    }
    let inv_det = 1.0 / det;
    let t = t_scaled * inv_det;
    let max_zt = p.iter().map(|q| q.z.abs()).fold(0.0, f64::max);
    let max_xt = p.iter().map(|q| q.x.abs()).fold(0.0, f64::max);
    let max_yt = p.iter().map(|q| q.y.abs()).fold(0.0, f64::max);
    let delta_z = gamma64(3) * max_zt;
    let delta_x = gamma64(5) * (max_xt + max_zt);
    let delta_y = gamma64(5) * (max_yt + max_zt);
    let delta_e = 2.0 * (gamma64(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
    let max_e = e0.abs().max(e1.abs()).max(e2.abs());
    let delta_t = 3.0 * (gamma64(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * inv_det.abs();
    // The hit is reported in f32: it must also be a positive f32 distance.
    if t <= delta_t || (t as f32) <= 0.0 || !((t as f32) < t_max as f32) {
        return None;
    }
    Some((t as f32, [(e0 * inv_det) as f32, (e1 * inv_det) as f32, (e2 * inv_det) as f32]))
}

/// Orthonormal basis around unit `n` (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
#[inline]
pub fn basis(n: Vec3A) -> (Vec3A, Vec3A) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = Vec3A::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let s = Vec3A::new(b, sign + n.y * n.y * a, -n.y);
    (t, s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_edge_is_hit_exactly_once() {
        // Two triangles sharing the diagonal of the unit square; rays aimed exactly at the diagonal.
        let a = [Vec3A::new(0.0, 0.0, 0.0), Vec3A::new(1.0, 0.0, 0.0), Vec3A::new(1.0, 1.0, 0.0)];
        let b = [Vec3A::new(0.0, 0.0, 0.0), Vec3A::new(1.0, 1.0, 0.0), Vec3A::new(0.0, 1.0, 0.0)];
        for k in 1..100 {
            let s = k as f32 / 100.0;
            let o = Vec3A::new(s, s, 1.0);
            let d = Vec3A::new(0.0, 0.0, -1.0);
            let hits = intersect_triangle(o, d, f32::INFINITY, &a).is_some() as u32
                + intersect_triangle(o, d, f32::INFINITY, &b).is_some() as u32;
            assert!(hits >= 1, "ray at {s} slipped through the shared edge");
        }
    }

    /// A 3-4-5 triangle's least height is 2·6/5 = 2.4, rounded down; a degenerate one's is 0.
    #[test]
    fn least_height_is_twice_the_area_over_the_longest_edge() {
        let h = least_height(&[Vec3A::ZERO, Vec3A::new(3.0, 0.0, 0.0), Vec3A::new(0.0, 4.0, 0.0)]);
        assert!(h as f64 <= 2.4 && h as f64 > 2.4 * (1.0 - 1e-7), "{h}");
        assert_eq!(least_height(&[Vec3A::ZERO, Vec3A::X, 2.0 * Vec3A::X]), 0.0);
    }

    /// The tangent comes back from its two in-plane components as the unit projection of the
    /// direction given, at every scale; zero where that direction is the normal.
    #[test]
    fn tangent_is_kept_in_the_plane() {
        use rand_xoshiro::rand_core::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(3);
        let mut u = move || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
        let (mut tris, mut tangents) = (Vec::new(), Vec::new());
        for k in 0..300 {
            let (scale, centre) = [(1e-3, 0.0), (1.0, 0.0), (1.0, 1e4)][k % 3];
            let mut v = || Vec3A::new(u(), u(), u()) * scale + centre;
            tris.push([v(), v(), v()]);
            tangents.push(Vec3A::new(u(), u(), u()));
        }
        let n = tris.len();
        let given: Vec<([Vec3A; 3], Vec3A)> = tris.iter().copied().zip(tangents.iter().copied()).collect();
        let geo = Geometry::build_with_tangents(tris, (0..n as u32).collect(), tangents).unwrap();
        for p in 0..n {
            let (v, t) = given[geo.surface_of(p) as usize];
            let normal = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
            let expected = (t - normal * normal.dot(t)).normalize();
            assert!((geo.tangent(p) - expected).length() < 1e-5, "{} against {expected}", geo.tangent(p));
        }
        let flat = [Vec3A::ZERO, Vec3A::X, Vec3A::Y];
        let geo = Geometry::build_with_tangents(vec![flat], vec![0], vec![Vec3A::Z]).unwrap();
        assert_eq!(geo.tangent(0), Vec3A::ZERO);
    }

    /// `step_away` moves each component as `next_up` / `next_down` would, bit for bit: random
    /// values of every magnitude and sign, and zeros, subnormals, the largest finite values,
    /// infinities and NaN, each with a positive, negative, zero and NaN offset.
    #[test]
    fn step_away_gives_next_up_and_next_down_bits() {
        let reference = |x: f32, offset: f32| {
            if offset > 0.0 {
                x.next_up()
            } else if offset < 0.0 {
                x.next_down()
            } else {
                x
            }
        };
        let special = [
            0.0,
            -0.0,
            f32::from_bits(1),
            -f32::from_bits(1),
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            1.0,
            -1.0,
        ];
        let offsets = [1.0, -1.0, 0.0, -0.0, f32::NAN, f32::from_bits(1), -f32::from_bits(1)];
        let mut rng = 0x9E37_79B9_7F4A_7C15u64;
        let mut random = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            f32::from_bits((rng >> 32) as u32)
        };
        let mut xs: Vec<f32> = special.to_vec();
        xs.extend((0..20_000).map(|_| random()));
        for (k, &x) in xs.iter().enumerate() {
            for &o in &offsets {
                // Each lane with its own x and offset, the neighbours' chosen to differ.
                let (x3, o3) = ([x, xs[(k + 1) % xs.len()], -x], [o, -o, offsets[k % offsets.len()]]);
                let got = step_away(Vec3A::from_array(x3), Vec3A::from_array(o3)).to_array();
                for i in 0..3 {
                    let want = reference(x3[i], o3[i]);
                    assert_eq!(got[i].to_bits(), want.to_bits(), "x {:e} offset {:e} lane {i}", x3[i], o3[i]);
                }
            }
        }
    }

    /// Leaving a hit at any barycentrics, on an edge, a hair inside it or well inside, at scales
    /// from 1e-3 to 3e4 off the origin, `spawn_from` puts the origin strictly on the side the ray
    /// leaves by and over the triangle's inside (barycentrics of its projection all positive, in
    /// f64): what keeps a ray from starting behind a wall that meets the edge. Where it takes the
    /// offset alone, the point was already 16 bounds inside; elsewhere it is `spawn` exactly.
    #[test]
    fn spawned_origins_lie_over_the_inside_and_off_the_plane() {
        use rand_xoshiro::rand_core::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(19);
        let mut u = move || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let (mut fast, mut pulled) = (0, 0);
        for (scale, centre) in [(1e-3f32, 0.0f32), (1.0, 0.0), (1.0, 1e4), (1e3, -3e4)] {
            let mut tris = Vec::new();
            for _ in 0..200 {
                let mut v = || (Vec3A::new(u(), u(), u()) - 0.5) * scale + centre;
                tris.push([v(), v(), v()]);
            }
            let n = tris.len();
            let geo = Geometry::build(tris, (0..n as u32).collect()).unwrap();
            for prim in 0..n as u32 {
                let v = geo.verts(prim as usize).map(|p| p.as_dvec3());
                let normal = geo.normal(prim as usize);
                for small in [0.0, 1e-7, 1e-5, 1e-3, 0.3] {
                    let share = u();
                    let mut b = [small, (1.0 - small) * share, (1.0 - small) * (1.0 - share)];
                    b.rotate_left(prim as usize % 3);
                    let (p, err) = geo.hit_point(&Hit { t: 0.0, prim, b });
                    let dir = (Vec3A::new(u(), u(), u()) - 0.5).normalize();
                    let origin = geo.spawn_from(p, err, prim, b, dir);
                    if origin == offset_ray_origin(p, err, normal, dir) && origin != geo.spawn(p, err, prim, dir) {
                        assert!(small > 0.0, "a point on an edge was not pulled");
                        fast += 1;
                    } else {
                        assert_eq!(origin, geo.spawn(p, err, prim, dir));
                        pulled += 1;
                    }
                    let o = origin.as_dvec3();
                    let n = (v[1] - v[0]).cross(v[2] - v[0]);
                    let side = (o - v[0]).dot(n) * dir.dot(normal) as f64;
                    assert!(side > 0.0, "scale {scale}: origin on the plane or behind it");
                    let area = |a: glam::DVec3, c: glam::DVec3| (c - a).cross(o - a).dot(n);
                    let inside = [area(v[1], v[2]), area(v[2], v[0]), area(v[0], v[1])];
                    assert!(inside.iter().all(|&w| w > 0.0), "scale {scale}, b {b:?}: origin over the outside");
                }
            }
        }
        // Both ways are tested: most interior points skip the pull, edge points never do.
        assert!(fast > 1000 && pulled > 1000, "{fast} offset alone, {pulled} pulled");
    }

    /// The tree finds the brute-force closest hit of every ray (same triangle and t, or a tie at
    /// equal t), and the AVX2 and portable node tests give the same bits.
    #[test]
    fn tree_matches_brute_force_and_both_node_tests_agree() {
        // The large scenes' tree (`wide_tree`: 3012 triangles) and the small scenes' own
        // (`small_tree`: 64), at scales from 1e-3 to 1e4 and 3e4 off the origin.
        // The large tree's boxes are the triangles' padded by 10⁻⁵ of their coordinates, so it is
        // not held to rays from far away: one aimed at a corner of the box from 1000 box sizes
        // off found the face beside the nearest one, an ulp of t farther (the nearest face's box
        // culled by the slab test's rounding of t = 3000). obvhs's quantised boxes did the same.
        const { assert!(52 + 12 == small_tree::MOST_TRIANGLES) };
        for (scale, offset) in [(1.0, 0.0), (1e-3, 0.0), (1e4, 0.0), (1.0, 3e4)] {
            tree_matches_brute_force(3000, scale, Vec3A::splat(offset), false);
            tree_matches_brute_force(52, scale, Vec3A::splat(offset), true);
        }
    }

    /// `random` small random triangles in a unit cube, plus a closed box of 12 around it, all
    /// scaled by `scale` and moved by `offset`; rays from inside the cube, axis-aligned ones
    /// (zero direction components) and rays aimed at the box's corners and edges among random
    /// ones, and (with `far`) rays from 1000 box sizes away at its corners and edges (rays that
    /// pass a corner by a rounding then hit nothing). The tree's hit is the brute-force closest
    /// hit and the shadow test agrees.
    fn tree_matches_brute_force(random: usize, scale: f32, offset: Vec3A, far: bool) {
        use rand_xoshiro::rand_core::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
        let mut u = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let place = |p: Vec3A| p * scale + offset;
        let mut tris = Vec::new();
        for _ in 0..random {
            let c = Vec3A::new(u(), u(), u());
            tris.push([c, c + 0.05 * Vec3A::new(u(), u(), u()), c + 0.05 * Vec3A::new(u(), u(), u())].map(place));
        }
        let corners = |i: usize| place(Vec3A::new((i & 1) as f32, ((i >> 1) & 1) as f32, (i >> 2) as f32) * 3.0 - 1.0);
        for [a, b, c, d] in [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]] {
            tris.push([corners(a), corners(b), corners(c)]);
            tris.push([corners(a), corners(c), corners(d)]);
        }
        let n = tris.len();
        let mut geo = Geometry::build(tris, (0..n as u32).collect()).unwrap();
        let simd = geo.simd;
        for k in 0..20_000 {
            let mut o = place(Vec3A::new(u(), u(), u()));
            let d = match k % 8 {
                0 => Vec3A::new(0.0, 0.0, if u() < 0.5 { 1.0 } else { -1.0 }),
                1 => Vec3A::new(-0.0, 1.0, 0.0),
                // A corner of the box, or the midpoint of two (an edge's, a face's or the box's
                // centre).
                2 => (corners(k / 8 % 8) - o).normalize(),
                3 => ((corners(k / 8 % 8) + corners((k / 8 + 1) % 8)) * 0.5 - o).normalize(),
                // From a thousand box sizes away, at a corner or the midpoint of two.
                4 | 5 if far => {
                    o = place(Vec3A::splat(0.5) + 3000.0 * (Vec3A::new(u(), u(), u()) - 0.5).normalize());
                    let edge = if k % 8 == 4 { 0 } else { 1 };
                    ((corners(k / 8 % 8) + corners((k / 8 + edge) % 8)) * 0.5 - o).normalize()
                }
                _ => (Vec3A::new(u(), u(), u()) - 0.5).normalize(),
            };
            // The shadow segment: half the cube's size.
            let shadow_t = 0.5 * scale;
            let mut brute: Option<(f32, u32)> = None;
            for prim in 0..n {
                if let Some((t, _)) = intersect_triangle(o, d, f32::INFINITY, &geo.verts(prim)) {
                    if brute.is_none_or(|(bt, _)| t < bt) {
                        brute = Some((t, prim as u32));
                    }
                }
            }
            geo.simd = false;
            let portable = geo.intersect(o, d, f32::INFINITY, NO_PRIM);
            let portable_free = geo.unoccluded(o, d, shadow_t, [NO_PRIM; 2]);
            geo.simd = simd;
            let fast = geo.intersect(o, d, f32::INFINITY, NO_PRIM);
            assert_eq!(portable.map(|h| (h.t.to_bits(), h.prim)), fast.map(|h| (h.t.to_bits(), h.prim)), "ray {k}");
            assert_eq!(portable_free, geo.unoccluded(o, d, shadow_t, [NO_PRIM; 2]), "ray {k}");
            // A ray from outside aimed at a corner can pass it by a rounding: then neither hits.
            let Some((bt, bp)) = brute else {
                assert!(far && matches!(k % 8, 4 | 5) && fast.is_none() && portable_free, "ray {k}: tree {fast:?}");
                continue;
            };
            let hit = fast.unwrap_or_else(|| panic!("ray {k}: brute ({bt}, {bp}), the tree none"));
            assert!(
                hit.t == bt
                    && (hit.prim == bp
                        || intersect_triangle(o, d, f32::INFINITY, &geo.verts(hit.prim as usize)).unwrap().0 == bt),
                "ray {k} (scale {scale}, offset {offset}): tree {hit:?}, brute ({bt}, {bp})"
            );
            assert_eq!(portable_free, !(bt < shadow_t), "ray {k}: shadow test");
        }
    }

    /// A room of five walls, a lamp below its ceiling and two blocks on its floor, every face a
    /// quad: the small-scene tree puts each wall and the lamp in a leaf under the root, and each
    /// node below the root holds one block's faces only (obvhs's tree had put half a wall and the
    /// lamp in a block's node, a box across half the room that most rays entered).
    #[test]
    fn small_tree_keeps_walls_at_the_root_and_blocks_apart() {
        let quad = |c: [[f32; 3]; 4]| {
            let v = c.map(Vec3A::from);
            [[v[0], v[1], v[2]], [v[0], v[2], v[3]]]
        };
        let block = |lo: [f32; 3], hi: [f32; 3]| {
            let [x0, y0, z0] = lo;
            let [x1, y1, z1] = hi;
            [
                quad([[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]]),
                quad([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]]),
                quad([[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]),
                quad([[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]]),
                quad([[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]]),
            ]
        };
        let mut quads = vec![
            quad([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 0.0, 1.0]]),
            quad([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0], [0.0, 1.0, 1.0]]),
            quad([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 1.0], [0.0, 1.0, 1.0]]),
            quad([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]]),
            quad([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.0, 1.0]]),
            quad([[0.4, 0.999, 0.4], [0.6, 0.999, 0.4], [0.6, 0.999, 0.6], [0.4, 0.999, 0.6]]),
        ];
        quads.extend(block([0.1, 0.0, 0.1], [0.4, 0.3, 0.4]));
        quads.extend(block([0.6, 0.0, 0.5], [0.9, 0.6, 0.8]));
        let tris: Vec<[Vec3A; 3]> = quads.concat();
        let n = tris.len();
        // Surfaces 0–4 the walls, 5 the lamp, 6 and 7 the blocks.
        let surface: Vec<u32> = (0..n as u32).map(|t| if t < 12 { t / 2 } else { 6 + (t - 12) / 10 }).collect();
        let geo = Geometry::build(tris, surface).unwrap();
        let shape = geo.bvh.as_ref().unwrap().shape();
        let surfaces_of = |(first, count): (u32, u32)| (first..first + count).map(|t| geo.surface[t as usize]);
        let in_root_leaves: Vec<u32> = shape[0].iter().flatten().flat_map(|&leaf| surfaces_of(leaf)).collect();
        for wall in 0..6 {
            assert_eq!(in_root_leaves.iter().filter(|&&s| s == wall).count(), 2, "surface {wall}: {shape:?}");
        }
        assert!(shape.len() >= 3, "{shape:?}");
        for node in &shape[1..] {
            let mut surfaces = node.iter().map(|leaf| leaf.expect("blocks' nodes hold leaves")).flat_map(surfaces_of);
            let first = surfaces.next().unwrap();
            assert!(first >= 6 && surfaces.all(|s| s == first), "{shape:?}");
        }
    }

    /// The large scenes' tree (`wide_tree`) over a sphere of 20 480 triangles: every triangle in
    /// exactly one leaf, and the SAH programme fills the wide nodes (more than 6 children a node
    /// on average, here 6.6; on the 1.3 M-triangle icosphere 7.2, where a greedy collapse that
    /// opened the largest child while a slot was free left 4.2) and its leaves (2.8 triangles a
    /// leaf here; 1.8 with the paper's costs, which price a leaf by its triangles alone).
    #[test]
    fn wide_tree_leaves_hold_each_triangle_once_in_full_nodes() {
        let mut tris: Vec<[Vec3A; 3]> = Vec::new();
        let (rings, segments) = (80, 128);
        let at = |i: usize, j: usize| {
            let (theta, phi) =
                (std::f32::consts::PI * i as f32 / rings as f32, std::f32::consts::TAU * j as f32 / segments as f32);
            Vec3A::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
        };
        for i in 0..rings {
            for j in 0..segments {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
        let n = tris.len();
        let geo = Geometry::build(tris, vec![0; n]).unwrap();
        let shape = geo.bvh.as_ref().unwrap().shape();
        let seen = leaves_holding_each_triangle(&geo);
        assert!(seen.iter().all(|&k| k == 1), "a triangle in {} leaves", seen.iter().max().unwrap());
        let children: usize = shape.iter().map(Vec::len).sum();
        let fill = children as f64 / shape.len() as f64;
        // Leaves cost about a node's visit whatever their count (`wide_tree::C_LEAF`), so some
        // nodes keep a slot free where one leaf of three beats three of one.
        assert!(fill > 6.0, "{fill} children a node over {} nodes", shape.len());
        let leaves = shape.iter().flatten().flatten().count();
        let per_leaf = n as f64 / leaves as f64;
        assert!(per_leaf > 2.0, "{per_leaf} triangles a leaf");
        assert!(geo.bvh.as_ref().unwrap().depth() <= bvh::MOST_LEVELS);
    }

    /// Coordinates near f32's limit, whose box areas overflow f32 (the programme's f32 costs
    /// were then all ∞: the whole scene became one leaf of 80, which a leaf reference cannot
    /// hold, or with that fixed a chain of one-child nodes refused as too deep): the tree is
    /// built and holds each triangle once. (Scenes are refused beyond 10¹⁵ m, and the
    /// watertight test's products overflow near 10¹⁹; `Geometry::build` takes any f32.)
    #[test]
    fn wide_tree_survives_overflowing_areas() {
        let n = 80;
        let tris: Vec<[Vec3A; 3]> = (0..n)
            .map(|k| {
                let x = (k as f32 - 40.0) * 1e36;
                [Vec3A::new(x, -1e37, 1e37), Vec3A::new(x, 1e37, 1e37), Vec3A::new(x + 5e35, 0.0, -1e37)]
            })
            .collect();
        let geo = Geometry::build(tris, (0..n as u32).collect()).unwrap();
        let seen = leaves_holding_each_triangle(&geo);
        assert!(seen.len() == n && seen.iter().all(|&k| k == 1), "{seen:?}");
    }

    /// For each triangle, how many of the tree's leaves hold it.
    fn leaves_holding_each_triangle(geo: &Geometry) -> Vec<u32> {
        let mut seen = vec![0u32; geo.len()];
        for &(first, count) in geo.bvh.as_ref().unwrap().shape().iter().flatten().flatten() {
            (first..first + count).for_each(|t| seen[t as usize] += 1);
        }
        seen
    }

    /// A disk of 3·10⁴ sliver triangles all meeting at its centre makes a tree too deep for the
    /// traversal's stack: the scene is refused with a message, not traced into an overflow.
    #[test]
    fn a_tree_too_deep_to_trace_is_refused() {
        let segments = 30_000;
        let rim = |k: usize| {
            let phi = std::f64::consts::TAU * k as f64 / segments as f64;
            Vec3A::new(phi.cos() as f32, phi.sin() as f32, 0.0)
        };
        let tris: Vec<[Vec3A; 3]> = (0..segments).map(|k| [Vec3A::ZERO, rim(k), rim(k + 1)]).collect();
        let Err(message) = Geometry::build(tris, vec![0; segments]) else { panic!("the disk's tree was traced") };
        assert!(message.contains("levels deep") && message.contains("30000 triangles"), "{message}");
    }

    /// The AVX2 leaf lanes (`leaf4`) give the scalar test's bits: the same hit (t, triangle,
    /// barycentrics; and the same shadow answers), on paths that bounce around a tessellated room
    /// (rays leaving surfaces at concave corners and shared edges, where the f64 test decides)
    /// at millimetre to kilometre scales, with rays aimed exactly at edges and vertices.
    #[test]
    fn leaf_lanes_give_the_scalar_bits() {
        use rand_xoshiro::rand_core::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(11);
        let mut u = move || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        for (scale, centre) in [(1e-3f32, 0.0f32), (1.0, 0.0), (1.0, 1e4), (1e3, 0.0), (1e4, -3e4)] {
            // A closed unit cube, each face a 4 × 4 grid of squares, and 200 small random triangles.
            let at = |p: Vec3A| (p - 0.5) * scale + centre;
            let mut tris = grid_cube(4, at);
            for _ in 0..200 {
                let c = Vec3A::new(u(), u(), u()) * 0.8 + 0.1;
                tris.push([c, c + 0.1 * Vec3A::new(u(), u(), u()), c + 0.1 * Vec3A::new(u(), u(), u())].map(at));
            }
            let n = tris.len();
            let mut geo = Geometry::build(tris, (0..n as u32).collect()).unwrap();
            if !geo.simd {
                return; // no AVX2 here: only the scalar test runs
            }
            // Leaves of more than four: both passes of the lanes run, for hits and shadow rays.
            let most = geo.bvh.as_ref().unwrap().shape().iter().flatten().flatten().map(|l| l.1).max();
            assert!(geo.big_leaves && most > Some(4), "leaves of at most {most:?}");
            let cast = |geo: &mut Geometry, o: Vec3A, d: Vec3A, t_max: f32, skip: u32| {
                geo.simd = false;
                let scalar = geo.intersect(o, d, t_max, skip);
                let scalar_free = geo.unoccluded(o, d, t_max, [skip, NO_PRIM]);
                geo.simd = true;
                let lanes = geo.intersect(o, d, t_max, skip);
                let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.b.map(f32::to_bits)));
                assert_eq!(bits(scalar), bits(lanes), "scale {scale}: ray {o} {d} up to {t_max}");
                assert_eq!(scalar_free, geo.unoccluded(o, d, t_max, [skip, NO_PRIM]), "scale {scale}: {o} {d}");
                lanes
            };
            for k in 0..4000 {
                // Aimed at a grid vertex, a grid edge's midpoint, or anywhere.
                let target = match k % 3 {
                    0 => at(Vec3A::new((k % 5) as f32 / 4.0, ((k / 5) % 5) as f32 / 4.0, 1.0)),
                    1 => at(Vec3A::new(0.125 + (k % 4) as f32 / 4.0, 0.0, ((k / 4) % 5) as f32 / 4.0)),
                    _ => at(Vec3A::new(u(), u(), u()) * 1.2 - 0.1),
                };
                let mut o = at(Vec3A::new(u(), u(), u()) * 0.9 + 0.05);
                let mut d = (target - o).normalize();
                let mut skip = NO_PRIM;
                // A path of bounces, each leaving its surface as the photon loop does.
                for _ in 0..6 {
                    let t_max = if u() < 0.3 { scale * u() } else { f32::INFINITY };
                    let Some(hit) = cast(&mut geo, o, d, t_max, skip) else { break };
                    // A segment through the hit with the hit's triangle skipped, as `visible`
                    // skips both ends' (a lane left unmasked would report it blocked).
                    let end = 1.5 * hit.t;
                    geo.simd = false;
                    let scalar_free = geo.unoccluded(o, d, end, [skip, hit.prim]);
                    geo.simd = true;
                    assert_eq!(scalar_free, geo.unoccluded(o, d, end, [skip, hit.prim]), "{o} {d} to {end}");
                    // Back to the side it came from, at grazing angles too (where a corner's
                    // wall lies just ahead).
                    let (p, err);
                    (p, err, d) = bounce(&geo, &hit, d, [u() * 2.0 - 1.0, u() * 2.0 - 1.0, (1e-3 + u()).powi(3)]);
                    o = geo.spawn(p, err, hit.prim, d);
                    skip = hit.prim;
                }
            }
        }
    }

    /// Paths that bounce around a small room (each ray spawned off the triangle it leaves, as the
    /// photon loop spawns them) find with `intersect_leaving`, which passes over the flat leaf of
    /// the triangle left, the same hit as `intersect` and as brute force over every other
    /// triangle, its coplanar neighbours included: at millimetre to kilometre scales, from
    /// axis-aligned walls, a skewed wall that is no plane, a rotated block's vertical faces and a
    /// lamp flush with the ceiling, at grazing angles and aimed at edges and corners.
    #[test]
    fn rays_leaving_a_flat_leaf_find_what_every_triangle_finds() {
        use rand_xoshiro::rand_core::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(5);
        let mut u = move || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        for (scale, centre) in [(1e-3f32, 0.0f32), (1.0, 0.0), (1.0, 300.0), (1e3, 0.0), (1e4, -3e4)] {
            let at = |p: [f32; 3]| Vec3A::from_array(p) * scale + centre;
            let quad = |q: [[f32; 3]; 4]| [[at(q[0]), at(q[1]), at(q[2])], [at(q[0]), at(q[2]), at(q[3])]];
            let mut quads = vec![
                [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 0.0, 1.0]], // floor
                [[0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 0.0]], // ceiling
                [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 1.0], [0.0, 1.0, 1.0]], // back
                [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 1.0], [0.0, 1.0, 0.0]], // right
                // Left: skewed as the measured Cornell box's, its corners on no one plane.
                [[1.0, 0.0, 0.0], [0.99, 0.0, 1.0], [1.01, 1.0, 1.0], [1.0, 1.0, 0.0]],
                [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0]], // front
                // A lamp flush with the ceiling's plane, facing down.
                [[0.4, 1.0, 0.4], [0.6, 1.0, 0.4], [0.6, 1.0, 0.6], [0.4, 1.0, 0.6]],
            ];
            // A block turned about y: four vertical faces and a top, of exact corners.
            let base = [[0.25, 0.2], [0.5, 0.3], [0.4, 0.55], [0.15, 0.45]];
            for k in 0..4 {
                let ([x0, z0], [x1, z1]) = (base[k], base[(k + 1) % 4]);
                quads.push([[x0, 0.0, z0], [x1, 0.0, z1], [x1, 0.4, z1], [x0, 0.4, z0]]);
            }
            quads.push(base.map(|[x, z]| [x, 0.4, z]));
            let tris: Vec<[Vec3A; 3]> = quads.into_iter().flat_map(quad).collect();
            let n = tris.len();
            let geo = Geometry::build(tris, (0..n as u32).collect()).unwrap();
            assert!(!geo.big_leaves);
            let flat = geo.flat_leaf.iter().filter(|&&f| f != NO_PRIM).count();
            // Every quad but the skewed wall is flat (at 1e4 off the origin too: its coordinates
            // span less than 2^16); the lamp may share the ceiling's leaf.
            assert!(flat >= n - 2, "scale {scale}: {flat} of {n} triangles in flat leaves");
            let mut passed = 0;
            for k in 0..3000 {
                let mut o = at([u() * 0.9 + 0.05, u() * 0.9 + 0.05, u() * 0.9 + 0.05]);
                let target = match k % 3 {
                    0 => at([(k % 2) as f32, ((k / 2) % 2) as f32, ((k / 4) % 2) as f32]),
                    1 => at([0.5, 1.0, 0.4 + 0.2 * u()]),
                    _ => at([u() * 1.2 - 0.1, u() * 1.2 - 0.1, u() * 1.2 - 0.1]),
                };
                let mut d = (target - o).normalize();
                let mut skip = NO_PRIM;
                for _ in 0..6 {
                    let leaving = geo.intersect_leaving(o, d, f32::INFINITY, skip);
                    let whole = geo.intersect(o, d, f32::INFINITY, skip);
                    let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.b.map(f32::to_bits)));
                    assert_eq!(bits(leaving), bits(whole), "scale {scale}: {o} {d} leaving {skip}");
                    let mut brute: Option<f32> = None;
                    for prim in (0..n as u32).filter(|&p| p != skip) {
                        if let Some((t, _)) = intersect_triangle(o, d, f32::INFINITY, &geo.verts(prim as usize)) {
                            brute = Some(brute.map_or(t, |b| b.min(t)));
                        }
                    }
                    assert_eq!(leaving.map(|h| h.t), brute, "scale {scale}: {o} {d} leaving {skip}");
                    passed += geo.flat_leaf.get(skip as usize).is_some_and(|&f| f != NO_PRIM) as u32;
                    let Some(hit) = leaving else { break };
                    let (p, err);
                    (p, err, d) = bounce(&geo, &hit, d, [u() * 2.0 - 1.0, u() * 2.0 - 1.0, (1e-3 + u()).powi(3)]);
                    o = geo.spawn_from(p, err, hit.prim, hit.b, d);
                    skip = hit.prim;
                }
            }
            // Most rays left a flat leaf, so the pass was taken.
            assert!(passed > 10_000, "scale {scale}: {passed} rays left a flat leaf");
        }
    }

    /// A bounce off `hit` of a ray travelling along `d`: the hit point and its error bound, and
    /// the direction a·t₁ + b·t₂ + c·n (normalised) about the triangle's normal, back to the side
    /// the ray came from.
    fn bounce(geo: &Geometry, hit: &Hit, d: Vec3A, [a, b, c]: [f32; 3]) -> (Vec3A, Vec3A, Vec3A) {
        let (p, err) = geo.hit_point(hit);
        let ng = geo.normal(hit.prim as usize);
        let (t1, t2) = basis(ng);
        let side = if d.dot(ng) > 0.0 { -1.0 } else { 1.0 };
        (p, err, (t1 * a + t2 * b + ng * (side * c)).normalize())
    }

    /// The unit cube's six faces, each a grid × grid of squares (two triangles each), placed by `at`.
    fn grid_cube(grid: i32, at: impl Fn(Vec3A) -> Vec3A) -> Vec<[Vec3A; 3]> {
        let mut tris = Vec::new();
        for axis in 0..3 {
            for side in [0.0f32, 1.0] {
                for i in 0..grid {
                    for j in 0..grid {
                        let q = |di: i32, dj: i32| {
                            let (a, b) = ((i + di) as f32 / grid as f32, (j + dj) as f32 / grid as f32);
                            at(match axis {
                                0 => Vec3A::new(side, a, b),
                                1 => Vec3A::new(b, side, a),
                                _ => Vec3A::new(a, b, side),
                            })
                        };
                        tris.push([q(0, 0), q(1, 0), q(1, 1)]);
                        tris.push([q(0, 0), q(1, 1), q(0, 1)]);
                    }
                }
            }
        }
        tris
    }

    /// `intersect_many` walks rays in turns in a tree that outgrows the caches and one by one in
    /// a small one: either way each hit is `intersect_leaving`'s, bit for bit, for rays leaving
    /// triangles or free, with infinite and finite t_max, in groups of any size (partial turns).
    #[test]
    fn many_rays_walked_in_turns_give_intersect_leavings_bits() {
        use rand_xoshiro::rand_core::{Rng, SeedableRng};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(23);
        let mut u = move || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        for (grid, scale, centre) in [(64, 1.0f32, 0.0f32), (64, 1e3, -3e3), (4, 1.0, 0.0)] {
            // A closed unit cube, each face a grid × grid of squares, and 300 random triangles.
            let at = |p: Vec3A| (p - 0.5) * scale + centre;
            let mut tris = grid_cube(grid, at);
            for _ in 0..300 {
                let c = Vec3A::new(u(), u(), u()) * 0.8 + 0.1;
                tris.push([c, c + 0.1 * Vec3A::new(u(), u(), u()), c + 0.1 * Vec3A::new(u(), u(), u())].map(at));
            }
            let n = tris.len();
            let geo = Geometry::build(tris, (0..n as u32).collect()).unwrap();
            // The fine grid's tree takes the turns (where the CPU has AVX2), the coarse one not.
            assert_eq!(geo.bvh.as_ref().unwrap().is_large(), grid == 64, "grid {grid}");
            // Without AVX2 every group goes one by one, and only that is compared.
            let turns = geo.simd && grid == 64;
            println!("grid {grid}: rays walked in turns: {turns}");
            // Bouncing paths: each ray leaves the triangle the one before hit. Every fourth path
            // starts along an axis (a zero direction component: the walk's `still` boxes).
            let axes = [Vec3A::X, Vec3A::NEG_Y, Vec3A::Z, Vec3A::new(0.6, 0.0, -0.8)];
            let mut rays = Vec::new();
            while rays.len() < 3000 {
                let mut o = at(Vec3A::new(u(), u(), u()) * 0.9 + 0.05);
                let mut d = match rays.len() % 4 {
                    0 => axes[(rays.len() / 4) % axes.len()],
                    _ => (Vec3A::new(u(), u(), u()) - 0.5).normalize(),
                };
                let mut leaving = NO_PRIM;
                for k in 0..5 {
                    let t_max = if k % 2 == 1 { scale * u() } else { f32::INFINITY };
                    rays.push(RayQuery { origin: o, dir: d, t_max, leaving });
                    let Some(hit) = geo.intersect_leaving(o, d, f32::INFINITY, leaving) else { break };
                    let (p, err);
                    (p, err, d) = bounce(&geo, &hit, d, [u() * 2.0 - 1.0, u() * 2.0 - 1.0, 1e-3 + u()]);
                    o = geo.spawn_from(p, err, hit.prim, hit.b, d);
                    leaving = hit.prim;
                }
            }
            let bits = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.b.map(f32::to_bits)));
            let mut hits = vec![None; rays.len()];
            let (mut from, mut group, mut found) = (0, 1, 0);
            while from < rays.len() {
                let to = (from + group).min(rays.len());
                geo.intersect_many(&rays[from..to], &mut hits[from..to]);
                for (r, &h) in rays[from..to].iter().zip(&hits[from..to]) {
                    let one = geo.intersect_leaving(r.origin, r.dir, r.t_max, r.leaving);
                    assert_eq!(bits(h), bits(one), "grid {grid}, scale {scale}: {r:?}");
                    found += h.is_some() as usize;
                }
                from = to;
                group = group % (3 * INTERLEAVE) + 7;
            }
            // Most rays hit something (a finite t_max stops some short).
            assert!(found > rays.len() / 2, "grid {grid}: {found} of {} rays hit", rays.len());
        }
    }

    /// A ray leaving a large floor a hair from a wall of a concave corner meets the wall closer
    /// than the f32 error bound can prove positive: the leaf lanes mark it doubtful and the f64
    /// test decides, as in the scalar loop.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn leaf_lanes_send_doubtful_hits_to_the_f64_test() {
        if !bvh::simd_available() {
            return;
        }
        let floor = [Vec3A::new(0.0, -1e3, 0.0), Vec3A::new(1e3, -1e3, 0.0), Vec3A::new(0.0, 1e3, 0.0)];
        let wall = [Vec3A::new(0.0, -1e3, 0.0), Vec3A::new(0.0, 1e3, 0.0), Vec3A::new(0.0, 0.0, 1e3)];
        let geo = Geometry::build(vec![floor, wall], vec![0, 1]).unwrap();
        let wall_id = (0..2).find(|&i| geo.surface_of(i) == 1).unwrap() as u32;
        let floor_id = 1 - wall_id;
        let first = wall_id.min(floor_id);
        let k = wall_id - first;
        let mut doubtful = 0;
        // Origins ever closer to the wall, just above the floor, the ray running nearly along
        // the wall (the test's z axis is then along the wall, where its bound is loosest).
        for e in 1..10 {
            let o = Vec3A::new(10f32.powi(-e), 3.0, 1e-9);
            let d = Vec3A::new(-0.01, 1.0, 0.02).normalize();
            let ray = ShearedRay::new(o, d);
            // SAFETY: AVX2 and FMA are present; both triangles are in `tris`.
            let lanes = unsafe { leaf4::test(&ray, &geo.tris, first, 2, lanes_but(first, 2, floor_id), f32::INFINITY) };
            let scalar = ray.intersect(f32::INFINITY, &geo.verts(wall_id as usize));
            let lane = (lanes.candidates == 1 << k)
                .then(|| lanes.hit(k as usize, f32::INFINITY, &ray, &geo.tris[wall_id as usize]))
                .flatten();
            let bits = |h: Option<(f32, [f32; 3])>| h.map(|(t, b)| (t.to_bits(), b.map(f32::to_bits)));
            assert!(scalar.is_some(), "the wall is ahead of {o}");
            assert_eq!(bits(scalar), bits(lane), "from {o}");
            doubtful += (lanes.doubtful == 1 << k) as u32;
        }
        assert!(doubtful > 0, "no origin came within the f32 bound of the wall");
    }

    /// An axis-aligned ray (a collimated beam along an axis) is cut by the boxes on the axes it
    /// does not move along, so it visits about as many leaves as a tilted ray. Before, those axes
    /// were left uncut (their slab distances are NaN) and a ray straight down onto this grid met
    /// every leaf of the 20 000 triangles (the glass scene's collimated sun ran 100× slower).
    #[test]
    fn axis_aligned_rays_visit_few_leaves() {
        // A 100 × 100 grid of unit squares (two triangles each) in the plane z = 0.
        let mut tris = Vec::new();
        for i in 0..100 {
            for j in 0..100 {
                let p = |di: i32, dj: i32| Vec3A::new((i + di) as f32, (j + dj) as f32, 0.0);
                tris.push([p(0, 0), p(1, 0), p(1, 1)]);
                tris.push([p(0, 0), p(1, 1), p(0, 1)]);
            }
        }
        let n = tris.len();
        let geo = Geometry::build(tris, vec![0; n]).unwrap();
        let bvh = geo.bvh.as_ref().unwrap();
        let leaves_visited = |o: Vec3A, d: Vec3A| {
            let mut leaves = 0;
            let sheared = ShearedRay::new(o, d);
            let t = bvh.closest::<bvh::Portable>(
                o,
                d,
                f32::INFINITY,
                |_, _| {},
                |first, count, mut t_max| {
                    leaves += 1;
                    for id in first..first + count {
                        if let Some((t, _)) = sheared.intersect(t_max, &geo.verts(id as usize)) {
                            t_max = t_max.min(t);
                        }
                    }
                    t_max
                },
            );
            (leaves, t)
        };
        // Straight down from inside squares, from exactly over a grid line (bounds are
        // inclusive: the boxes on both sides contain it) and from a grid corner. These meet 1–4
        // leaves (the boxes that contain the point); the bound leaves room for another build of
        // the tree, and uncut they met all 10 000.
        for (x, y) in [(10.5, 20.25), (57.125, 3.5), (42.0, 42.5), (99.0, 0.0), (50.0, 50.0)] {
            let (leaves, t) = leaves_visited(Vec3A::new(x, y, 5.0), Vec3A::new(0.0, 0.0, -1.0));
            assert_eq!(t, 5.0, "({x}, {y}): the grid is hit 5 below");
            assert!(leaves <= 8, "({x}, {y}): {leaves} leaves for one axis-aligned ray");
        }
        // Along the grid's plane (z and y still) at x = 30.5: it runs in the plane of every
        // triangle, which the watertight test never reports as a hit, so nothing is found; the
        // boxes it passes are the row it runs along, not the whole grid.
        let (leaves, _) = leaves_visited(Vec3A::new(30.5, -1.0, 0.0), Vec3A::new(0.0, 1.0, 0.0));
        assert!(leaves <= 150, "{leaves} leaves for a ray along one row of 200 triangles");
    }

    #[test]
    fn offset_origin_is_on_the_leaving_side_at_any_scale() {
        for scale in [1e-3f32, 1.0, 1e3, 1e5] {
            let tri = [
                Vec3A::new(0.0, 0.0, 0.0) * scale + Vec3A::splat(scale),
                Vec3A::new(1.0, 0.0, 0.3) * scale + Vec3A::splat(scale),
                Vec3A::new(0.2, 1.0, 0.7) * scale + Vec3A::splat(scale),
            ];
            let geo = Geometry::build(vec![tri], vec![0]).unwrap();
            let n = geo.normal(0);
            let hit = Hit { t: 1.0, prim: 0, b: [0.3, 0.3, 0.4] };
            let (p, err) = geo.hit_point(&hit);
            for dir in [n, -n] {
                let o = offset_ray_origin(p, err, n, dir);
                let side = (o - geo.verts(0)[0]).as_dvec3().dot(n.as_dvec3());
                assert!(side * dir.dot(n) as f64 > 0.0, "offset origin on the wrong side at scale {scale}");
            }
        }
    }
}

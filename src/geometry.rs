//! Triangles, the BVH (obvhs CWBVH) and robust ray queries: a watertight ray–triangle test and
//! ray origins offset by the hit point's own floating-point error bound, so that scattering works
//! at millimetre and kilometre scales alike with no fixed epsilon.

use std::time::Duration;

// `UVec2` is named, unqualified, inside obvhs's `traverse!` macro.
use glam::{UVec2, Vec3A, Vec3Swizzles};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray;
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

/// A closest hit: distance along the (unit) ray, primitive, barycentrics of the vertices.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
    pub b: [f32; 3],
}

/// A triangle as the BVH sees it: its bounds padded so that the BVH's single-precision slab
/// tests are conservative. A planar face has a flat box, whose entry and exit distances coincide;
/// rounding can then put entry after exit and cull the node, and a photon slips out through an
/// edge. The padding is 2·f32::EPSILON in absolute terms and 1e-5 of the coordinates' magnitude
/// in relative terms (far above the slab test's few-ulp rounding, and the CWBVH's quantisation
/// only rounds boxes outward; far below any feature worth tracing).
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
/// its surface and its unit tangent. In a million-triangle mesh every hit is a cache miss; one
/// line per triangle makes it one miss, not one per table (vertices, normals, surfaces). The
/// tangent's components fill the three words the vec3s leave over, so it costs no space.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct PackedTriangle {
    a: [f32; 3],
    surface: u32,
    b: [f32; 3],
    tangent_x: f32,
    c: [f32; 3],
    tangent_y: f32,
    normal: [f32; 3],
    tangent_z: f32,
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
        let [a, b, c] = v.map(|p| p.to_array());
        let normal = n.to_array();
        PackedTriangle { a, surface, b, tangent_x: t.x, c, tangent_y: t.y, normal, tangent_z: t.z }
    }

    #[inline(always)]
    fn verts(&self) -> [Vec3A; 3] {
        [Vec3A::from_array(self.a), Vec3A::from_array(self.b), Vec3A::from_array(self.c)]
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
    bvh: Option<CwBvh>,
    /// Each triangle's unit vertex normals for smooth shading, zero for a flat triangle; empty
    /// when no triangle has any (`shading_normal`).
    shading: Vec<[Vec3A; 3]>,
}

impl Geometry {
    /// Builds the BVH and reorders triangles into its leaf order, so a BVH primitive id indexes
    /// the arrays directly.
    /// Fails (with a message for the user) only on a tree too deep to trace.
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
            return Ok(Geometry { tris: vec![], surface: vec![], local: vec![], bvh: None, shading: vec![] });
        }
        let padded: Vec<PaddedTriangle> = tris.iter().map(|t| PaddedTriangle(*t)).collect();
        // An 8-wide BVH with quantised child boxes (obvhs CWBVH): one 80-byte node per 8
        // children, so a ray through a million triangles fetches fewer, smaller nodes and misses
        // the caches far less (with the packing and prefetching below, ~1.9× faster there; the
        // Cornell box ~1.1×). Small leaves: with up to 8 triangles per leaf a Cornell
        // ray made about 10 triangle tests; with 3 (the most a CWBVH leaf holds) it traces as fast as
        // with 2, and faster than with 1.
        let params = BvhBuildParams { max_prims_per_leaf: 3, ..BvhBuildParams::medium_build() };
        let mut bvh = build_cwbvh(&padded, params, &mut Duration::default());
        // The traversal's stack holds 32 node groups and drops pushes beyond that (silently
        // skipping subtrees), so a deeper tree must not be traced. PLOC trees of real scenes are
        // ~10 levels deep; only a pathological input gets there (a disk of 10^5 segments: 131
        // levels, its sliver triangles all overlapping at the centre).
        let depth = cwbvh_depth(&bvh);
        if depth >= 32 {
            return Err(format!(
                "the scene's {} triangles make a ray-tracing tree {depth} levels deep, and photon traces at most 31: \
                 this comes from many long, thin triangles overlapping (a disk or fan of very many segments); \
                 use fewer segments or a better-shaped mesh",
                tris.len()
            ));
        }
        let order: Vec<usize> = bvh.primitive_indices.iter().map(|&i| i as usize).collect();
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
        for (k, idx) in bvh.primitive_indices.iter_mut().enumerate() {
            *idx = k as u32;
        }
        let tris = verts
            .iter()
            .zip(&surface)
            .zip(&order)
            .map(|((v, &s), &i)| PackedTriangle::new(v, s, tangents[i]))
            .collect();
        let shading = if shading.is_empty() { shading } else { order.iter().map(|&i| shading[i]).collect() };
        Ok(Geometry { tris, surface, local, bvh: Some(bvh), shading })
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
        Vec3A::new(t.tangent_x, t.tangent_y, t.tangent_z)
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
            from = self.spawn(p, err, hit.prim, dir);
            skip = hit.prim;
        }
        crossings
    }

    /// Closest hit along `origin + t·dir`, t in (0, t_max), ignoring primitive `skip` (the one the
    /// ray leaves: a flat triangle can never be hit again by a ray leaving it).
    #[inline]
    pub fn intersect(&self, origin: Vec3A, dir: Vec3A, t_max: f32, skip: u32) -> Option<Hit> {
        let bvh = self.bvh.as_ref()?;
        let mut ray = Ray::new(origin, dir, 0.0, t_max);
        let sheared = ShearedRay::new(origin, dir);
        let mut best: Option<Hit> = None;
        let mut state = bvh.new_traversal(dir);
        let mut node;
        obvhs::traverse!(bvh, node, state, self.intersect_node_prefetch(bvh, node, &ray, state.oct_inv4), {
            let id = state.primitive_id;
            if id != skip {
                if let Some((t, b)) = sheared.intersect(ray.tmax, &self.verts(id as usize)) {
                    if t < ray.tmax {
                        ray.tmax = t;
                        best = Some(Hit { t, prim: id, b });
                    }
                }
            }
        });
        best
    }

    /// True when nothing blocks the open segment from `origin` to `origin + t_max·dir`, ignoring
    /// the primitives `skip` (those the segment starts and ends on; NO_PRIM for none).
    pub fn unoccluded(&self, origin: Vec3A, dir: Vec3A, t_max: f32, skip: [u32; 2]) -> bool {
        let Some(bvh) = self.bvh.as_ref() else {
            return true;
        };
        let ray = Ray::new(origin, dir, 0.0, t_max);
        let sheared = ShearedRay::new(origin, dir);
        let mut state = bvh.new_traversal(dir);
        let mut node;
        let mut blocked = false;
        // The macro's `break` would leave only the current leaf group; the label ends the traversal.
        'traversal: {
            obvhs::traverse!(bvh, node, state, self.intersect_node_prefetch(bvh, node, &ray, state.oct_inv4), {
                let id = state.primitive_id;
                if !skip.contains(&id) && sheared.intersect(ray.tmax, &self.verts(id as usize)).is_some() {
                    blocked = true;
                    break 'traversal;
                }
            });
        }
        !blocked
    }

    /// `intersect_node`, then a prefetch of what the traversal reads next: the hit inner
    /// children's nodes and the hit leaves' triangles. In a large mesh those are cache misses;
    /// started now, they overlap with the work on the current group (the million-triangle
    /// benchmark traces ~3 % faster; the Cornell box is unchanged).
    #[inline(always)]
    fn intersect_node_prefetch(&self, bvh: &CwBvh, node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
        let hits = intersect_node(node, ray, oct_inv4);
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            // Every 64-byte line of an object (a node is 80 bytes; a triangle one aligned line).
            let line = |p: *const i8, bytes: usize| {
                let (first, last) = (p as usize & !63, (p as usize + bytes - 1) & !63);
                for a in (first..=last).step_by(64) {
                    // SAFETY: prefetching is only a hint and never faults.
                    unsafe { _mm_prefetch(a as *const i8, _MM_HINT_T0) };
                }
            };
            // Hit inner children, as the traversal finds them: bit 24 + (slot ^ octant) of the
            // mask; a child is stored at child_base_idx + the number of inner children in lower slots.
            let mut inner = hits >> 24;
            while inner != 0 {
                let slot = inner.trailing_zeros() ^ (oct_inv4 & 0xff);
                inner &= inner - 1;
                let below = node.imask as u32 & ((1u32 << slot) - 1);
                if let Some(child) = bvh.nodes.get(node.child_base_idx as usize + below.count_ones() as usize) {
                    line(child as *const CwBvhNode as *const i8, std::mem::size_of::<CwBvhNode>());
                }
            }
            // Hit leaves' triangles: bit k of the low 24 is primitive primitive_base_idx + k.
            let mut prims = hits & 0x00ff_ffff;
            while prims != 0 {
                let k = node.primitive_base_idx as usize + prims.trailing_zeros() as usize;
                prims &= prims - 1;
                if let Some(t) = self.tris.get(k) {
                    line(t as *const PackedTriangle as *const i8, std::mem::size_of::<PackedTriangle>());
                }
            }
        }
        hits
    }

    /// True when nothing lies strictly between two points, each offset off its own surface.
    /// The offsets cover only each point's own rounding, while a ray's hit distance errs by up to
    /// ~1e-6 of its length (pbrt-v4 §6.8.4). A long ray ending on a surface near the origin, where
    /// the offset is tiny, could then hit that surface short of its end, so the end's primitive
    /// is skipped and the segment stops `SHADOW_MARGIN` of its length short of each end (pbrt-v4: 1e-4).
    /// Without this, 1 in 1000 lamp-to-block connections in the Cornell box came out occluded one
    /// way and visible the other.
    pub fn visible(&self, a: RayEnd, b: RayEnd) -> bool {
        let dir = (b.p - a.p).normalize();
        let from = a.offset_toward(dir);
        let to = b.offset_toward(-dir);
        let seg = to - from;
        let len = seg.length();
        if !(len > 0.0) {
            return false;
        }
        // Trimmed at both ends alike, so that a → b and b → a test the same stretch.
        let dir = seg / len;
        self.unoccluded(from + dir * (len * SHADOW_MARGIN), dir, len * (1.0 - 2.0 * SHADOW_MARGIN), [a.prim, b.prim])
    }

    /// Origin of a ray leaving primitive `prim` at `p` (error bound `err`) along `dir`. A hit
    /// within rounding of an edge can be rounded onto the edge, or past it; where a wall meets
    /// that edge in a concave corner, a ray leaving toward the wall would then start on or
    /// behind the wall's plane and slip out of a closed room. So `p` is first pulled toward the
    /// triangle's centroid by 8 rounding bounds (a few 1e-6 of the coordinates), putting it
    /// inside the triangle again, then offset off the plane by `offset_ray_origin`.
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

/// Levels of a CWBVH (the root alone is 1).
fn cwbvh_depth(bvh: &CwBvh) -> usize {
    let mut deepest = 0;
    let mut todo = vec![(0usize, 1usize)];
    while let Some((n, d)) = todo.pop() {
        deepest = deepest.max(d);
        let Some(node) = bvh.nodes.get(n) else { continue };
        let inner = (node.imask as u32).count_ones() as usize;
        todo.extend((0..inner).map(|k| (node.child_base_idx as usize + k, d + 1)));
    }
    deepest
}

/// Which children of a CWBVH node the ray's segment [0, tmax] passes through, as the hit mask
/// obvhs's traversal wants. This is obvhs's SSE node test (`CwBvhNode::intersect_ray_simd`) with
/// one change: the near clip is 0, not its fixed 1e-4. In our metres that skipped every box
/// ending within 0.1 mm ahead of the ray's origin, so photons leaving a wall near a corner
/// missed the wall next to it and leaked out of closed rooms.
#[inline(always)]
fn intersect_node(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    let dir_inv = node.compute_extent() * ray.inv_direction;
    let orig = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let byte = |x: u64, b: usize| ((x >> (b * 8)) as u32) & 0xff;
    let hits = children_hit(node, ray, dir_inv, orig);
    let mut hit_mask = 0u32;
    for child in 0..8 {
        if hits & (1 << child) != 0 {
            hit_mask |= byte(child_bits8, child) << byte(bit_index8, child);
        }
    }
    hit_mask
}

/// Bit c set when child c's box (quantised: q·extent + p) meets the ray's [0, tmax]. Which slab
/// bound is the near one follows the sign of the inverse direction the distances are computed
/// with, not of the direction: obvhs inverts a component of −0.0 to −1/ε, and testing
/// `direction < 0` then swapped near and far and culled every box around the ray (half the
/// photons of a collimated beam whose normal came out as (−0, 1, 0) went through the floor).
/// A tiny component's inverse is clamped to ±1/ε; that can only make a box look hit, never missed.
/// A NaN bound (0·∞, kept for safety) leaves the box uncut on that axis.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn children_hit(node: &CwBvhNode, ray: &Ray, dir_inv: Vec3A, orig: Vec3A) -> u32 {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64; the loads read the node's own arrays.
    unsafe {
        let quad = |v: &[u8; 8], i: usize| {
            _mm_set_ps(v[i * 4 + 3] as f32, v[i * 4 + 2] as f32, v[i * 4 + 1] as f32, v[i * 4] as f32)
        };
        let mut hits = 0u32;
        for i in 0..2 {
            // _mm_max_ps/_mm_min_ps return their second operand when either is NaN: the running
            // bound goes second, so a NaN slab bound is ignored.
            let mut near = _mm_setzero_ps();
            let mut far = _mm_set1_ps(ray.tmax);
            for (lo, hi, inv, o, neg) in [
                (&node.child_min_x, &node.child_max_x, dir_inv.x, orig.x, ray.inv_direction.x < 0.0),
                (&node.child_min_y, &node.child_max_y, dir_inv.y, orig.y, ray.inv_direction.y < 0.0),
                (&node.child_min_z, &node.child_max_z, dir_inv.z, orig.z, ray.inv_direction.z < 0.0),
            ] {
                let (inv, o) = (_mm_set1_ps(inv), _mm_set1_ps(o));
                let (a, b) = (quad(lo, i), quad(hi, i));
                let (a, b) = if neg { (b, a) } else { (a, b) };
                near = _mm_max_ps(_mm_add_ps(_mm_mul_ps(a, inv), o), near);
                far = _mm_min_ps(_mm_add_ps(_mm_mul_ps(b, inv), o), far);
            }
            hits |= (_mm_movemask_ps(_mm_cmple_ps(near, far)) as u32) << (4 * i);
        }
        hits
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn children_hit(node: &CwBvhNode, ray: &Ray, dir_inv: Vec3A, orig: Vec3A) -> u32 {
    let neg = [ray.inv_direction.x < 0.0, ray.inv_direction.y < 0.0, ray.inv_direction.z < 0.0];
    let axes = [
        (&node.child_min_x, &node.child_max_x, dir_inv.x, orig.x),
        (&node.child_min_y, &node.child_max_y, dir_inv.y, orig.y),
        (&node.child_min_z, &node.child_max_z, dir_inv.z, orig.z),
    ];
    let mut hits = 0u32;
    for child in 0..8 {
        let (mut near, mut far) = (0.0f32, ray.tmax);
        for (axis, &(lo, hi, inv, o)) in axes.iter().enumerate() {
            let (a, b) = (lo[child] as f32 * inv + o, hi[child] as f32 * inv + o);
            let (a, b) = if neg[axis] { (b, a) } else { (a, b) };
            // f32::max/min ignore a NaN operand.
            near = near.max(a);
            far = far.min(b);
        }
        if near <= far {
            hits |= 1 << child;
        }
    }
    hits
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
    let mut po = p + offset;
    // Round away from p so the offset survives the addition's own rounding.
    for i in 0..3 {
        if offset[i] > 0.0 {
            po[i] = po[i].next_up();
        } else if offset[i] < 0.0 {
            po[i] = po[i].next_down();
        }
    }
    po
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
        let pd = Self::permute_for(kz, d);
        ShearedRay { o, d, kz, sx: -pd.x / pd.z, sy: -pd.y / pd.z, sz: 1.0 / pd.z }
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

    #[inline]
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

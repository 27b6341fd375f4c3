//! The ray-casting tree: an 8-wide BVH with full-precision child boxes laid out for one AVX2
//! slab test per node, traversed nearest child first with a compact stack.
//!
//! The nodes are filled (`Node8::set_child`) by `wide_tree`, which collapses obvhs's binary PLOC
//! tree, or for a small scene by `small_tree`. Child boxes are f32, rounded outward, so that a
//! node's eight children are tested at once with three FMAs per plane and a single
//! cache-line-aligned load each, with no dequantisation per ray. The AVX2 test is chosen
//! at run time; the portable one does the same arithmetic (fused multiply-adds, the same
//! max/min order), so a scene gives the same bits on every machine.

use std::mem::MaybeUninit;

use glam::Vec3A;
use obvhs::aabb::Aabb;

/// No child in a slot (`Node8::EMPTY` is a node with none).
const NO_CHILD: u32 = u32::MAX;
/// Marks a child reference as a leaf: `LEAF | first << COUNT_BITS | (count − 1)`.
const LEAF: u32 = 1 << 31;
/// The bits of a leaf reference that hold its count less one.
const COUNT_BITS: u32 = 3;
/// The most triangles a tree can index in its leaves' 28-bit start.
pub const MAX_TRIANGLES: usize = 1 << (31 - COUNT_BITS);
/// The most levels a tree may have (the root alone is 1); `wide_tree` refuses deeper ones.
pub const MOST_LEVELS: usize = 31;
/// Entries of the traversal stack: a walk keeps at most 7 per level above the one it is on and
/// pushes up to 8 there.
const STACK: usize = 7 * (MOST_LEVELS - 1) + 8;
/// The most triangles in a leaf (the count's bits; two passes of `leaf4`'s lanes).
pub const LEAF_MOST: u32 = 1 << COUNT_BITS;

/// A leaf reference's first triangle and count (`Node8::leaf`).
#[inline(always)]
fn leaf_parts(c: u32) -> (u32, u32) {
    ((c & !LEAF) >> COUNT_BITS, (c & (LEAF_MOST - 1)) + 1)
}

/// Eight children: their boxes as planes [lo x, hi x, lo y, hi y, lo z, hi z] × 8 lanes (one
/// 32-byte row per plane), and what each is (an inner node's index, a leaf, or `NO_CHILD`). 224 bytes,
/// padded to four cache lines by the alignment.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub struct Node8 {
    planes: [[f32; 8]; 6],
    child: [u32; 8],
}

impl Node8 {
    /// A node with no children.
    pub const EMPTY: Node8 = Node8 {
        planes: [
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
        ],
        child: [NO_CHILD; 8],
    };

    /// The child reference of a leaf of `count` (1..=LEAF_MOST) triangles from `first`.
    pub fn leaf(first: u32, count: u32) -> u32 {
        debug_assert!((1..=LEAF_MOST).contains(&count));
        LEAF | first << COUNT_BITS | (count - 1)
    }

    /// Puts `child` (a node's index or a `leaf`) in `slot` with the box [lo, hi].
    pub fn set_child(&mut self, slot: usize, child: u32, lo: [f32; 3], hi: [f32; 3]) {
        self.child[slot] = child;
        for axis in 0..3 {
            self.planes[2 * axis][slot] = lo[axis];
            self.planes[2 * axis + 1][slot] = hi[axis];
        }
    }

    /// Puts `child` in `slot` with the box `b` widened by `pad` and rounded outward to f32.
    pub fn set_child_box(&mut self, slot: usize, child: u32, b: &Aabb, pad: f64) {
        let lo = b.min.to_array().map(|x| ((x as f64 - pad) as f32).next_down());
        let hi = b.max.to_array().map(|x| ((x as f64 + pad) as f32).next_up());
        self.set_child(slot, child, lo, hi);
    }

    /// The indices of the inner nodes among the children.
    #[cfg(test)]
    pub fn inner_children(&self) -> impl Iterator<Item = u32> + '_ {
        self.child.iter().copied().filter(|&c| c != NO_CHILD && c & LEAF == 0)
    }
}

pub struct Bvh8 {
    nodes: Vec<Node8>,
    /// Whether the tree and its triangles outgrow the L2 cache, where prefetching pays (in the
    /// 32-triangle Cornell box it cost ~3 %; in the 1.3 M-triangle sphere it saved ~15 %).
    large: bool,
}

impl Bvh8 {
    /// Each node's children, in slot order: a leaf's first triangle and count, or None for an
    /// inner node.
    #[cfg(test)]
    pub fn shape(&self) -> Vec<Vec<Option<(u32, u32)>>> {
        let kind = |c: u32| if c & LEAF != 0 { Some(leaf_parts(c)) } else { None };
        self.nodes.iter().map(|n| n.child.iter().filter(|&&c| c != NO_CHILD).map(|&c| kind(c)).collect()).collect()
    }

    /// Every leaf's first triangle and count.
    pub fn leaves(&self) -> Vec<(u32, u32)> {
        self.nodes.iter().flat_map(|n| n.child).filter(|&c| c != NO_CHILD && c & LEAF != 0).map(leaf_parts).collect()
    }

    /// Levels of the tree (the root alone is 1).
    #[cfg(test)]
    pub fn depth(&self) -> usize {
        let mut deepest = 0;
        let mut todo = vec![(0usize, 1usize)];
        while let Some((n, d)) = todo.pop() {
            deepest = deepest.max(d);
            todo.extend(self.nodes[n].inner_children().map(|c| (c as usize, d + 1)));
        }
        deepest
    }

    /// A tree of `nodes`, the root first.
    pub fn from_nodes(nodes: Vec<Node8>, triangle_bytes: usize) -> Self {
        let large = nodes.len() * std::mem::size_of::<Node8>() + triangle_bytes > 1 << 20;
        // Copied into one block of its size, advised as huge pages before it is written
        // (`pages`): the vector grew by pushing, and its early pages stay 4 kB.
        let nodes = if large { nodes.to_vec() } else { nodes };
        Bvh8 { nodes, large }
    }

    /// Closest-hit traversal: `leaf(first, count, t_max)` tests a leaf's triangles and returns
    /// the new t_max (the nearest hit so far); children are visited nearest first and a stacked
    /// child is dropped once a hit lies before its box.
    #[inline(always)]
    pub fn closest<T: NodeTest>(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        t_max: f32,
        prefetch_leaf: impl Fn(u32, u32),
        mut leaf: impl FnMut(u32, u32, f32) -> f32,
    ) -> f32 {
        let ray = RayPlanes::new(origin, dir);
        // Chosen once a ray, so the usual ray's walk has no test for still axes.
        if ray.still != 0 {
            self.closest_walk::<T, true>(&ray, t_max, &prefetch_leaf, &mut leaf)
        } else {
            self.closest_walk::<T, false>(&ray, t_max, &prefetch_leaf, &mut leaf)
        }
    }

    #[inline(always)]
    fn closest_walk<T: NodeTest, const STILL: bool>(
        &self,
        ray: &RayPlanes,
        t_max: f32,
        prefetch_leaf: &impl Fn(u32, u32),
        leaf: &mut impl FnMut(u32, u32, f32) -> f32,
    ) -> f32 {
        // Uninitialised: zeroing 1.7 kB per ray cost 9 % of a Cornell ray. Entries below `sp`
        // are always written.
        let mut stack = WALK_STACK_UNSET;
        let mut sp = 0usize;
        let mut t_max = t_max;
        let mut at = 0u32;
        'walk: loop {
            if at & LEAF == 0 {
                let node = &self.nodes[at as usize];
                let (mut mask, near) = T::hits::<STILL>(node, ray, t_max);
                self.prefetch(node, mask, prefetch_leaf);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if mask == 0 {
                        at = node.child[first];
                        continue 'walk;
                    }
                    (at, sp) = push_nearest_last(node, first, mask, &near, &mut stack, sp);
                    continue 'walk;
                }
            } else {
                let (first, count) = leaf_parts(at);
                t_max = leaf(first, count, t_max);
            }
            loop {
                if sp == 0 {
                    return t_max;
                }
                sp -= 1;
                // SAFETY: entries below the old sp were written.
                let (next, near) = unsafe { stack[sp].assume_init() };
                if near <= t_max {
                    at = next;
                    continue 'walk;
                }
            }
        }
    }

    /// Whether the tree and its triangles outgrow the L2 cache (`large`).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub fn is_large(&self) -> bool {
        self.large
    }

    /// A closest-hit walk to be taken a step at a time (`closest_step`), on `stack`, which it
    /// keeps for its whole walk.
    #[inline(always)]
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub fn closest_start<'s>(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        t_max: f32,
        stack: &'s mut WalkStack,
    ) -> ClosestWalk<'s> {
        ClosestWalk { ray: RayPlanes::new(origin, dir), stack, sp: 0, t_max, at: 0 }
    }

    /// One node or leaf of walk `w`: `closest`'s steps, in its order, so the same leaves are
    /// tested with the same t_max. False once the walk has ended.
    /// Several rays' walks taking turns step by step give each ray's prefetched next node the
    /// others' steps to arrive in (`Geometry::intersect_many`).
    #[inline(always)]
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub fn closest_step<T: NodeTest>(
        &self,
        w: &mut ClosestWalk,
        prefetch_leaf: &impl Fn(u32, u32),
        mut leaf: impl FnMut(u32, u32, f32) -> f32,
    ) -> bool {
        let at = w.at;
        if at & LEAF == 0 {
            let node = &self.nodes[at as usize];
            let (mut mask, near) = if w.ray.still != 0 {
                T::hits::<true>(node, &w.ray, w.t_max)
            } else {
                T::hits::<false>(node, &w.ray, w.t_max)
            };
            self.prefetch(node, mask, prefetch_leaf);
            if mask != 0 {
                let first = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if mask == 0 {
                    w.at = node.child[first];
                    return true;
                }
                (w.at, w.sp) = push_nearest_last(node, first, mask, &near, w.stack, w.sp);
                return true;
            }
        } else {
            let (first, count) = leaf_parts(at);
            w.t_max = leaf(first, count, w.t_max);
        }
        while w.sp > 0 {
            w.sp -= 1;
            // SAFETY: entries below the old sp were written (the walk has had its stack
            // since `closest_start`, at height 0).
            let (next, near) = unsafe { w.stack[w.sp].assume_init() };
            if near <= w.t_max {
                w.at = next;
                return true;
            }
        }
        false
    }

    /// Starts loading what the traversal reads next: the hit inner children's four lines (three
    /// of box rows, then the child references, read right after the test) and (through
    /// `prefetch_leaf`, given a leaf's first triangle and count) the hit leaves' triangles. In a
    /// large mesh those are cache misses; started now they overlap with the work on this node.
    #[inline(always)]
    fn prefetch(&self, node: &Node8, mut mask: u32, prefetch_leaf: &impl Fn(u32, u32)) {
        if !self.large {
            return;
        }
        while mask != 0 {
            let c = node.child[mask.trailing_zeros() as usize];
            mask &= mask - 1;
            if c & LEAF != 0 {
                let (first, count) = leaf_parts(c);
                prefetch_leaf(first, count);
            } else if let Some(n) = self.nodes.get(c as usize) {
                let p = n as *const Node8 as *const u8;
                for line in 0..4 {
                    prefetch(p.wrapping_add(64 * line));
                }
            }
        }
    }

    /// Any-hit traversal: true as soon as `leaf(first, count, t_max)` reports a blocking hit.
    #[inline(always)]
    pub fn any<T: NodeTest>(
        &self,
        origin: Vec3A,
        dir: Vec3A,
        t_max: f32,
        prefetch_leaf: impl Fn(u32, u32),
        mut leaf: impl FnMut(u32, u32, f32) -> bool,
    ) -> bool {
        let ray = RayPlanes::new(origin, dir);
        if ray.still != 0 {
            self.any_walk::<T, true>(&ray, t_max, &prefetch_leaf, &mut leaf)
        } else {
            self.any_walk::<T, false>(&ray, t_max, &prefetch_leaf, &mut leaf)
        }
    }

    #[inline(always)]
    fn any_walk<T: NodeTest, const STILL: bool>(
        &self,
        ray: &RayPlanes,
        t_max: f32,
        prefetch_leaf: &impl Fn(u32, u32),
        leaf: &mut impl FnMut(u32, u32, f32) -> bool,
    ) -> bool {
        let mut stack = [MaybeUninit::<u32>::uninit(); STACK];
        let mut sp = 0usize;
        let mut at = 0u32;
        loop {
            if at & LEAF == 0 {
                let node = &self.nodes[at as usize];
                let (mut mask, _) = T::hits::<STILL>(node, ray, t_max);
                self.prefetch(node, mask, prefetch_leaf);
                if mask != 0 {
                    at = node.child[mask.trailing_zeros() as usize];
                    mask &= mask - 1;
                    while mask != 0 {
                        stack[sp].write(node.child[mask.trailing_zeros() as usize]);
                        sp += 1;
                        mask &= mask - 1;
                    }
                    continue;
                }
            } else {
                let (first, count) = leaf_parts(at);
                if leaf(first, count, t_max) {
                    return true;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            // SAFETY: entries below the old sp were written.
            at = unsafe { stack[sp].assume_init() };
        }
    }
}

/// A node's hit children, slot `first` and those of `rest` (not empty), pushed on `stack` from
/// height `sp` and ordered farthest first, so the nearest is on top: taken off again, it is the
/// child visited next. Returns it and the new height.
#[inline(always)]
fn push_nearest_last(
    node: &Node8,
    first: usize,
    mut rest: u32,
    near: &[f32; 8],
    stack: &mut WalkStack,
    mut sp: usize,
) -> (u32, usize) {
    let base = sp;
    stack[sp].write((node.child[first], near[first]));
    sp += 1;
    while rest != 0 {
        let k = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        let entry = (node.child[k], near[k]);
        let mut j = sp;
        // SAFETY: base ≤ j − 1 < sp, a written entry.
        while j > base && unsafe { stack[j - 1].assume_init() }.1 < entry.1 {
            stack[j] = stack[j - 1];
            j -= 1;
        }
        stack[j].write(entry);
        sp += 1;
    }
    sp -= 1;
    // SAFETY: sp < the count written.
    (unsafe { stack[sp].assume_init() }.0, sp)
}

/// A closest-hit walk between steps (`Bvh8::closest_step`): the ray, its stack and the stack's
/// height, its t_max, and the node or leaf visited next. The stack is borrowed, not held, so
/// that a walk is started without copying 1.7 kB (which cost ~100 ns a ray).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub struct ClosestWalk<'s> {
    ray: RayPlanes,
    stack: &'s mut WalkStack,
    sp: usize,
    t_max: f32,
    at: u32,
}

/// A walk's stack of children still to visit, with their entry distances. Left uninitialised
/// (`WALK_STACK_UNSET`), as in `closest_walk`; entries below the walk's height are written.
pub type WalkStack = [MaybeUninit<(u32, f32)>; STACK];
pub const WALK_STACK_UNSET: WalkStack = [MaybeUninit::uninit(); STACK];

/// A ray's part of the slab test, once per ray: 1/d, o/d (so each plane costs one FMA,
/// t = plane·(1/d) − o/d), and which plane row is the near one on each axis (the low plane where
/// 1/d ≥ 0, the sign bit of 1/d deciding, so −0 is consistently negative).
/// A zero component gives 1/d = ±∞ and t = plane·∞ − o·∞ = NaN, which leaves that axis uncut
/// (the max/min below keep their running bound). The ray never leaves its origin's coordinate
/// on such an axis, so there a box is kept only where it contains that coordinate
/// (`still_mask`): uncut, an axis-aligned ray (a collimated beam straight down) visited every
/// box its height range met, 100× the work in the glass scene. Nothing is clamped: clamping 1/d
/// shortens the far distance and can cull a box the ray runs along.
pub struct RayPlanes {
    inv: [f32; 3],
    o_inv: [f32; 3],
    near: [usize; 3],
    /// Bit a set where d's component a is ±0.
    still: u32,
    o: Vec3A,
}

impl RayPlanes {
    #[inline(always)]
    fn new(o: Vec3A, d: Vec3A) -> Self {
        // One vector division, the scalar ones' bits.
        let inv = (Vec3A::ONE / d).to_array();
        let still = d.cmpeq(Vec3A::ZERO).bitmask();
        let oa = o.to_array();
        let near = [0, 1, 2].map(|a| 2 * a + inv[a].is_sign_negative() as usize);
        RayPlanes { inv, o_inv: [0, 1, 2].map(|a| oa[a] * inv[a]), near, still, o }
    }

    /// The children whose boxes contain the origin's coordinate on every axis the ray does not
    /// move along (bounds included: a ray along a face stays in).
    #[inline(always)]
    fn still_mask(&self, node: &Node8) -> u32 {
        let o = self.o.to_array();
        let mut mask = 0xff;
        for (a, &oa) in o.iter().enumerate() {
            if self.still & (1 << a) != 0 {
                for k in 0..8 {
                    let inside = node.planes[2 * a][k] <= oa && node.planes[2 * a + 1][k] >= oa;
                    mask &= !((!inside as u32) << k);
                }
            }
        }
        mask
    }
}

/// Which of a node's children the ray's [0, t_max] meets (bit k for child k), and each child's
/// entry distance.
/// With `STILL` (a ray with a zero direction component) the boxes are also kept to those that
/// contain the origin's coordinate on the axes the ray does not move along (`still_mask`).
pub trait NodeTest {
    /// Whether a leaf's triangles are tested in AVX2 lanes (`leaf4`) rather than one by one.
    const LEAF_LANES: bool;
    fn hits<const STILL: bool>(node: &Node8, ray: &RayPlanes, t_max: f32) -> (u32, [f32; 8]);
}

/// The test lane by lane, in the AVX2 test's exact arithmetic.
pub struct Portable;

impl NodeTest for Portable {
    const LEAF_LANES: bool = false;
    #[inline(always)]
    fn hits<const STILL: bool>(node: &Node8, ray: &RayPlanes, t_max: f32) -> (u32, [f32; 8]) {
        let mut near = [0f32; 8];
        let mut mask = 0u32;
        for (k, entry) in near.iter_mut().enumerate() {
            let (mut lo, mut hi) = (0f32, t_max);
            for a in 0..3 {
                let tn = node.planes[ray.near[a]][k].mul_add(ray.inv[a], -ray.o_inv[a]);
                let tf = node.planes[ray.near[a] ^ 1][k].mul_add(ray.inv[a], -ray.o_inv[a]);
                // _mm256_max_ps(x, y) = if x > y { x } else { y }: a NaN x keeps y.
                lo = if tn > lo { tn } else { lo };
                hi = if tf < hi { tf } else { hi };
            }
            *entry = lo;
            mask |= ((lo <= hi) as u32) << k;
        }
        if STILL {
            mask &= ray.still_mask(node);
        }
        (mask, near)
    }
}

/// Eight children at once (AVX2 and FMA; only used where the CPU has them).
#[cfg(target_arch = "x86_64")]
pub struct Avx2;

#[cfg(target_arch = "x86_64")]
impl NodeTest for Avx2 {
    const LEAF_LANES: bool = true;
    #[inline(always)]
    fn hits<const STILL: bool>(node: &Node8, ray: &RayPlanes, t_max: f32) -> (u32, [f32; 8]) {
        use std::arch::x86_64::*;
        // SAFETY: called only from `#[target_feature(enable = "avx2,fma")]` functions, reached
        // only when the CPU reports both; the rows are 32-byte aligned (the node is 64-aligned).
        unsafe {
            let row = |i: usize| _mm256_load_ps(node.planes[i].as_ptr());
            let mut lo = _mm256_setzero_ps();
            let mut hi = _mm256_set1_ps(t_max);
            for a in 0..3 {
                let inv = _mm256_set1_ps(ray.inv[a]);
                let o_inv = _mm256_set1_ps(ray.o_inv[a]);
                let tn = _mm256_fmsub_ps(row(ray.near[a]), inv, o_inv);
                let tf = _mm256_fmsub_ps(row(ray.near[a] ^ 1), inv, o_inv);
                lo = _mm256_max_ps(tn, lo);
                hi = _mm256_min_ps(tf, hi);
            }
            let mut mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(lo, hi)) as u32;
            if STILL {
                mask &= ray.still_mask(node);
            }
            let mut near = [0f32; 8];
            _mm256_storeu_ps(near.as_mut_ptr(), lo);
            (mask, near)
        }
    }
}

/// A hint to bring the cache line at `p` in; never faults.
#[inline(always)]
pub fn prefetch(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint; it reads nothing and never faults.
    unsafe {
        std::arch::x86_64::_mm_prefetch(p as *const i8, std::arch::x86_64::_MM_HINT_T0)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Whether this CPU runs the AVX2 node test (`PHOTON_PORTABLE_BVH` set forces the portable one,
/// for comparing the two).
pub fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::env::var_os("PHOTON_PORTABLE_BVH").is_none()
            && is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

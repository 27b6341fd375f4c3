//! Surface points the camera sees with nothing in between, known without a ray.
//!
//! The light tracer connects each photon vertex in view to the pinhole with a shadow ray
//! (`Geometry::visible`). A blocker of the segment from vertex x on triangle T to the eye lies on
//! that segment, so it projects onto x's own image point, and it lies on the eye's side of T's
//! plane (the segment leaves x toward the eye). So in an image tile K no ray is needed for T's
//! points when every other triangle's part on the eye's side of T's plane has an image that
//! misses K. That is decided once a run, per tile of 4×4 pixels: T is *clear* in K.
//!
//! The eye's side is judged as `Geometry::visible` tests it: its segment starts SHADOW_MARGIN of
//! its length off T's plane, so only what rises above that height, less δ for rounding
//! (10⁻⁶ of the scene's extent plus the farthest distance), can block; that leaves out coplanar
//! neighbours and those meeting T at a convex edge. Each image is compared with the tile widened
//! by what rounding may move a point's f32 image (`CameraModel::project`, which picks the tile)
//! or a camera ray's direction, and by the ray's offset and rounding seen from the nearest depth
//! in view (a blocker's part nearer than that may be anywhere), so it agrees with the ray up to
//! the rounding bounds argued here. T's plane is taken in f64 from its vertices. A triangle
//! almost edge-on to the eye (|height of the eye over its plane| ≤ 10⁻³ of its distance) is
//! never clear.
//!
//! Built for scenes of up to `MAX_SCENE_TRIANGLES` triangles (a room, the Cornell box); a tile that more
//! than `MAX_CANDIDATES` triangles' images meet keeps the ray.

use std::collections::HashMap;

use glam::DVec3;

use crate::detectors::film::{CameraModel, PolygonImage, Projection};
use crate::geometry::{Geometry, SHADOW_MARGIN};

/// Pixels on a tile's side.
const TILE: usize = 4;
/// Scenes with more triangles keep every ray (the build compares triangles pairwise per tile).
pub const MAX_SCENE_TRIANGLES: usize = 4096;
/// Tiles that more triangles' images than this meet keep every ray.
const MAX_CANDIDATES: usize = 16;

pub struct ClearView {
    tiles_wide: usize,
    /// The ray's offset and rounding seen from the nearest depth in view, in pixels (`new`).
    spread: f64,
    /// Tile k's clear triangles are `prims[start[k]..start[k + 1]]`.
    start: Vec<u32>,
    prims: Vec<u32>,
}

/// A rectangle of the image in continuous pixel coordinates: [column lo, hi], [row lo, hi].
pub type Rect = ([f64; 2], [f64; 2]);

/// Whether a polygon's image meets `rect` (separating axes: the rectangle's two and the
/// polygon's edge normals; the image of a convex polygon in front of the eye is convex).
pub fn meets(image: &PolygonImage, rect: &Rect) -> bool {
    let corners = match image {
        PolygonImage::Anywhere => return true,
        PolygonImage::Corners(corners, _) => corners,
    };
    let (lo, hi) = corners.iter().fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), c| {
        ([lo[0].min(c[0]), lo[1].min(c[1])], [hi[0].max(c[0]), hi[1].max(c[1])])
    });
    if hi[0] < rect.0[0] || lo[0] > rect.0[1] || hi[1] < rect.1[0] || lo[1] > rect.1[1] {
        return false;
    }
    let rect_corners = [[rect.0[0], rect.1[0]], [rect.0[1], rect.1[0]], [rect.0[0], rect.1[1]], [rect.0[1], rect.1[1]]];
    let span = |points: &mut dyn Iterator<Item = f64>| {
        points.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| (lo.min(x), hi.max(x)))
    };
    for k in 0..corners.len() {
        let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
        let axis = [a[1] - b[1], b[0] - a[0]];
        let along = |c: &[f64; 2]| c[0] * axis[0] + c[1] * axis[1];
        let (p_lo, p_hi) = span(&mut corners.iter().map(along));
        let (r_lo, r_hi) = span(&mut rect_corners.iter().map(along));
        if p_hi < r_lo || r_hi < p_lo {
            return false;
        }
    }
    true
}

/// The part of triangle `tri` where side·(q − o)·n ≥ floor (Sutherland–Hodgman against one plane).
fn clip_to_side(tri: &[DVec3; 3], o: DVec3, n: DVec3, side: f64, floor: f64) -> Vec<DVec3> {
    let d = tri.map(|q| side * (q - o).dot(n) - floor);
    let mut out = Vec::with_capacity(4);
    for k in 0..3 {
        let (v, u, dv, du) = (tri[k], tri[(k + 1) % 3], d[k], d[(k + 1) % 3]);
        if dv >= 0.0 {
            out.push(v);
        }
        if (dv >= 0.0) != (du >= 0.0) {
            out.push(v + (u - v) * (dv / (dv - du)));
        }
    }
    out
}

impl ClearView {
    /// None for a scene with no triangles or more than `MAX_SCENE_TRIANGLES`, or whose nearest
    /// geometry in view is so close to the eye that the ray's rounding spans a pixel.
    pub fn new(geo: &Geometry, cam: &CameraModel) -> Option<ClearView> {
        let n = geo.len();
        if n == 0 || n > MAX_SCENE_TRIANGLES {
            return None;
        }
        let eye = cam.position.as_dvec3();
        let tris: Vec<[DVec3; 3]> = (0..n).map(|p| geo.verts(p).map(|v| v.as_dvec3())).collect();
        let extent = tris.iter().flatten().chain([&eye]).fold(0f64, |m, v| m.max(v.abs().max_element()));
        let far = tris.iter().flatten().fold(0f64, |m, v| m.max((*v - eye).length()));
        // How far the tested segment may stray from the exact one x → eye: the f32 rounding of
        // its origin (~10⁻⁷ of the extent) and of its direction and of the hit test's
        // translation (a few 10⁻⁷ of its length), generously.
        let delta = 1e-6 * (extent + far);
        let images: Vec<Option<PolygonImage>> = tris.iter().map(|t| cam.polygon_image(t)).collect();
        // The ray's offset and rounding (≲ 10⁻⁶ of the extent, generously 4·10⁻⁶ of it plus the
        // farthest distance) seen from the nearest depth in view, in pixels: every tile tested
        // is widened by that and by the image's own rounding (below).
        let near = images.iter().fold(f64::INFINITY, |m, image| match image {
            Some(PolygonImage::Corners(_, z)) => m.min(*z),
            _ => m,
        });
        let spread = cam.pixels_per_unit() * 4e-6 * (extent + far) / near;
        // Below a pixel, so the view pyramid's own widening (`view_margin` + 1 pixel) also holds
        // every blocker the rounded ray can meet.
        if !(spread < 1.0) {
            return None;
        }
        // What rounding may move a point's image (`project`, which picks its tile) or a camera
        // ray's direction (`EmitterView` asks about the pixels its rays pass through).
        let [mx, my] = cam.direction_rounding().map(|r| r + cam.image_rounding());
        let (wx, wy) = (mx + spread, my + spread);

        let (tiles_wide, tiles_high) = (cam.width.div_ceil(TILE), cam.height.div_ceil(TILE));
        let tile_rect = |k: usize| -> Rect {
            let (tr, tc) = ((k / tiles_wide) as f64, (k % tiles_wide) as f64);
            let t = TILE as f64;
            ([tc * t - wx, (tc + 1.0) * t + wx], [tr * t - wy, (tr + 1.0) * t + wy])
        };
        let mut candidates: Vec<Vec<u32>> = vec![Vec::new(); tiles_wide * tiles_high];
        let mut crowded = vec![false; candidates.len()];
        for (p, image) in images.iter().enumerate() {
            let Some(image) = image else { continue };
            // The tiles the image's box (widened) meets, then the polygon test per tile.
            let (cols, rows) = match image {
                PolygonImage::Anywhere => ([0, tiles_wide - 1], [0, tiles_high - 1]),
                PolygonImage::Corners(c, _) => {
                    let (lo, hi) = c.iter().fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), c| {
                        ([lo[0].min(c[0]), lo[1].min(c[1])], [hi[0].max(c[0]), hi[1].max(c[1])])
                    });
                    let tile = |x: f64, n: usize| ((x / TILE as f64).floor().max(0.0) as usize).min(n - 1);
                    (
                        [tile(lo[0] - wx, tiles_wide), tile(hi[0] + wx, tiles_wide)],
                        [tile(lo[1] - wy, tiles_high), tile(hi[1] + wy, tiles_high)],
                    )
                }
            };
            for tr in rows[0]..=rows[1] {
                for tc in cols[0]..=cols[1] {
                    let k = tr * tiles_wide + tc;
                    if !meets(image, &tile_rect(k)) {
                        continue;
                    }
                    if candidates[k].len() < MAX_CANDIDATES {
                        candidates[k].push(p as u32);
                    } else {
                        crowded[k] = true;
                    }
                }
            }
        }
        // Per triangle: a point on its plane, its unit normal, the eye's side of it (0 when the
        // eye is almost in the plane), and the least height over the plane on the eye's side that
        // the tested segment reaches. `Geometry::visible` starts the segment SHADOW_MARGIN of its
        // length from a point off the plane toward the eye, so at a height of at least
        // SHADOW_MARGIN·|H| (H the eye's height over the plane), rising to the eye: only the part
        // of another triangle above that height, less δ, can block it. That leaves out coplanar
        // neighbours and those meeting T at a convex edge.
        let planes: Vec<(DVec3, DVec3, f64, f64)> = (0..n)
            .map(|p| {
                // In f64 from the vertices: f32's normal of a sliver tilts by ~ε·length/width,
                // which would put T's own points off the plane by more than δ.
                let [a, b, c] = tris[p];
                let (o, normal) = (a, (b - a).cross(c - a).normalize());
                let height = (eye - o).dot(normal);
                let distance = tris[p].iter().fold(0f64, |m, v| m.max((*v - eye).length()));
                let side = if height.abs() > 1e-3 * distance { height.signum() } else { 0.0 };
                let floor = (SHADOW_MARGIN as f64 * (1.0 - 1e-3) * height.abs() - delta).max(-delta);
                (o, normal, side, floor)
            })
            .collect();
        // The image of triangle u's part on the eye's side of triangle t's plane.
        let mut blockers: HashMap<(u32, u32), Option<PolygonImage>> = HashMap::new();
        let mut start = Vec::with_capacity(candidates.len() + 1);
        let mut prims = Vec::new();
        for (k, list) in candidates.iter().enumerate() {
            start.push(prims.len() as u32);
            if crowded[k] {
                continue;
            }
            let rect = tile_rect(k);
            for &t in list {
                // Edge-on to the eye, or passing so near it that its points' images are uncertain.
                if planes[t as usize].2 == 0.0 || matches!(images[t as usize], Some(PolygonImage::Anywhere)) {
                    continue;
                }
                let blocked = list.iter().any(|&u| {
                    u != t
                        && blockers
                            .entry((t, u))
                            .or_insert_with(|| {
                                let (o, normal, side, floor) = planes[t as usize];
                                // A part nearer the eye than every whole image: `spread` does not
                                // cover its rounding, so it may be anywhere.
                                match cam.polygon_image(&clip_to_side(&tris[u as usize], o, normal, side, floor)) {
                                    Some(PolygonImage::Corners(_, z)) if !(z >= near) => Some(PolygonImage::Anywhere),
                                    image => image,
                                }
                            })
                            .as_ref()
                            .is_some_and(|image| meets(image, &rect))
                });
                if !blocked {
                    prims.push(t);
                }
            }
        }
        start.push(prims.len() as u32);
        Some(ClearView { tiles_wide, spread, start, prims })
    }

    /// Whether a point of triangle `prim` with projection `proj` is seen by the eye with nothing
    /// in between (false: unknown, cast the ray).
    #[inline(always)]
    pub fn is_clear(&self, proj: &Projection, prim: u32) -> bool {
        self.is_clear_in(proj.col as usize, proj.row as usize, prim)
    }

    /// Whether every point of triangle `prim` that pixel (`col`, `row`) sees is seen by the eye
    /// with nothing in between (false: unknown).
    #[inline(always)]
    pub fn is_clear_in(&self, col: usize, row: usize, prim: u32) -> bool {
        let k = (row / TILE) * self.tiles_wide + col / TILE;
        match (self.start.get(k), self.start.get(k + 1)) {
            (Some(&a), Some(&b)) => self.prims.get(a as usize..b as usize).is_some_and(|p| p.contains(&prim)),
            _ => false,
        }
    }

    /// How far, in pixels, a ray's offset and its hit test's rounding may move what it meets
    /// from what the exact ray meets (at most; see `new`).
    pub fn spread(&self) -> f64 {
        self.spread
    }

    /// How many (tile, triangle) pairs are clear.
    pub fn clear_pairs(&self) -> usize {
        self.prims.len()
    }
}

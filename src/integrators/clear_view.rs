//! Surface points the camera sees with nothing in between, or cannot see, known without a ray.
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
//! The same tiles also know points that are hidden: T is *hidden* in K when another triangle's
//! part that lies at heights over T's plane, on the eye's side, which every tested segment from
//! T to the eye crosses (above SHADOW_MARGIN of the eye's height and below the eye, less
//! rounding), has an image that contains K, widened as above. Every segment from a point of T
//! seen in K then meets that part between its ends, so `Geometry::visible` finds it (a surface
//! that lets rays through, an index-matched boundary, is the caller's to rule out).
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
    /// Tile k's clear triangles, and its hidden ones marked `HIDDEN`, are
    /// `prims[start[k]..start[k + 1]]`.
    start: Vec<u32>,
    prims: Vec<u32>,
}

/// A rectangle of the image in continuous pixel coordinates: [column lo, hi], [row lo, hi].
pub type Rect = ([f64; 2], [f64; 2]);

/// The lowest and highest [column, row] of an image's corners.
pub fn bounds(corners: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    corners.iter().fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), c| {
        ([lo[0].min(c[0]), lo[1].min(c[1])], [hi[0].max(c[0]), hi[1].max(c[1])])
    })
}

/// Whether some triangle u ≠ t of `list` passes `test` with its part `part(u)` as seen from t,
/// each part made once per (t, u) in `cache`.
fn any_other<P>(
    list: &[u32],
    t: u32,
    cache: &mut HashMap<(u32, u32), Option<P>>,
    part: impl Fn(u32) -> Option<P>,
    test: impl Fn(&P) -> bool,
) -> bool {
    list.iter().any(|&u| u != t && cache.entry((t, u)).or_insert_with(|| part(u)).as_ref().is_some_and(&test))
}

/// Whether a polygon's image meets `rect` (separating axes: the rectangle's two and the
/// polygon's edge normals; the image of a convex polygon in front of the eye is convex).
pub fn meets(image: &PolygonImage, rect: &Rect) -> bool {
    let corners = match image {
        PolygonImage::Anywhere => return true,
        PolygonImage::Corners(corners, _) => corners,
    };
    let (lo, hi) = bounds(corners);
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

/// The part of polygon `poly` where side·(q − o)·n ≥ floor (Sutherland–Hodgman against one plane).
fn clip_to_side(poly: &[DVec3], o: DVec3, n: DVec3, side: f64, floor: f64) -> Vec<DVec3> {
    let d: Vec<f64> = poly.iter().map(|&q| side * (q - o).dot(n) - floor).collect();
    let mut out = Vec::with_capacity(poly.len() + 1);
    for k in 0..poly.len() {
        let j = (k + 1) % poly.len();
        let (v, u, dv, du) = (poly[k], poly[j], d[k], d[j]);
        if dv >= 0.0 {
            out.push(v);
        }
        if (dv >= 0.0) != (du >= 0.0) {
            out.push(v + (u - v) * (dv / (dv - du)));
        }
    }
    out
}

/// Whether the rectangle `rect` lies strictly inside the convex polygon `corners` (either
/// orientation).
pub fn contains(corners: &[[f64; 2]], rect: &Rect) -> bool {
    let n = corners.len();
    let area: f64 = (0..n)
        .map(|k| {
            let (a, b) = (corners[k], corners[(k + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum();
    let rect_corners = [[rect.0[0], rect.1[0]], [rect.0[1], rect.1[0]], [rect.0[0], rect.1[1]], [rect.0[1], rect.1[1]]];
    n >= 3
        && area != 0.0
        && (0..n).all(|k| {
            let (a, b) = (corners[k], corners[(k + 1) % n]);
            rect_corners.iter().all(|p| {
                let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
                cross * area.signum() > 0.0
            })
        })
}

/// What the clear view knows of a point's segment to the eye (`ClearView::judge`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sight {
    /// `Geometry::visible` would find nothing on it.
    Clear,
    /// It would find a blocker: another triangle crosses every such segment in the tile.
    Hidden,
    /// Not known: cast the ray.
    Unknown,
}

/// Marks a hidden entry of `ClearView::prims`.
const HIDDEN: u32 = 1 << 31;

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
        // Twice the direction's: its bound is stated with about 2× to spare.
        let [mx, my] = cam.direction_rounding().map(|r| 2.0 * r + cam.image_rounding());
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
                    let (lo, hi) = bounds(c);
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
        // Per triangle: the heights over its plane, on the eye's side, that every tested segment
        // covers: it runs from a point within δ of the plane to the eye, less SHADOW_MARGIN of
        // its length at each end, so from SHADOW_MARGIN·|H| to (1 − SHADOW_MARGIN)·|H|, each
        // within rounding (δ); narrowed by a thousandth of the margin and 2δ each side.
        let tested: Vec<(f64, f64)> = (0..n)
            .map(|p| {
                let height = (eye - planes[p].0).dot(planes[p].1).abs();
                let m = SHADOW_MARGIN as f64 * (1.0 + 1e-3);
                (m * height + 2.0 * delta, (1.0 - m) * height - 2.0 * delta)
            })
            .collect();
        // The image of triangle u's part on the eye's side of triangle t's plane.
        let mut blockers: HashMap<(u32, u32), Option<PolygonImage>> = HashMap::new();
        // The image of u's part within t's tested heights, where it lies wholly beyond `near`:
        // a ray from the eye through it meets that part above t's plane and below the eye, so
        // between the eye and t, within the tested segment.
        let mut hiders: HashMap<(u32, u32), Option<Vec<[f64; 2]>>> = HashMap::new();
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
                let (o, normal, side, floor) = planes[t as usize];
                let blocked = any_other(
                    list,
                    t,
                    &mut blockers,
                    |u| {
                        // A part nearer the eye than every whole image: `spread` does not cover
                        // its rounding, so it may be anywhere.
                        match cam.polygon_image(&clip_to_side(&tris[u as usize], o, normal, side, floor)) {
                            Some(PolygonImage::Corners(_, z)) if !(z >= near) => Some(PolygonImage::Anywhere),
                            image => image,
                        }
                    },
                    |image| meets(image, &rect),
                );
                if !blocked {
                    prims.push(t);
                    continue;
                }
                let (lo, hi) = tested[t as usize];
                let hides = any_other(
                    list,
                    t,
                    &mut hiders,
                    |u| {
                        let slab = clip_to_side(&tris[u as usize], o, normal, side, lo);
                        match cam.polygon_image(&clip_to_side(&slab, o, normal, -side, -hi)) {
                            Some(PolygonImage::Corners(c, z)) if z >= near => Some(c),
                            _ => None,
                        }
                    },
                    |image| contains(image, &rect),
                );
                if hides {
                    prims.push(t | HIDDEN);
                }
            }
        }
        start.push(prims.len() as u32);
        Some(ClearView { tiles_wide, spread, start, prims })
    }

    /// Whether every point of triangle `prim` that pixel (`col`, `row`) sees is seen by the eye
    /// with nothing in between (false: unknown).
    #[inline(always)]
    pub fn is_clear_in(&self, col: usize, row: usize, prim: u32) -> bool {
        self.tile(col, row).contains(&prim)
    }

    /// What `Geometry::visible` would find between a point of triangle `prim` with projection
    /// `proj` and the eye, where that is known. A Hidden point's blocker may be a surface that
    /// lets rays through (an index-matched boundary): callers that look through such surfaces
    /// take only Clear.
    #[inline(always)]
    pub fn judge(&self, proj: &Projection, prim: u32) -> Sight {
        for &entry in self.tile(proj.col as usize, proj.row as usize) {
            if entry == prim {
                return Sight::Clear;
            }
            if entry == prim | HIDDEN {
                return Sight::Hidden;
            }
        }
        Sight::Unknown
    }

    /// The entries of the tile holding pixel (`col`, `row`): clear triangles, and hidden ones
    /// marked `HIDDEN`.
    #[inline(always)]
    fn tile(&self, col: usize, row: usize) -> &[u32] {
        let k = (row / TILE) * self.tiles_wide + col / TILE;
        match (self.start.get(k), self.start.get(k + 1)) {
            (Some(&a), Some(&b)) => self.prims.get(a as usize..b as usize).unwrap_or(&[]),
            _ => &[],
        }
    }

    /// How far, in pixels, a ray's offset and its hit test's rounding may move what it meets
    /// from what the exact ray meets (at most; see `new`).
    pub fn spread(&self) -> f64 {
        self.spread
    }

    /// How many (tile, triangle) pairs are clear.
    pub fn clear_pairs(&self) -> usize {
        self.prims.iter().filter(|&&e| e & HIDDEN == 0).count()
    }
}

//! The pinhole camera and its film: light tracing's "next event to the camera".
//!
//! Pixel value. Pixel j reports the mean radiance over its footprint on an image plane at unit
//! distance: I_j = (1/A_pix) ∫_{Ω_j} L(ω) dω / cos³θ_c, where θ_c is the angle to the optical
//! axis (dA_plane = dω / cos³θ_c). A surface of constant radiance c therefore reads I_j = c.
//!
//! Importance in area measure. With dω = cosθ_x dA / d² for a point x at distance d:
//! I_j = ∫_A L(x → e) · cosθ_x / (d² A_pix cos³θ_c) · V(x, e) dA, for x projecting into pixel j.
//!
//! Light-tracing estimator (one term per photon vertex, Φ the weight arriving at x):
//! - emission vertex with direction pdf p(ω) per solid angle: L dA = Φ p(ω)/cosθ_x, so the
//!   splat is Φ · p(ω) / (d² A_pix cos³θ_c) (the cosθ_x cancel; the same holds for a point light,
//!   whose intensity is Φ p(ω));
//! - diffuse vertex with BSDF f (ρ/π reflected, τ/π transmitted): L dA = Φ f, so the splat is
//!   Φ · f · |cosθ_x| / (d² A_pix cos³θ_c).
//!   Specular vertices (mirror, dielectric) have a delta BSDF and cannot be connected to a pinhole.
//!
//! Colour. Each splat is multiplied by the photon's colour weights: (x̄, ȳ, z̄)(λ)/∫ȳ for a spectral
//! photon, or its light's mean (x̄, ȳ, z̄)/∫ȳ under the light's spectrum in grey transport; so a
//! flat spectral radiance c reads Y = c.

use std::cell::RefCell;
use std::sync::Mutex;

use glam::{DVec3, Vec3A};
use ndarray::{Array2, Array3};

use super::exact::{ExactSum, ExactSum4};
use crate::scene::Camera;

pub struct CameraModel {
    pub position: Vec3A,
    forward: Vec3A,
    right: Vec3A,
    up: Vec3A,
    /// Half extents of the image plane at unit distance.
    half_w: f32,
    half_h: f32,
    pub width: usize,
    pub height: usize,
    /// `right` and `up` in pixels per unit of image plane (`project`): a point at depth z lands
    /// at column v·column_axis/z + width/2 and row height/2 − v·row_axis/z.
    column_axis: Vec3A,
    row_axis: Vec3A,
    /// 1/area of one pixel on the unit-distance image plane.
    inv_pixel_area: f32,
}

/// What a convex polygon looks like from the eye (`CameraModel::polygon_image`).
pub enum PolygonImage {
    /// It passes within 10⁻⁴ of its own depth of the eye: the hit test's f32 rounding there
    /// outgrows any margin, so it may be seen in any pixel.
    Anywhere,
    /// The corners of its part inside the view's pyramid in continuous pixel coordinates
    /// [column, row] (a point in pixel (r, c) has column in [c, c + 1)), and that part's least
    /// depth along the optical axis.
    Corners(Vec<[f64; 2]>, f64),
}

/// Where a world point lands on the film, and the factor 1/(d² A_pix cos³θ_c) of its splat.
#[derive(Clone, Copy, Debug)]
pub struct Projection {
    pub pixel: usize,
    /// The pixel's row and column (pixel = row·width + column).
    pub row: u32,
    pub col: u32,
    /// Unit direction from the point toward the camera, and the distance.
    pub to_camera: Vec3A,
    pub distance: f32,
    pub importance: f32,
}

impl CameraModel {
    pub fn new(c: &Camera) -> Self {
        let position = c.position.as_vec3a();
        let forward = (c.look_at - c.position).normalize().as_vec3a();
        // Right-handed: with y up and looking along +z, image-right is −x.
        let right = forward.cross(c.up.as_vec3a()).normalize();
        let up = right.cross(forward);
        let [width, height] = c.resolution.map(|r| r as usize);
        let half_w = (c.fov_deg.to_radians() * 0.5).tan() as f32;
        let half_h = half_w * height as f32 / width as f32;
        let pixel_w = 2.0 * half_w / width as f32;
        let pixel_area = pixel_w * pixel_w;
        CameraModel {
            position,
            forward,
            right,
            up,
            half_w,
            half_h,
            width,
            height,
            column_axis: right * (0.5 * width as f32 / half_w),
            row_axis: up * (0.5 * height as f32 / half_h),
            inv_pixel_area: 1.0 / pixel_area,
        }
    }

    #[inline]
    pub fn project(&self, p: Vec3A) -> Option<Projection> {
        // Two divisions and a square root: 1/z and 1/d serve every quotient below.
        let v = p - self.position;
        let z = v.dot(self.forward);
        if !(z > 0.0) {
            return None;
        }
        let inv_z = 1.0 / z;
        let (w, h) = (self.width as f32, self.height as f32);
        let col_f = v.dot(self.column_axis) * inv_z + 0.5 * w;
        let row_f = 0.5 * h - v.dot(self.row_axis) * inv_z;
        if !(col_f > 0.0 && col_f < w && row_f > 0.0 && row_f < h) {
            return None;
        }
        let col = (col_f as usize).min(self.width - 1);
        let row = (row_f as usize).min(self.height - 1);
        let distance = v.length();
        let inv_d = 1.0 / distance;
        // 1/(d² A_pix cos³θ_c) with cosθ_c = z/d: d/(A_pix z³).
        Some(Projection {
            pixel: row * self.width + col,
            row: row as u32,
            col: col as u32,
            to_camera: -v * inv_d,
            distance,
            importance: distance * (inv_z * inv_z * inv_z) * self.inv_pixel_area,
        })
    }

    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Columns and rows (inclusive ranges) of a rectangle of pixels that holds the image of the
    /// triangle, with a margin for rounding; None when it misses the image or lies wholly
    /// behind the camera. The triangle is first clipped to the view's pyramid (widened by the
    /// margin), so a lamp reaching behind the camera lists only the pixels it can be seen in; one
    /// passing within 10⁻⁴ of its depth of the eye gives the whole image.
    pub fn pixel_box(&self, triangle: &[Vec3A; 3]) -> Option<([usize; 2], [usize; 2])> {
        let hull = triangle.iter().map(|&p| self.camera_space((p - self.position).as_dvec3())).collect();
        let (w, h) = (self.width as f64, self.height as f64);
        let [mx, my] = self.view_margin();
        let corners = match self.hull_image(hull)? {
            PolygonImage::Anywhere => return Some(([0, self.width - 1], [0, self.height - 1])),
            PolygonImage::Corners(corners, _) => corners,
        };
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for [col, row] in corners {
            lo = [lo[0].min(col), lo[1].min(row)];
            hi = [hi[0].max(col), hi[1].max(row)];
        }
        let span = |lo: f64, hi: f64, n: usize, margin: f64| {
            let first = (lo.floor() - margin).max(0.0) as usize;
            let last = ((hi.floor() + margin).max(0.0) as usize).min(n - 1);
            [first.min(n - 1), last]
        };
        if !(hi[0] >= -mx && lo[0] <= w + mx && hi[1] >= -my && lo[1] <= h + my) {
            return None;
        }
        Some((span(lo[0], hi[0], self.width, mx), span(lo[1], hi[1], self.height, my)))
    }

    /// The image of a convex polygon given by its corners in world space (`PolygonImage`); None
    /// when no part of it lies in the view's pyramid (widened by `view_margin`).
    pub fn polygon_image(&self, corners: &[DVec3]) -> Option<PolygonImage> {
        let eye = self.position.as_dvec3();
        self.hull_image(corners.iter().map(|&p| self.camera_space(p - eye)).collect())
    }

    /// Camera space in pixel units: column x/z + w/2, row h/2 − y/z, z the depth.
    fn camera_space(&self, v: DVec3) -> DVec3 {
        let (cx, cy, fz) = (self.column_axis.as_dvec3(), self.row_axis.as_dvec3(), self.forward.as_dvec3());
        DVec3::new(v.dot(cx), v.dot(cy), v.dot(fz))
    }

    /// Pixels per unit of the unit-distance image plane.
    pub fn pixels_per_unit(&self) -> f64 {
        0.5 * self.width as f64 / self.half_w as f64
    }

    /// Columns and rows of margin around a polygon's image: a pixel, plus `direction_rounding`
    /// rounded up (with a field of view of hundredths of a degree that is more than a pixel).
    pub fn view_margin(&self) -> [f64; 2] {
        self.direction_rounding().map(|r| 1.0 + r.ceil())
    }

    /// Columns and rows that a ray direction's f32 rounding (< 10⁻⁶ rad, up to (1 + tan²)
    /// image-plane units a radian off axis) spans.
    pub fn direction_rounding(&self) -> [f64; 2] {
        let span = |half: f32, n: usize| {
            let half = half as f64;
            1e-6 * (1.0 + 2.0 * half * half) * n as f64 / (2.0 * half)
        };
        [span(self.half_w, self.width), span(self.half_h, self.height)]
    }

    /// Pixels that `project`'s f32 arithmetic may move a point's image: col = (v·c)/z + w/2, with
    /// v the point's difference from the eye (each coordinate rounded, relative ε), c of length
    /// ppu (pixels per unit) and z = v·f. v's rounding moves the image by ≤ ε·ppu·(|v|/z)·(1 + a),
    /// v·c's by γ₃·ppu·|v|/z, z's and the quotient's by |col − w/2|·(γ₃·|v|/z + 2ε), the sum by
    /// ε·w. With |v|/z = 1/cosθ ≤ 1 + a + b and |col − w/2| ≤ ppu·a (a, b the half field's
    /// tangents), all of it is below (γ₄ + 5ε)·ppu·(1 + a + b)² < 10⁻⁶·ppu·(1 + a + b)². Rows
    /// alike.
    pub fn image_rounding(&self) -> f64 {
        let (a, b) = (self.half_w as f64, self.half_h as f64);
        1e-6 * self.pixels_per_unit() * (1.0 + a + b).powi(2)
    }

    fn hull_image(&self, mut hull: Vec<DVec3>) -> Option<PolygonImage> {
        if hull.is_empty() {
            return None;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        let [mx, my] = self.view_margin();
        // The pyramid |x| ≤ a·z, |y| ≤ b·z (which holds only at z ≥ 0), one plane at a time
        // (Sutherland–Hodgman): inside where d(v) = ±v.x − a·v.z (or the same in y) ≤ 0.
        let (a, b) = (0.5 * w + mx + 1.0, 0.5 * h + my + 1.0);
        let planes =
            [DVec3::new(1.0, 0.0, -a), DVec3::new(-1.0, 0.0, -a), DVec3::new(0.0, 1.0, -b), DVec3::new(0.0, -1.0, -b)];
        for plane in planes {
            let mut clipped = Vec::with_capacity(hull.len() + 1);
            for (k, &v) in hull.iter().enumerate() {
                let u = hull[(k + 1) % hull.len()];
                let (dv, du) = (plane.dot(v), plane.dot(u));
                if dv <= 0.0 {
                    clipped.push(v);
                }
                if (dv <= 0.0) != (du <= 0.0) {
                    clipped.push(v + (u - v) * (dv / (dv - du)));
                }
            }
            hull = clipped;
            if hull.is_empty() {
                return None;
            }
        }
        // A triangle passing within 10⁻⁴ of its own depth of the eye: the hit test's own f32
        // rounding there (~10⁻⁷ of the distance over the hit distance, in radians) outgrows the
        // margin, so it may be seen in any pixel.
        let (near, far) = hull.iter().fold((f64::INFINITY, 0f64), |(n, f), v| (n.min(v.z), f.max(v.z)));
        if !(near >= 1e-4 * far) {
            return Some(PolygonImage::Anywhere);
        }
        // Only a polygon collapsed onto the eye has corners at z = 0 inside the pyramid
        // |x| ≤ a·z: it has no image.
        let corners: Vec<[f64; 2]> =
            hull.iter().filter(|v| v.z > 0.0).map(|v| [v.x / v.z + 0.5 * w, 0.5 * h - v.y / v.z]).collect();
        if corners.is_empty() {
            return None;
        }
        Some(PolygonImage::Corners(corners, near))
    }

    /// Unit direction through the point (u, v) ∈ [0,1)² of pixel `pixel`: a uniform point on the
    /// pixel's footprint on the unit-distance image plane, so the pixel's radiance estimate is
    /// simply L along the ray (see the module comment).
    #[inline]
    pub fn ray_direction(&self, pixel: usize, u: f32, v: f32) -> Vec3A {
        let (row, col) = (pixel / self.width, pixel % self.width);
        let sx = ((col as f32 + u) / self.width as f32) * 2.0 - 1.0;
        let sy = 1.0 - ((row as f32 + v) / self.height as f32) * 2.0;
        (self.forward + sx * self.half_w * self.right + sy * self.half_h * self.up).normalize()
    }

    /// Solid-angle density with which the camera's samples, spread evenly over the whole image,
    /// leave along unit `w`: 1/(A_image cos³θ_c) inside the field of view, else 0. Multiple
    /// importance sampling compares it with the light subpaths' densities: pixel j's n samples
    /// have density 1/(A_pix cos³θ_c) each, and n/A_pix = N/A_image for N samples over the image,
    /// one light subpath per camera sample.
    #[inline]
    pub fn direction_pdf(&self, w: Vec3A) -> f64 {
        let z = w.dot(self.forward);
        if z <= 0.0 {
            return 0.0;
        }
        let (sx, sy) = (w.dot(self.right) / z / self.half_w, w.dot(self.up) / z / self.half_h);
        if !(sx > -1.0 && sx < 1.0 && sy > -1.0 && sy < 1.0) {
            return 0.0;
        }
        let image_area = 4.0 * self.half_w as f64 * self.half_h as f64;
        1.0 / (image_area * (z as f64).powi(3))
    }
}

/// Photons per film batch: the unit whose spread gives each pixel's variance. Small, so even
/// short runs have many film batches; fixed within each transport batch, so thread-independent.
pub const FILM_BATCH_PHOTONS: u32 = 1024;

/// One splat: which photon of the transport batch made it, where, and its XYZ (in units of
/// emitted photon weight).
#[derive(Clone, Copy, Debug)]
pub struct Splat {
    pub photon: u32,
    pub pixel: u32,
    pub xyz: [f32; 3],
}

/// How many pixels ahead `Film::flush` prefetches pixel sums.
const MERGE_PREFETCH_DISTANCE: usize = 16;

/// Batches `Film::merge` holds before adding their pixel sums, all at once. A batch touches about
/// a fifth of a 512² film's pixels (two cache lines of sums each), spread over the whole film;
/// added one batch at a time, the film (33 MB at 512²) streams through memory once a batch.
/// Added 16 at a time, tile by tile, each tile's sums stay in the L2 cache while every held batch
/// adds its share: a third of the traffic (Cornell box 512², light-traced, 2·10⁶ photons: the
/// merge thread's time 0.26–0.32 s → 0.15–0.21 s; 32 or 64 gained no more).
const MERGE_GROUP: usize = 16;
/// Pixels per tile of `Film::flush`: 2048 pixels' sums are 256 kB.
const FLUSH_TILE: usize = 2048;

/// A hint to bring the cache line at `p` in; it never faults and changes no result.
#[inline(always)]
fn prefetch(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch only hints the cache and never faults.
    unsafe {
        std::arch::x86_64::_mm_prefetch(p as *const i8, std::arch::x86_64::_MM_HINT_T0)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// One transport batch's splats, in photon order: a list rather than a full-resolution buffer, so
/// a batch costs memory in proportion to what it splatted, whatever the resolution.
#[derive(Default)]
pub struct FilmBatch {
    pub splats: Vec<Splat>,
    /// The photon now being traced (its index within the transport batch).
    pub photon: u32,
    /// Visibility rays cast toward the camera.
    pub shadow_rays: u64,
    /// Camera integrators (path, bdpt): each sample's XYZ radiance estimate for its own pixel, in
    /// sample order; sample k of the run (counting from 0) belongs to pixel k mod pixels.
    pub samples: Vec<[f32; 3]>,
    /// Run-wide index of `samples[0]`.
    pub first_sample: u64,
    /// The light tracer's camera samples of the emitters it sees directly (`EmitterView`): per
    /// entry of the film's listed camera part (`Film::with_listed_camera_pixels`), at most once
    /// a batch, the sums X, Y, Z, ΣY² of its samples and their count.
    pub view: Vec<(u32, [f64; 4], u32)>,
    /// The splats reduced (`digest`): per touched pixel, in pixel order, its X, Y, Z and
    /// Σ_b S_b²/n_b of Y over the batch's film batches; the image's Σ_b S_b²/n_b; film batches.
    digest: Option<Digest>,
}

/// Touched pixels in increasing order, each with its sums (X, Y, Z, Σ_b S_b²/n_b of Y).
type PixelList = Vec<(u32, [f64; 4])>;

struct Digest {
    /// Touched pixels in increasing order, each with its sums.
    pixels: PixelList,
    image_y_sq_over_n: f64,
    film_batches: u64,
}

impl FilmBatch {
    /// A batch for `photons` photons, its splat list one this thread has used before (`spare_list`),
    /// with room for a typical photon's splats: grown by pushes from empty, the list was copied
    /// at each doubling into fresh pages. Reserved pages that are never written cost nothing.
    pub fn for_photons(photons: u64) -> Self {
        const SPLATS_PER_PHOTON: u64 = 6;
        let mut splats = spare_list();
        splats.reserve((photons * SPLATS_PER_PHOTON).min(1 << 24) as usize);
        FilmBatch { splats, ..Default::default() }
    }

    #[inline]
    pub fn add(&mut self, pixel: usize, xyz: Vec3A) {
        self.splats.push(Splat { photon: self.photon, pixel: pixel as u32, xyz: [xyz.x, xyz.y, xyz.z] });
    }

    /// Reduces the splats of a batch of `photons` photons to per-pixel sums, on the worker that
    /// traced it, so the run's merge only adds them (exactly) in pixel order. Each pixel's sums
    /// are over its splats in photon order (a stable sort by pixel keeps it), so they do not
    /// depend on where the batch is digested.
    pub fn digest(&mut self, photons: u64) {
        let sub = FILM_BATCH_PHOTONS as u64;
        let film_batches = photons.div_ceil(sub);
        let n = |k: u64| sub.min(photons - k * sub) as f64;
        // The whole image's Y per film batch.
        let mut image_y_sq_over_n = 0.0;
        let mut splats = self.splats.iter().peekable();
        for k in 0..film_batches {
            let mut y = 0.0;
            while let Some(sp) = splats.next_if(|sp| (sp.photon as u64) < (k + 1) * sub) {
                y += sp.xyz[1] as f64;
            }
            image_y_sq_over_n += y * y / n(k);
        }
        sort_by_pixel(&mut self.splats);
        let splats = &self.splats[..];
        // Sized first: grown by pushes, the list was copied at each doubling into fresh pages.
        let touched = 1 + splats.windows(2).filter(|w| w[0].pixel != w[1].pixel).count();
        let mut pixels = spare_pixel_list();
        pixels.reserve(touched);
        // Each pixel's run of splats, and within it each film batch's (plain loops: the
        // `chunk_by` iterators cost a quarter of the digest).
        let mut i = 0;
        while let Some(first) = splats.get(i) {
            let mut v = [0.0; 4];
            while let Some(head) = splats.get(i).filter(|sp| sp.pixel == first.pixel) {
                let group = head.photon / FILM_BATCH_PHOTONS;
                let mut y = 0.0;
                while let Some(sp) =
                    splats.get(i).filter(|sp| sp.pixel == first.pixel && sp.photon / FILM_BATCH_PHOTONS == group)
                {
                    v[0] += sp.xyz[0] as f64;
                    v[1] += sp.xyz[1] as f64;
                    v[2] += sp.xyz[2] as f64;
                    y += sp.xyz[1] as f64;
                    i += 1;
                }
                v[3] += y * y / n(group as u64);
            }
            pixels.push((first.pixel, v));
        }
        self.digest = Some(Digest { pixels, image_y_sq_over_n, film_batches });
        // The digest is all that is merged: the list goes back for this thread's next batch.
        keep_list(std::mem::take(&mut self.splats));
    }

    /// The batch's digest, made here where its worker did not make it (a batch built by hand).
    fn take_digest(&mut self, photons: u64) -> Digest {
        if self.digest.is_none() {
            self.digest(photons);
        }
        self.digest.take().expect("just digested")
    }
}

thread_local! {
    /// This thread's splat lists between batches (a digested batch's list, the radix sort's
    /// second list). A worker that made them afresh each batch wrote every splat into new pages,
    /// and the kernel's page faults took 4 % of an image run's CPU time.
    static SPARE_LISTS: RefCell<Vec<Vec<Splat>>> = const { RefCell::new(Vec::new()) };
}

/// Digest lists that a film has added (`Film::flush`), for the workers' next digests. The merge
/// adds them on another thread than the one that made them, so they come back through a lock
/// (once a batch, never a photon).
static SPARE_PIXEL_LISTS: Mutex<Vec<PixelList>> = Mutex::new(Vec::new());
/// The most lists kept. Pops and pushes balance, so about a merge group's lists are held; the
/// cap only bounds what a burst leaves behind. Kept lists keep their capacity for the process's
/// life (a few MB at 512²).
const SPARE_PIXEL_LISTS_KEPT: usize = 2 * MERGE_GROUP;

fn spare_pixel_list() -> PixelList {
    SPARE_PIXEL_LISTS.lock().ok().and_then(|mut lists| lists.pop()).unwrap_or_default()
}

/// Empties `lists` into the spare lists, keeping their allocations up to the most kept.
fn keep_pixel_lists(lists: &mut Vec<PixelList>) {
    let Ok(mut spare) = SPARE_PIXEL_LISTS.lock() else {
        lists.clear();
        return;
    };
    for list in lists.drain(..) {
        keep_pixel_list(&mut spare, list);
    }
}

fn keep_pixel_list(spare: &mut Vec<PixelList>, mut list: PixelList) {
    if spare.len() < SPARE_PIXEL_LISTS_KEPT {
        list.clear();
        spare.push(list);
    }
}

/// Frees the spare digest lists. A run calls it when it ends: kept, a run's lists (up to
/// `SPARE_PIXEL_LISTS_KEPT` of a few MB each) stayed allocated between runs of a process that
/// runs many scenes (the Python module). The workers' own spares end with the run's threads.
#[doc(hidden)]
pub fn release_spare_pixel_lists() {
    if let Ok(mut spare) = SPARE_PIXEL_LISTS.lock() {
        *spare = Vec::new();
    }
}

/// Bytes the spare digest lists hold allocated (for tests).
#[doc(hidden)]
pub fn spare_pixel_list_bytes() -> usize {
    SPARE_PIXEL_LISTS
        .lock()
        .map_or(0, |spare| spare.iter().map(|l| l.capacity() * std::mem::size_of::<(u32, [f64; 4])>()).sum())
}

/// An empty splat list, with the capacity of one this thread used before where it has one.
fn spare_list() -> Vec<Splat> {
    SPARE_LISTS.with_borrow_mut(|lists| lists.pop()).unwrap_or_default()
}

/// Keeps `list`'s allocation for this thread's next `spare_list` (two at most: a batch's and
/// the sort's).
fn keep_list(mut list: Vec<Splat>) {
    list.clear();
    SPARE_LISTS.with_borrow_mut(|lists| {
        if lists.len() < 2 {
            lists.push(list);
        }
    });
}

/// Sorts splats by pixel, stably (each pixel's splats stay in photon order): an LSD radix sort,
/// 11 bits a pass, several times faster than a comparison sort on a batch's tens of thousands.
fn sort_by_pixel(splats: &mut Vec<Splat>) {
    const BITS: u32 = 11;
    let max = splats.iter().map(|s| s.pixel).max().unwrap_or(0);
    let mut other = spare_list();
    let mut shift = 0;
    while shift < 32 && (max >> shift) != 0 {
        let mut start = [0usize; 1 << BITS];
        for sp in splats.iter() {
            start[((sp.pixel >> shift) & ((1 << BITS) - 1)) as usize] += 1;
        }
        let mut at = 0;
        for c in start.iter_mut() {
            (*c, at) = (at, at + *c);
        }
        // Every slot of `other` is written once below (the counts' prefix sums are a
        // permutation of 0..len), so it is not filled first.
        other.clear();
        other.reserve(splats.len());
        let slots = &mut other.spare_capacity_mut()[..splats.len()];
        for sp in splats.iter() {
            let d = &mut start[((sp.pixel >> shift) & ((1 << BITS) - 1)) as usize];
            slots[*d].write(*sp);
            *d += 1;
        }
        // SAFETY: the first splats.len() slots were all written above.
        unsafe { other.set_len(splats.len()) };
        std::mem::swap(splats, &mut other);
        shift += BITS;
    }
    keep_list(other);
}

/// The run's film: per pixel the exact sums (`exact`) of each transport batch's XYZ, and, per
/// film batch b of n_b photons with pixel sums S_b, Σ S_b²/n_b for each pixel's Y and for the
/// whole image's Y. Camera integrators add a second part (and the light tracer, for the lamps it
/// images from the camera, `EmitterView`): per pixel the sum of its own samples' values, ΣY² and
/// the sample count; that part's pixel value is the samples' mean and its variance the sample
/// variance over the count (pixels are independent there: each sample touches one pixel).
/// Exact sums make the film the same for any grouping of its batches.
pub struct Film {
    pub width: usize,
    pub height: usize,
    pixels: Vec<PixelSums>,
    image_y_sq_over_n: ExactSum,
    photons: u64,
    film_batches: u64,
    camera: Option<CameraPart>,
    /// Batches' per-pixel sums merged but not yet added to `pixels` (`merge`, `flush`); every
    /// read of `pixels` requires it empty.
    pending: Vec<PixelList>,
}

/// One pixel's exact sums: X, Y, Z, and Y's square term.
pub type PixelSums = ExactSum4;

#[derive(Clone)]
struct CameraPart {
    /// The pixels it covers, ascending: entry k is pixel `listed[k]` (the light tracer's lamps
    /// in view), or None for every pixel, entry p being pixel p (the camera integrators).
    listed: Option<Vec<u32>>,
    /// XYZ and ΣY² of each entry's samples.
    sums: Vec<PixelSums>,
    count: Vec<u32>,
}

impl CameraPart {
    fn new(pixels: usize) -> Self {
        CameraPart { listed: None, sums: vec![PixelSums::default(); pixels], count: vec![0; pixels] }
    }

    fn listed(pixels: Vec<u32>) -> Self {
        let n = pixels.len();
        CameraPart { listed: Some(pixels), sums: vec![PixelSums::default(); n], count: vec![0; n] }
    }

    /// (pixel, entry) pairs in increasing pixel order.
    fn entries(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..self.count.len()).map(|k| (self.listed.as_ref().map_or(k, |l| l[k] as usize), k))
    }

    /// (mean XYZ, variance of the mean Y) of entry `k`; no samples give zeros, one sample no variance.
    fn entry(&self, k: usize) -> ([f64; 3], f64) {
        let n = self.count[k] as f64;
        if n == 0.0 {
            return ([0.0; 3], 0.0);
        }
        let [x, y, z, y_sq] = self.sums[k].values();
        let mean_y = y / n;
        // Samples are f32: a spread below f32's resolution of the mean is their rounding of one
        // radiance (every sample seeing the same emitter), and the rest the sums' rounding.
        let spread = y_sq / n - mean_y * mean_y;
        let resolution = f32::EPSILON as f64 * mean_y;
        let var = if n > 1.0 && spread > resolution * resolution { spread / (n - 1.0) } else { 0.0 };
        ([x / n, mean_y, z / n], var)
    }
}

/// A film's exact state, for partial runs and ranks to exchange (`Film::state`, `Film::from_state`).
pub struct FilmState {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<PixelSums>,
    pub image_y_sq_over_n: ExactSum,
    pub photons: u64,
    pub film_batches: u64,
    /// The camera part: the pixels it covers (None: all; the light tracer's lamps in view: those
    /// listed), and per covered pixel its sums and sample count.
    pub camera: Option<CameraState>,
}

/// A film's camera part as a state holds it: (listed pixels or None for all, sums, counts).
pub type CameraState = (Option<Vec<u32>>, Vec<PixelSums>, Vec<u32>);

/// The finished image: per pixel linear XYZ and RGB radiance, and Y's variance.
pub struct Image {
    pub width: usize,
    pub height: usize,
    /// (pixel, channel) with channels X, Y, Z.
    pub xyz: Array2<f32>,
    pub rgb: Array3<f32>,
    pub y_var: Vec<f32>,
}

impl Image {
    /// sqrt(mean(Y_var))/mean(Y): the image's typical relative pixel error.
    pub fn pixel_rel_error(&self) -> f64 {
        let n = self.y_var.len() as f64;
        let mean_y = self.xyz.column(1).iter().map(|&y| y as f64).sum::<f64>() / n;
        let mean_var = self.y_var.iter().map(|&v| v as f64).sum::<f64>() / n;
        mean_var.sqrt() / mean_y
    }
}

impl Film {
    /// A film with no light. Inside a thread pool its sums are written by all the pool's threads:
    /// the first writes of a 512² film's 32 MB are page faults, which took 6–70 ms on one core
    /// of this project's virtual machines (the host backing fresh memory).
    pub fn new(width: usize, height: usize) -> Self {
        let pixels = width * height;
        let sums = if rayon::current_thread_index().is_some() {
            use rayon::prelude::*;
            (0..pixels).into_par_iter().with_min_len(1 << 14).map(|_| PixelSums::default()).collect()
        } else {
            vec![PixelSums::default(); pixels]
        };
        Film {
            width,
            height,
            pixels: sums,
            image_y_sq_over_n: ExactSum::default(),
            photons: 0,
            film_batches: 0,
            camera: None,
            pending: Vec::new(),
        }
    }

    /// A film whose camera part covers the pixels `listed` (ascending): the light tracer's lamps
    /// in view (`EmitterView`), whose batches send their samples by entry (`FilmBatch::view`).
    pub fn with_listed_camera_pixels(mut self, listed: Vec<u32>) -> Self {
        self.camera = Some(CameraPart::listed(listed));
        self
    }

    /// Fewest samples any pixel of the camera part has (None without one).
    pub fn min_samples_per_pixel(&self) -> Option<u32> {
        self.camera.as_ref().map(|c| c.count.iter().copied().min().unwrap_or(0))
    }

    /// Adds one transport batch of `photons` photons, in any order of batches. Its pixel sums are
    /// taken from `b` and held until `MERGE_GROUP` batches are (`flush`); read the film through
    /// `flushed`, or after `flush`.
    pub fn merge(&mut self, b: &mut FilmBatch, photons: u64) {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            unsafe { self.merge_camera_avx2(b) };
        } else {
            self.merge_camera(b, |sums, v| sums.add(v));
        }
        #[cfg(not(target_arch = "x86_64"))]
        self.merge_camera(b, |sums, v| sums.add(v));
        let digest = b.take_digest(photons);
        self.image_y_sq_over_n.add(digest.image_y_sq_over_n);
        self.film_batches += digest.film_batches;
        self.photons += photons;
        // Exact sums take their values in any order: held now, added with others (`flush`).
        self.pending.push(digest.pixels);
        if self.pending.len() >= MERGE_GROUP {
            self.flush();
        }
    }

    /// `merge_camera` with a sample's four sums added at once (`ExactSum4::add_avx2`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn merge_camera_avx2(&mut self, b: &FilmBatch) {
        // SAFETY: this function runs only where the CPU has AVX2.
        self.merge_camera(b, |sums, v| unsafe { sums.add_avx2(v) });
    }

    /// The camera part of `merge`: a camera integrator's samples and the light tracer's lamps in
    /// view, each added to its pixel's exact sums by `add`.
    #[inline(always)]
    fn merge_camera(&mut self, b: &FilmBatch, add: impl Fn(&mut PixelSums, [f64; 4])) {
        // A camera integrator's samples, one a pixel in turn (its film's part covers every pixel).
        if !b.samples.is_empty() && self.camera.as_ref().is_none_or(|c| c.listed.is_none()) {
            let pixels = self.width * self.height;
            let cam = self.camera.get_or_insert_with(|| CameraPart::new(pixels));
            let value = |v: &[f32; 3]| {
                let (x, y, z) = (v[0] as f64, v[1] as f64, v[2] as f64);
                [x, y, z, y * y]
            };
            let pixel = |i: usize| ((b.first_sample + i as u64) % pixels as u64) as usize;
            if b.samples.len() <= pixels {
                // Each pixel has at most one sample in the batch: one exact addition each.
                for (i, v) in b.samples.iter().enumerate() {
                    add(&mut cam.sums[pixel(i)], value(v));
                    cam.count[pixel(i)] += 1;
                }
            } else {
                // A film smaller than the batch: each pixel's samples summed in sample order
                // first, so a sum still takes one value a batch (`exact::MAX_VALUES`).
                let mut batch = vec![([0.0f64; 4], 0u32); pixels];
                for (i, v) in b.samples.iter().enumerate() {
                    let (acc, n) = &mut batch[pixel(i)];
                    for (a, x) in acc.iter_mut().zip(value(v)) {
                        *a += x;
                    }
                    *n += 1;
                }
                for (p, (acc, n)) in batch.into_iter().enumerate() {
                    if n > 0 {
                        add(&mut cam.sums[p], acc);
                        cam.count[p] += n;
                    }
                }
            }
        }
        // The light tracer's lamps in view, by entry of the listed part the film was made with.
        if let Some(cam) = self.camera.as_mut().filter(|c| c.listed.is_some()) {
            for &(k, sums, n) in &b.view {
                let k = k as usize;
                // A pixel keeps its first ~4·10⁹ samples (a decision that ignores their values,
                // so its mean stays unbiased); its count never wraps.
                if let Some(count) = cam.count.get(k).and_then(|c| c.checked_add(n)) {
                    add(&mut cam.sums[k], sums);
                    cam.count[k] = count;
                }
            }
        }
    }

    /// Adds the held batches' pixel sums: tile by tile, each held batch adding its pixels in the
    /// tile (its list is in pixel order), so a tile's sums are fetched from memory once for all.
    pub fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            unsafe { self.add_pending_avx2() };
            return;
        }
        self.add_pending(|sums, v| sums.add(v));
    }

    /// `add_pending` with the four sums of a pixel added at once (`ExactSum4::add_avx2`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn add_pending_avx2(&mut self) {
        // SAFETY: this function runs only where the CPU has AVX2.
        self.add_pending(|sums, v| unsafe { sums.add_avx2(v) });
    }

    #[inline(always)]
    fn add_pending(&mut self, add: impl Fn(&mut PixelSums, [f64; 4])) {
        let mut at = vec![0usize; self.pending.len()];
        let pixels = self.pixels.len();
        for tile_end in (FLUSH_TILE..pixels + FLUSH_TILE).step_by(FLUSH_TILE) {
            for (list, at) in self.pending.iter().zip(at.iter_mut()) {
                while let Some(&(p, v)) = list.get(*at) {
                    if p as usize >= tile_end {
                        break;
                    }
                    if let Some(&(ahead, _)) = list.get(*at + MERGE_PREFETCH_DISTANCE) {
                        // A pixel's four sums span two cache lines.
                        let at = &self.pixels[ahead as usize] as *const PixelSums as *const u8;
                        prefetch(at);
                        prefetch(at.wrapping_add(64));
                    }
                    add(&mut self.pixels[p as usize], v);
                    *at += 1;
                }
            }
        }
        keep_pixel_lists(&mut self.pending);
    }

    /// The film with every merged batch added (`flush`), for reading.
    pub fn flushed(&mut self) -> &Film {
        self.flush();
        self
    }

    /// Reads of the pixel sums come after `flush`: a held batch would be missing from them.
    fn assert_flushed(&self) {
        assert!(self.pending.is_empty(), "the film is read with merged batches not yet added: call flush first");
    }

    /// Adds another film's batches (a partial run's, another rank's): the same camera.
    pub fn merge_run(&mut self, o: &Film) -> Result<(), String> {
        if (o.width, o.height) != (self.width, self.height) {
            return Err(format!("films of {}×{} and {}×{} pixels", self.width, self.height, o.width, o.height));
        }
        self.assert_flushed();
        o.assert_flushed();
        // Only a state that no run wrote makes a count or a sum overflow: refused, not wrapped.
        let wrapped = || "its film's counts overflow when added to the others': no run of photon writes such a state";
        self.photons = self.photons.checked_add(o.photons).ok_or_else(wrapped)?;
        self.film_batches = self.film_batches.checked_add(o.film_batches).ok_or_else(wrapped)?;
        for (a, b) in self.pixels.iter_mut().zip(&o.pixels) {
            a.add_sums(b).map_err(|e| e.to_string())?;
        }
        self.image_y_sq_over_n.add_sum(&o.image_y_sq_over_n).map_err(|e| e.to_string())?;
        match (&mut self.camera, &o.camera) {
            (_, None) => {}
            (None, Some(oc)) => self.camera = Some(oc.clone()),
            (Some(cam), Some(oc)) => {
                if cam.listed != oc.listed {
                    return Err("the films' camera parts cover different pixels".into());
                }
                for (a, b) in cam.sums.iter_mut().zip(&oc.sums) {
                    a.add_sums(b).map_err(|e| e.to_string())?;
                }
                for (a, b) in cam.count.iter_mut().zip(&oc.count) {
                    *a = a.checked_add(*b).ok_or("a pixel has more than 2³² camera samples")?;
                }
            }
        }
        Ok(())
    }

    /// The exact state, for a state file or another rank.
    pub fn state(&self) -> FilmState {
        self.assert_flushed();
        FilmState {
            width: self.width,
            height: self.height,
            pixels: self.pixels.clone(),
            image_y_sq_over_n: self.image_y_sq_over_n,
            photons: self.photons,
            film_batches: self.film_batches,
            camera: self.camera.as_ref().map(|c| (c.listed.clone(), c.sums.clone(), c.count.clone())),
        }
    }

    /// The film a state describes; None if its arrays do not fit its size.
    pub fn from_state(s: FilmState) -> Option<Film> {
        let pixels = s.width.checked_mul(s.height)?;
        // A listed part's pixels strictly ascending and on the film; a full one covers it.
        let fits = |(listed, sums, count): &CameraState| {
            let entries = match listed {
                None => pixels,
                Some(l) => {
                    if !(l.windows(2).all(|w| w[0] < w[1]) && l.last().is_none_or(|&p| (p as usize) < pixels)) {
                        return false;
                    }
                    l.len()
                }
            };
            sums.len() == entries && count.len() == entries
        };
        if s.pixels.len() != pixels || s.camera.as_ref().is_some_and(|c| !fits(c)) {
            return None;
        }
        let mut film = Film::new(s.width, s.height);
        film.pixels = s.pixels;
        film.image_y_sq_over_n = s.image_y_sq_over_n;
        film.photons = s.photons;
        film.film_batches = s.film_batches;
        film.camera = s.camera.map(|(listed, sums, count)| CameraPart { listed, sums, count });
        Some(film)
    }

    /// `variance_of_mean` over this film's photons and film batches.
    fn variance_of_mean(&self, sum: f64, sq_over_n: f64) -> f64 {
        variance_of_mean(sum, sq_over_n, self.photons, self.film_batches)
    }

    pub fn film_batches(&self) -> u64 {
        self.film_batches
    }

    /// Mean Y over the image and its standard error, from the spread of whole-image batch sums
    /// (pixels are correlated: one photon splats into several).
    pub fn mean_y(&self, emitted_w: f64) -> (f64, f64) {
        self.assert_flushed();
        let pixels = (self.width * self.height) as f64;
        let n = self.photons.max(1) as f64;
        let total: f64 = self.pixels.iter().map(|p| p.lane(1).value()).sum();
        let var = self.variance_of_mean(total, self.image_y_sq_over_n.value());
        let (mut mean, mut var) = (total / n * emitted_w / pixels, var * (emitted_w / pixels).powi(2));
        if let Some(cam) = &self.camera {
            // Mean of independent pixel means: variance Σ var_p / P².
            for (_, k) in cam.entries() {
                let (m, v) = cam.entry(k);
                mean += m[1] / pixels;
                var += v / (pixels * pixels);
            }
        }
        (mean, var.sqrt())
    }

    /// The image in watts: each photon carries Φ_total/N; Y_var from the film batches' spread.
    pub fn image(&self, emitted_w: f64) -> Image {
        self.assert_flushed();
        let n = self.photons.max(1) as f64;
        let w = emitted_w / n;
        let pixels = self.width * self.height;
        let mut xyz = Array2::zeros((pixels, 3));
        let mut rgb = Array3::zeros((self.height, self.width, 3));
        let mut y_var = vec![0.0f32; pixels];
        // The camera part's entries, in pixel order as the pixels are visited.
        let mut camera = self.camera.as_ref().map(|c| (c, c.entries().peekable()));
        for p in 0..pixels {
            let [x, y, z, y_sq_over_n] = self.pixels[p].values();
            let mut sum = [x * w, y * w, z * w];
            let mut var = self.variance_of_mean(y, y_sq_over_n) * emitted_w * emitted_w;
            if let Some((cam, entries)) = camera.as_mut() {
                if let Some((_, k)) = entries.next_if(|&(q, _)| q == p) {
                    let (m, v) = cam.entry(k);
                    sum = [sum[0] + m[0], sum[1] + m[1], sum[2] + m[2]];
                    var += v;
                }
            }
            let v = Vec3A::new(sum[0] as f32, sum[1] as f32, sum[2] as f32);
            xyz[[p, 0]] = v.x;
            xyz[[p, 1]] = v.y;
            xyz[[p, 2]] = v.z;
            let c = crate::spectrum::color::desaturate_into_gamut(
                crate::spectrum::color::xyz_to_linear_srgb(v.into()),
                v.y,
            );
            let (row, col) = (p / self.width, p % self.width);
            rgb[[row, col, 0]] = c.x;
            rgb[[row, col, 1]] = c.y;
            rgb[[row, col, 2]] = c.z;
            y_var[p] = var as f32;
        }
        Image { width: self.width, height: self.height, xyz, rgb, y_var }
    }
}

/// Between-batch variance of a mean: with per-batch sums S_b over n_b photons (N in all, K
/// batches) and m = ΣS_b/N, the per-photon variance is Σ n_b (m_b − m)²/(K − 1) =
/// (Σ S_b²/n_b − N m²)/(K − 1), and the mean's variance is that over N.
fn variance_of_mean(sum: f64, sq_over_n: f64, photons: u64, film_batches: u64) -> f64 {
    let (n, k) = (photons as f64, film_batches as f64);
    if film_batches < 2 {
        return 0.0;
    }
    let m = sum / n;
    ((sq_over_n - n * m * m) / (k - 1.0)).max(0.0) / n
}

/// The light-traced image's typical relative pixel error (`Image::pixel_rel_error` of a film's
/// image without a camera part), from Y's two sums a pixel in plain f64: all the estimator pilot
/// needs of its image. Two films of exact sums (32 MB each at 512²) and their finished images
/// took most of the pilot's time. Batches are added in the caller's fixed order, so the figure
/// depends on them only.
pub struct PixelNoise {
    /// Per pixel: Y's sum and its Σ_b S_b²/n_b.
    y: Vec<[f64; 2]>,
    photons: u64,
    film_batches: u64,
}

impl PixelNoise {
    pub fn new(width: usize, height: usize) -> Self {
        // Written here rather than taken zeroed from the allocator: a zeroed page that is read
        // (`+=`) before it is written is mapped to the shared zero page first, and its copy on
        // the write then flushes every core's TLB (a third of the pilot's time went to it).
        let mut y = Vec::with_capacity(width * height);
        y.resize(width * height, [0.0; 2]);
        PixelNoise { y, photons: 0, film_batches: 0 }
    }

    /// Adds one transport batch of `photons` photons (its light-traced splats).
    pub fn add(&mut self, b: &mut FilmBatch, photons: u64) {
        let mut digest = b.take_digest(photons);
        for &(p, v) in &digest.pixels {
            if let Some(s) = self.y.get_mut(p as usize) {
                s[0] += v[1];
                s[1] += v[3];
            }
        }
        self.photons += photons;
        self.film_batches += digest.film_batches;
        if let Ok(mut spare) = SPARE_PIXEL_LISTS.lock() {
            keep_pixel_list(&mut spare, std::mem::take(&mut digest.pixels));
        }
    }

    /// sqrt(mean over pixels of Y's variance) / mean Y, per unit emitted power; NaN without light.
    pub fn rel_error(&self) -> f64 {
        let n = self.photons.max(1) as f64;
        let (mut y, mut var) = (0.0, 0.0);
        for &[sum, sq_over_n] in &self.y {
            y += sum / n;
            var += variance_of_mean(sum, sq_over_n, self.photons, self.film_batches);
        }
        let pixels = self.y.len() as f64;
        (var / pixels).sqrt() / (y / pixels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_xoshiro::rand_core::{Rng, SeedableRng};

    fn batch(rng: &mut rand_xoshiro::Xoshiro256PlusPlus, pixels: u32, photons: u32) -> FilmBatch {
        let mut b = FilmBatch::default();
        for photon in 0..photons {
            b.photon = photon;
            for _ in 0..rng.next_u32() % 4 {
                let xyz = Vec3A::new(rng.next_u32() as f32, rng.next_u32() as f32, 1.0) * 1e-9;
                b.add((rng.next_u32() % pixels) as usize, xyz);
            }
        }
        b
    }

    /// The pilot's pixel noise from Y's plain sums is the film's image's `pixel_rel_error`, to
    /// the image's f32 rounding (the two sum the same values in other orders and precisions).
    #[test]
    fn pixel_noise_is_the_images_pixel_error() {
        let (width, height) = (37, 23);
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(3);
        let (mut film, mut noise) = (Film::new(width, height), PixelNoise::new(width, height));
        for _ in 0..40 {
            let b = batch(&mut rng, (width * height) as u32, 2000);
            let copy = || FilmBatch { splats: b.splats.clone(), ..FilmBatch::default() };
            film.merge(&mut copy(), 2000);
            noise.add(&mut copy(), 2000);
        }
        let (a, b) = (film.flushed().image(1.0).pixel_rel_error(), noise.rel_error());
        assert!(a > 0.0 && (a - b).abs() <= 1e-5 * a, "film {a}, pixel noise {b}");
    }

    /// Batches held and added in groups, tile by tile (`flush`), give the film bit for bit that
    /// adding each batch at once gives, for a batch count that is no multiple of the group and
    /// a film that is no multiple of the tile.
    #[test]
    fn grouped_merges_give_the_same_sums() {
        let (width, height) = (97, 61);
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(5);
        let batches: Vec<FilmBatch> = (0..2 * MERGE_GROUP + 5).map(|_| batch(&mut rng, 97 * 61, 3000)).collect();
        let (mut grouped, mut single) = (Film::new(width, height), Film::new(width, height));
        for b in &batches {
            // Undigested copies: `merge` digests each itself.
            let copy = || FilmBatch { splats: b.splats.clone(), ..FilmBatch::default() };
            grouped.merge(&mut copy(), 3000);
            single.merge(&mut copy(), 3000);
            single.flush();
        }
        let (a, b) = (grouped.flushed().state(), single.state());
        assert!(a.pixels == b.pixels && a.image_y_sq_over_n == b.image_y_sq_over_n);
        assert_eq!((a.photons, a.film_batches), (b.photons, b.film_batches));
        // Nearly all 5917 pixels were splatted, so every tile, the last partial one too, was added.
        assert!(a.pixels.iter().filter(|p| p.lane(1) != ExactSum::default()).count() > 5000);
    }

    /// `pixel_box` holds every pixel through which a camera ray meets the triangle: random
    /// triangles in front of, around and behind a tilted camera, each met by rays through
    /// random points of the image.
    #[test]
    fn pixel_boxes_hold_every_pixel_that_sees_the_triangle() {
        use glam::DVec3;
        let cam = CameraModel::new(&Camera {
            position: DVec3::new(0.3, -0.2, 0.1),
            look_at: DVec3::new(1.0, 0.5, 3.0),
            up: DVec3::Y,
            fov_deg: 50.0,
            resolution: [37, 23],
        });
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(9);
        let mut uniform = || (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32;
        let (mut seen, mut behind_seen, mut behind_bounded) = (0, 0, 0);
        for _ in 0..400 {
            let tri: [Vec3A; 3] = std::array::from_fn(|_| {
                Vec3A::new(uniform() * 6.0 - 2.0, uniform() * 6.0 - 2.5, uniform() * 8.0 - 2.0)
            });
            let b = cam.pixel_box(&tri);
            let behind = tri.iter().any(|&p| (p - cam.position).dot(cam.forward) <= 0.0);
            let mut met = false;
            for _ in 0..2000 {
                let pixel = (uniform() * cam.pixels() as f32) as usize % cam.pixels();
                let dir = cam.ray_direction(pixel, uniform(), uniform());
                if crate::geometry::intersect_triangle(cam.position, dir, f32::INFINITY, &tri).is_some() {
                    seen += 1;
                    met = true;
                    let ([c0, c1], [r0, r1]) = b.expect("a triangle a ray meets has a box");
                    let (row, col) = (pixel / cam.width, pixel % cam.width);
                    assert!(
                        (c0..=c1).contains(&col) && (r0..=r1).contains(&row),
                        "{tri:?}: pixel {pixel} outside {b:?}"
                    );
                }
            }
            if behind && met {
                behind_seen += 1;
                behind_bounded += (b != Some(([0, cam.width - 1], [0, cam.height - 1]))) as u32;
            }
        }
        // The draw met many triangles, some of them reaching behind the camera, and clipping
        // bounded most of those to a part of the image.
        assert!(
            seen > 10_000 && behind_seen > 10 && 2 * behind_bounded > behind_seen,
            "{seen} rays met a triangle; {behind_seen} seen reach behind the camera, {behind_bounded} of them bounded"
        );
    }

    /// A ceiling panel that reaches over and behind the camera is seen in the image's top rows
    /// only, and a triangle through the eye may be seen anywhere (there the hit test's rounding
    /// outgrows any margin).
    #[test]
    fn a_lamp_reaching_behind_the_camera_lists_only_the_rows_it_is_seen_in() {
        let cam = CameraModel::new(&Camera {
            position: DVec3::new(0.0, 1.5, 0.0),
            look_at: DVec3::new(0.0, 1.5, 5.0),
            up: DVec3::Y,
            fov_deg: 60.0,
            resolution: [64, 48],
        });
        // The ceiling at 2.5 m, 2 m either side, from 3 m behind the camera to 6 m ahead.
        let panel = [Vec3A::new(-2.0, 2.5, -3.0), Vec3A::new(2.0, 2.5, -3.0), Vec3A::new(0.0, 2.5, 6.0)];
        let (_, [r0, r1]) = cam.pixel_box(&panel).expect("the panel is in view");
        // Its lowest point in view is the far tip, 1 m above the eye at 6 m: 1/6 of the image
        // plane's half height tan 30° · 48/64 above the middle row 24 (rows count down).
        let tip_row = 24.0 - (1.0 / 6.0) / (30f64.to_radians().tan() * 48.0 / 64.0) * 24.0;
        assert!(r0 == 0 && (r1 as f64) <= tip_row + 2.0, "rows {r0}..={r1}, tip at row {tip_row}");
        let through = [Vec3A::new(-1.0, 1.5, -1.0), Vec3A::new(1.0, 1.5, -1.0), Vec3A::new(0.0, 1.5, 3.0)];
        assert_eq!(cam.pixel_box(&through), Some(([0, 63], [0, 47])));
    }

    /// A camera part listing some pixels (the light tracer's lamps in view) takes samples by
    /// entry, images them at its pixels only, survives its state, and refuses lists that are
    /// not strictly ascending on the film, and merges with a part listing other pixels.
    #[test]
    fn listed_camera_parts_image_their_pixels_and_round_trip() {
        let mut film = Film::new(8, 4).with_listed_camera_pixels(vec![3, 9, 30]);
        let mut b = FilmBatch {
            view: vec![(0, [1.0, 2.0, 3.0, 4.0], 2), (2, [0.5, 0.5, 0.5, 0.25], 1)],
            ..FilmBatch::default()
        };
        film.merge(&mut b, 10);
        let img = film.flushed().image(1.0);
        assert_eq!((img.xyz[[3, 1]], img.xyz[[30, 1]], img.xyz[[9, 1]]), (1.0, 0.5, 0.0));
        assert_eq!((img.xyz[[3, 0]], img.xyz[[3, 2]]), (0.5, 1.5));
        assert_eq!(img.xyz.column(1).iter().filter(|&&y| y != 0.0).count(), 2);
        let again = Film::from_state(film.state()).expect("its own state");
        assert_eq!(again.image(1.0).xyz, img.xyz);
        for bad in [vec![3, 3, 30], vec![9, 3, 30], vec![3, 9, 32]] {
            let mut s = film.state();
            s.camera.as_mut().unwrap().0 = Some(bad);
            assert!(Film::from_state(s).is_none());
        }
        let other = Film::new(8, 4).with_listed_camera_pixels(vec![3, 9, 31]);
        assert!(film.merge_run(&other).is_err());
        let same = Film::from_state(film.state()).unwrap();
        film.merge_run(&same).unwrap();
        assert_eq!(film.image(1.0).xyz[[3, 1]], 1.0);
    }

    /// A read with held batches is refused rather than missing them.
    #[test]
    #[should_panic(expected = "call flush first")]
    fn reading_before_flush_panics() {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(6);
        let mut film = Film::new(8, 8);
        film.merge(&mut batch(&mut rng, 64, 100), 100);
        film.image(1.0);
    }
}

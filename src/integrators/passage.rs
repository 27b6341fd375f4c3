//! Straight connections through index-matched boundaries. A smooth dielectric whose index equals
//! the index outside it neither reflects nor bends (Fresnel's R = 0 at n₁ = n₂): a connection
//! passes it, changing medium there, and is blocked only by other surfaces. The light tracer's
//! camera splats, the path tracer's light samples and BDPT's connections walk such connections,
//! and the camera integrators' paths make no vertex there, so a medium behind a matched boundary
//! (tissue, fog in a box) is reached by the estimators' connections and not only by paths that
//! happen to pass it. A crossing is no scattering event: it does not count toward `max_bounces`.

use glam::Vec3A;

use crate::geometry::{Geometry, NO_PRIM};
use crate::media;
use crate::scene::Material;

/// More boundaries than this between the two ends: the connection counts as blocked.
pub const MAX_CROSSINGS: usize = 64;

/// An index-matched smooth dielectric boundary, with no volume scattering of its own: nothing
/// reflects or bends there.
pub fn is_passable(m: &Material) -> bool {
    match m {
        Material::Dielectric { ior, outside_ior, roughness, scatter: None, .. } => {
            !roughness.is_rough() && ior == outside_ior
        }
        _ => false,
    }
}

/// What a connection may pass: per surface whether it is passable, and the media on each
/// boundary's sides (`Scene::surface_inside`, `surface_outside`).
#[derive(Clone, Copy)]
pub struct Through<'a> {
    pub passable: &'a [bool],
    pub inside: &'a [u32],
    pub outside: &'a [Option<u32>],
}

impl Through<'_> {
    /// Walks from `origin` (off its surface already; `skip` its primitive, or `NO_PRIM`) along
    /// the unit `dir` to `target`, starting in dielectric `medium`. Each stretch inside one medium
    /// is reported as `stretch(medium, length)`, in order; a hit on `end_prim` (the target's own
    /// primitive, or `NO_PRIM`) counts as arriving. False: a surface that is not passable, or
    /// more than `MAX_CROSSINGS` boundaries, lies in between.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn walk(
        &self,
        geo: &Geometry,
        mut origin: Vec3A,
        dir: Vec3A,
        target: Vec3A,
        (mut skip, end_prim): (u32, u32),
        mut medium: Option<u32>,
        mut stretch: impl FnMut(Option<u32>, f32),
    ) -> bool {
        let mut remaining = (target - origin).length();
        for _ in 0..=MAX_CROSSINGS {
            let hit = geo.intersect(origin, dir, remaining, skip).filter(|h| end_prim == NO_PRIM || h.prim != end_prim);
            let Some(h) = hit else {
                stretch(medium, remaining);
                return true;
            };
            let surface = geo.surface_of(h.prim as usize);
            if !self.passable[surface as usize] {
                return false;
            }
            stretch(medium, h.t);
            let n = geo.normal(h.prim as usize);
            medium = media::after_crossing(surface, n, dir, self.inside, self.outside);
            let (hp, err) = geo.hit_point(&h);
            origin = geo.spawn_from(hp, err, h.prim, h.b, dir);
            if (target - origin).dot(dir) <= 0.0 {
                // A boundary within the spawn offset of the target: the offset passed it.
                stretch(medium, 0.0);
                return true;
            }
            remaining = (target - origin).length();
            skip = h.prim;
        }
        false
    }
}

//! Volume detector (`[[detectors]] type = "volume"`): an axis-aligned grid of voxels that tallies,
//! per voxel, the absorbed power (where collisions and Beer–Lambert segments deposit it) and the
//! fluence rate by the track-length estimator, φ = Σ w·ℓ / V (Σ over path segments inside the
//! voxel, w the weight carried, ℓ the length inside, V the voxel's volume): W/m² once weights are
//! watts.

use glam::DVec3;

#[derive(Clone, Debug)]
pub struct VolumeGrid {
    pub name: String,
    /// Corners in the tracer's recentred frame (m), min < max on every axis.
    pub min: DVec3,
    pub max: DVec3,
    /// [nx, ny, nz].
    pub resolution: [usize; 3],
    /// First voxel of this grid in the scene's voxel array.
    pub offset: usize,
}

impl VolumeGrid {
    pub fn voxels(&self) -> usize {
        self.resolution.iter().product()
    }

    pub fn voxel_volume_m3(&self) -> f64 {
        let cell = (self.max - self.min) / self.cell_counts();
        cell.x * cell.y * cell.z
    }

    fn cell_counts(&self) -> DVec3 {
        DVec3::new(self.resolution[0] as f64, self.resolution[1] as f64, self.resolution[2] as f64)
    }

    /// The voxel (in the scene's array) holding `p`, if inside the grid.
    #[inline]
    pub fn voxel_of(&self, p: DVec3) -> Option<usize> {
        let f = (p - self.min) / (self.max - self.min) * self.cell_counts();
        if !(f.x >= 0.0 && f.y >= 0.0 && f.z >= 0.0) {
            return None;
        }
        let [nx, ny, nz] = self.resolution;
        let (i, j, k) = (f.x as usize, f.y as usize, f.z as usize);
        (i < nx && j < ny && k < nz).then(|| self.offset + (k * ny + j) * nx + i)
    }

    /// Walks the segment o + s·d, s ∈ [0, len] (d unit, len may be infinite) through the grid
    /// (Amanatides & Woo 1987), calling `f(voxel, s0, s1)` for each voxel it crosses with the
    /// stretch [s0, s1] inside it.
    pub fn traverse(&self, o: DVec3, d: DVec3, len: f64, mut f: impl FnMut(usize, f64, f64)) {
        // Clip to the box (slabs).
        let (mut t0, mut t1) = (0.0f64, len);
        for a in 0..3 {
            if d[a] == 0.0 {
                if o[a] < self.min[a] || o[a] > self.max[a] {
                    return;
                }
                continue;
            }
            let (ta, tb) = ((self.min[a] - o[a]) / d[a], (self.max[a] - o[a]) / d[a]);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
        if !(t0 < t1) {
            return;
        }
        let n = self.resolution;
        let cell = (self.max - self.min) / self.cell_counts();
        let mid = o + d * (0.5 * (t0 + t1.min(t0 + cell.min_element())));
        let mut idx = [0usize; 3];
        let (mut next, mut delta, mut step) = ([f64::INFINITY; 3], [f64::INFINITY; 3], [0isize; 3]);
        let start = o + d * t0;
        for a in 0..3 {
            // The voxel where the segment enters, judged a little inside (`mid`) on the entry
            // axis's tie, at `start` otherwise.
            let x = if d[a] == 0.0 { start[a] } else { start[a] + (mid[a] - start[a]) * 1e-9 };
            let k = ((x - self.min[a]) / cell[a]).floor().clamp(0.0, (n[a] - 1) as f64) as usize;
            idx[a] = k;
            if d[a] > 0.0 {
                step[a] = 1;
                next[a] = (self.min[a] + (k + 1) as f64 * cell[a] - o[a]) / d[a];
                delta[a] = cell[a] / d[a];
            } else if d[a] < 0.0 {
                step[a] = -1;
                next[a] = (self.min[a] + k as f64 * cell[a] - o[a]) / d[a];
                delta[a] = -cell[a] / d[a];
            }
        }
        let mut s = t0;
        // Each step leaves one voxel: at most nx + ny + nz of them.
        for _ in 0..n[0] + n[1] + n[2] {
            let a = if next[0] <= next[1] && next[0] <= next[2] {
                0
            } else if next[1] <= next[2] {
                1
            } else {
                2
            };
            let exit = next[a].min(t1);
            if exit > s {
                f(self.offset + (idx[2] * n[1] + idx[1]) * n[0] + idx[0], s, exit);
            }
            if next[a] >= t1 {
                return;
            }
            s = exit;
            let k = idx[a] as isize + step[a];
            if k < 0 || k >= n[a] as isize {
                return;
            }
            idx[a] = k as usize;
            next[a] += delta[a];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> VolumeGrid {
        VolumeGrid {
            name: "g".into(),
            min: DVec3::ZERO,
            max: DVec3::new(2.0, 3.0, 4.0),
            resolution: [2, 3, 4],
            offset: 5,
        }
    }

    #[test]
    fn traversal_lengths_add_up_to_the_chord_and_match_each_voxel() {
        // Random segments: the stretches are contiguous, sum to the chord inside the box, and
        // each stretch's midpoint lies in the voxel it is booked to.
        let g = grid();
        let mut s = crate::sampling::Sampler::for_batch(1, 0);
        for _ in 0..20_000 {
            let o = DVec3::new(s.uniform() * 4.0 - 1.0, s.uniform() * 5.0 - 1.0, s.uniform() * 6.0 - 1.0);
            let d = DVec3::new(s.uniform() - 0.5, s.uniform() - 0.5, s.uniform() - 0.5).normalize();
            let len = if s.uniform() < 0.3 { f64::INFINITY } else { s.uniform() * 5.0 };
            let mut total = 0.0;
            let mut last: Option<f64> = None;
            g.traverse(o, d, len, |v, a, b| {
                assert!(b > a);
                if let Some(l) = last {
                    assert!((a - l).abs() < 1e-9, "gap between stretches");
                }
                last = Some(b);
                total += b - a;
                assert_eq!(g.voxel_of(o + d * (0.5 * (a + b))), Some(v));
            });
            // The chord by fine stepping.
            let steps = 20_000;
            let reach = len.min(12.0);
            let inside = (0..steps)
                .filter(|&k| {
                    let p = o + d * ((k as f64 + 0.5) / steps as f64 * reach);
                    p.cmpge(g.min).all() && p.cmplt(g.max).all()
                })
                .count() as f64
                * reach
                / steps as f64;
            assert!((total - inside).abs() < 2e-3, "chord {total} against {inside}");
        }
    }

    #[test]
    fn axis_parallel_rays_on_voxel_faces_are_booked_once() {
        let g = grid();
        let mut total = 0.0;
        g.traverse(DVec3::new(1.0, 1.0, -1.0), DVec3::Z, f64::INFINITY, |_, a, b| total += b - a);
        assert!((total - 4.0).abs() < 1e-12, "{total}");
    }
}

//! Whether points with f32 coordinates lie exactly in one plane, decided in exact integer
//! arithmetic: a ray spawned off a triangle (its origin on the side it leaves by) never meets a
//! triangle of exactly that plane, so a leaf of such triangles need not be tested for it
//! (`Geometry::intersect_leaving`).

/// Nonzero coordinates whose magnitudes' binary exponents span more than this are not decided
/// (false): each coordinate is then an integer below 2^(24 + SPREAD) in units of the least one's
/// ulp, differences below 2^(25 + SPREAD), and the orientation test n·(p − a), with n a cross
/// product of differences, stays below 2^(78 + 3·SPREAD) ≤ 2^126, inside i128.
const SPREAD: i32 = 16;

/// A coordinate as m·2^e, m an integer of at most 24 bits (None where not finite).
fn parts(x: f32) -> Option<(i64, i32)> {
    if !x.is_finite() {
        return None;
    }
    let bits = x.to_bits();
    let exp = ((bits >> 23) & 0xff) as i32;
    let frac = (bits & 0x7f_ffff) as i64;
    // Subnormals have no implicit bit and the least exponent.
    let (m, e) = if exp == 0 { (frac, -149) } else { (frac | 0x80_0000, exp - 150) };
    Some((if bits >> 31 != 0 { -m } else { m }, e))
}

/// True when every point lies exactly in one plane (fewer than four points, or all on one line,
/// always do); false when they do not, or when the coordinates' range is too wide to decide
/// exactly here (`SPREAD`) or one is not finite.
pub fn coplanar(points: &[[f32; 3]]) -> bool {
    let mut split = Vec::with_capacity(points.len());
    for p in points {
        let Some(q) = p.iter().map(|&x| parts(x)).collect::<Option<Vec<_>>>() else { return false };
        split.push(q);
    }
    let exponents = || split.iter().flatten().filter(|(m, _)| *m != 0).map(|&(_, e)| e);
    let (Some(least), Some(most)) = (exponents().min(), exponents().max()) else { return true };
    if most - least > SPREAD {
        return false;
    }
    let ints: Vec<[i128; 3]> =
        split.iter().map(|q| std::array::from_fn(|k| (q[k].0 as i128) << (q[k].1 - least).max(0))).collect();
    let sub = |p: &[i128; 3], a: &[i128; 3]| [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
    let cross =
        |u: [i128; 3], v: [i128; 3]| [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    let Some(a) = ints.first() else { return true };
    // The plane's normal from the first two independent directions out of `a`.
    let Some(u) = ints.iter().map(|p| sub(p, a)).find(|d| *d != [0; 3]) else { return true };
    let Some(n) = ints.iter().map(|p| cross(u, sub(p, a))).find(|c| *c != [0; 3]) else { return true };
    ints.iter().all(|p| {
        let d = sub(p, a);
        n[0] * d[0] + n[1] * d[1] + n[2] * d[2] == 0
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_planes_are_told_from_a_vertex_one_ulp_off() {
        // The Cornell box's floor (y = 0) and a block's side: a vertical rectangle of a rotated
        // box, whose top corners repeat the bottom ones' x and z.
        let floor = [[552.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 559.2], [549.6, 0.0, 559.2]];
        let side = [[130.0, 0.0, 65.0], [82.0, 0.0, 225.0], [82.0, 165.0, 225.0], [130.0, 165.0, 65.0]];
        // An oblique plane, z = x + 2y, at coordinates exact in f32.
        let oblique = [[1.0, 0.0, 1.0], [0.0, 1.5, 3.0], [2.5, 1.0, 4.5], [-3.0, 0.25, -2.5]];
        for quad in [floor, side, oblique] {
            assert!(coplanar(&quad), "{quad:?}");
            for k in 0..4 {
                // Zeros are left alone: one ulp above 0 is subnormal, outside the decided range.
                for axis in (0..3).filter(|&axis| quad[k][axis] != 0.0) {
                    let mut bent = quad;
                    bent[k][axis] = bent[k][axis].next_up();
                    // Off the plane exactly when the normal has a part along the nudged axis.
                    let normal_has_axis = match quad {
                        q if q == floor => axis == 1,
                        q if q == side => axis != 1,
                        _ => true,
                    };
                    assert_eq!(coplanar(&bent), !normal_has_axis, "{bent:?}");
                }
            }
        }
    }

    #[test]
    fn degenerate_sets_and_undecidable_ranges() {
        // Fewer than four points, repeated points and points on one line lie in a plane.
        assert!(coplanar(&[]));
        assert!(coplanar(&[[1.0, 2.0, 3.0]; 5]));
        assert!(coplanar(&[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [-7.0, -7.0, -7.0]]));
        assert!(coplanar(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 7.0]]));
        // A tetrahedron does not.
        assert!(!coplanar(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]));
        // Planar, but over a range of 2^20 in magnitude: not decided here, so false.
        assert!(!coplanar(&[[1e-3, 0.0, 0.0], [1e3, 0.0, 0.0], [0.0, 1e3, 0.0], [5.0, 5.0, 0.0]]));
        // Subnormal and zero coordinates in one plane (z = 0).
        let tiny = f32::from_bits(3);
        assert!(coplanar(&[[tiny, 0.0, 0.0], [0.0, tiny, 0.0], [tiny, tiny, 0.0], [2.0 * tiny, 0.0, 0.0]]));
        assert!(!coplanar(&[[tiny, 0.0, 0.0], [0.0, tiny, 0.0], [tiny, tiny, 0.0], [0.0, 0.0, tiny]]));
        assert!(!coplanar(&[[f32::NAN, 0.0, 0.0], [0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]));
    }
}

//! The camera's clear view (`integrators::clear_view`) lets the light tracer skip the shadow ray
//! of a splat where no other triangle can lie between the point and the eye. It must vouch only
//! for points the ray itself finds unblocked, or light would pass through walls in the image:
//! checked here point by point against `Geometry::visible` on every bundled scene with a camera
//! and on cases built to break it (the eye inside a closed room with walls behind it, a plate
//! just in front of the eye, an eye almost in a wall's plane, a plate 1 cm before the eye), with
//! points drawn uniformly and near triangle edges, where silhouettes lie. It must also vouch for
//! most visible points of the Cornell box, or it saves nothing.

mod common;
use common::{bundled_toml, scene};

use photon::detectors::film::CameraModel;
use photon::geometry::{Hit, RayEnd};
use photon::integrators::clear_view::ClearView;
use photon::sampling::{uniform_triangle, Sampler};

/// (points in view, of them visible by the ray, of them vouched for by the clear view), or None
/// where no clear view is built; panics on any point vouched for that the ray finds blocked.
fn check(toml: &str, points: usize, seed: u64) -> Option<(usize, usize, usize)> {
    let s = scene(toml);
    let cam = CameraModel::new(s.camera.as_ref().expect("the scene has a camera"));
    let geo = &s.geometry;
    let clear = ClearView::new(geo, &cam)?;
    let mut rng = Sampler::for_batch(seed, 0);
    let (mut in_view, mut visible, mut vouched) = (0, 0, 0);
    for k in 0..points {
        let prim = ((rng.uniform() * geo.len() as f64) as usize).min(geo.len() - 1);
        let mut b = uniform_triangle(rng.uniform_f32(), rng.uniform_f32());
        if k % 2 == 1 {
            // Within 10⁻⁶…10⁻² of an edge (log-uniform).
            let e = rng.uniform_f32() as usize % 3;
            let d = 10f32.powf(-6.0 + 4.0 * rng.uniform_f32());
            let rest = 1.0 - b[e];
            b = [0, 1, 2].map(|i| if i == e { d } else { b[i] / rest * (1.0 - d) });
        }
        let (p, err) = geo.hit_point(&Hit { t: 1.0, prim: prim as u32, b });
        let Some(proj) = cam.project(p) else { continue };
        in_view += 1;
        let start = RayEnd { p, err, n: geo.normal(prim), prim: prim as u32 };
        let seen = geo.visible(start, RayEnd::free(cam.position));
        visible += seen as usize;
        if clear.is_clear(&proj, prim as u32) {
            vouched += 1;
            assert!(seen, "point {p:?} of triangle {prim} (pixel {}) is blocked but was vouched for", proj.pixel);
        }
    }
    Some((in_view, visible, vouched))
}

#[test]
fn the_clear_view_vouches_only_for_points_the_ray_sees_in_the_bundled_scenes() {
    // glass.toml's 20 496 triangles are past the clear view's limit: it keeps every ray there.
    let glass = scene(&bundled_toml("glass.toml"));
    assert!(glass.geometry.len() > photon::integrators::clear_view::MAX_SCENE_TRIANGLES);
    assert!(ClearView::new(&glass.geometry, &CameraModel::new(glass.camera.as_ref().unwrap())).is_none());
    for name in ["cornell_box.toml", "cornell_metals.toml", "cornell_glossy.toml", "led_phosphor.toml"] {
        let (in_view, visible, vouched) = check(&bundled_toml(name), 400_000, 7).expect("a clear view");
        println!("{name}: {in_view} points in view, {visible} visible, {vouched} vouched for");
        assert!(in_view > 10_000 && visible > 1000, "{name}: {in_view} in view, {visible} visible");
        if name == "cornell_box.toml" {
            // Most of the image is the inside of a wall or block face, away from edges. Points are
            // drawn per triangle here, which favours the blocks' small faces and their edges
            // (48 % vouched for); of a light-traced run's connections, 71 % are.
            assert!(vouched as f64 > 0.4 * visible as f64, "{name}: {vouched} of {visible} vouched for");
        }
    }
}

/// The office (a closed room) seen from inside, its walls reaching behind the eye.
fn office_with_camera(position: [f64; 3], look_at: [f64; 3]) -> String {
    let root = env!("CARGO_MANIFEST_DIR");
    let toml = bundled_toml("office.toml").replace("luminaires/", &format!("{root}/scenes/luminaires/"));
    assert!(!toml.contains("[camera]"));
    format!(
        "{toml}\n[camera]\nposition = {position:?}\nlook_at = {look_at:?}\nup = [0, 0, 1]\nfov_deg = 70\nresolution = [160, 120]\n"
    )
}

#[test]
fn the_clear_view_vouches_only_for_points_the_ray_sees_in_hard_cases() {
    let plate = |corners: &str| {
        format!("\n[[surfaces]]\nname = \"plate\"\nmaterial = \"desk\"\nshape = {{ type = \"quad\", corners = {corners} }}\n")
    };
    let cases = [
        ("inside the office", office_with_camera([0.3, 0.2, 1.6], [3.5, 2.8, 0.8])),
        ("looking along the floor", office_with_camera([2.0, 0.05, 0.0005], [2.0, 3.0, 0.0004])),
        ("almost in the back wall's plane", office_with_camera([3.9999, 0.01, 1.35], [3.9999, 3.0, 1.3])),
        // A small plate 1 cm before the eye.
        (
            "a plate before the eye",
            office_with_camera([2.0, 0.5, 1.2], [2.0, 3.0, 0.9])
                + &plate("[[1.99, 0.51, 1.19], [2.01, 0.51, 1.19], [2.01, 0.51, 1.21], [1.99, 0.51, 1.21]]"),
        ),
    ];
    for (what, toml) in cases {
        let s = scene(&toml);
        assert!(s.geometry.len() < 200, "{what}: {} triangles", s.geometry.len());
        // With the eye 0.5 mm over the floor the ray's rounding, seen from the floor's nearest
        // point in view, spans more than a pixel: no clear view is built.
        let Some((in_view, visible, vouched)) = check(&toml, 300_000, 11) else {
            assert_eq!(what, "looking along the floor", "{what}: no clear view");
            continue;
        };
        println!("{what}: {in_view} points in view, {visible} visible, {vouched} vouched for");
        assert!(in_view > 1000, "{what}: {in_view} in view");
        // It must vouch for some points where it can (not merely for none): all but the eye
        // 10⁻⁴ from a wall, whose plane passes so near the eye that it may block anywhere.
        if what != "almost in the back wall's plane" {
            assert!(vouched > visible / 10, "{what}: {vouched} of {visible} vouched for");
        }
    }
}

//! Every direction sampler against its pdf, by Pearson's χ² test as Mitsuba's `chi2` tests do:
//! N directions are binned on the sphere in bins of equal solid angle (equal in cos θ and φ about
//! +z); each bin's expected count is N ∫_bin pdf dΩ, integrated by a 32 × 32 midpoint rule inside
//! the bin; bins expecting fewer than 5 are pooled; the statistic's upper-tail probability must
//! exceed α = 10⁻³ (so a correct sampler fails one such test in a thousand; the seeds are fixed,
//! so a pass is reproducible). The pdf must also integrate to 1 over the sphere (to 10⁻³), and the
//! harness itself is shown to reject a sampler paired with the wrong pdf. ABg scatter, whose lobes
//! can be far narrower than these bins, is tested in its own direction-cosine bins (tests/abg.rs).

mod common;
use common::chi2_tail;

use std::f64::consts::PI;
use std::path::Path;

use glam::Vec3A;
use photon::bsdf::{Bsdf, Mode, Prepared};
use photon::lights::Emitter;
use photon::media::phase;
use photon::sampling::{cosine_hemisphere, cosine_power_lobe, uniform_hemisphere, uniform_sphere, Sampler};
use photon::scene::{LightShape, Material, Phase};
use photon::spectrum::Spectrum;

/// A material's run-wide constants, kept for the test's lifetime.
fn prepared(m: &Material) -> &'static Prepared {
    Box::leak(Box::new(Prepared::of(m, (400.0, 700.0))))
}

const N_COS: usize = 12;
const N_PHI: usize = 24;
const SAMPLES: usize = 300_000;
const ALPHA: f64 = 1e-3;

fn bin_of(w: Vec3A) -> usize {
    let i = (((w.z as f64 + 1.0) / 2.0 * N_COS as f64) as usize).min(N_COS - 1);
    let phi = (w.y as f64).atan2(w.x as f64).rem_euclid(2.0 * PI);
    let j = ((phi / (2.0 * PI) * N_PHI as f64) as usize).min(N_PHI - 1);
    i * N_PHI + j
}

fn direction(cos: f64, phi: f64) -> Vec3A {
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    Vec3A::new((sin * phi.cos()) as f32, (sin * phi.sin()) as f32, cos as f32)
}

/// (χ², degrees of freedom, upper-tail probability, ∫pdf dΩ) of `sample` against `pdf`.
fn chi2(seed: u64, mut sample: impl FnMut(&mut Sampler) -> Vec3A, pdf: impl Fn(Vec3A) -> f64) -> (f64, f64, f64, f64) {
    chi2_lossy(seed, |s| Some(sample(s)), pdf, false)
}

/// The same for a sampler that may return nothing (a path the model absorbs, as a microfacet
/// reflection leaving below the surface): the failures form one more cell, expected
/// N·(1 − ∫pdf dΩ), so both the shape and the share of lost samples are tested.
fn chi2_lossy(
    seed: u64,
    mut sample: impl FnMut(&mut Sampler) -> Option<Vec3A>,
    pdf: impl Fn(Vec3A) -> f64,
    lossy: bool,
) -> (f64, f64, f64, f64) {
    let mut s = Sampler::for_batch(seed, 0);
    let mut observed = vec![0.0f64; N_COS * N_PHI + 1];
    for _ in 0..SAMPLES {
        match sample(&mut s) {
            Some(w) => {
                assert!((w.length() - 1.0).abs() < 1e-4, "a sampled direction is not a unit vector: {w:?}");
                observed[bin_of(w)] += 1.0;
            }
            None => observed[N_COS * N_PHI] += 1.0,
        }
    }
    const SUB: usize = 64;
    let (d_cos, d_phi) = (2.0 / N_COS as f64, 2.0 * PI / N_PHI as f64);
    let mut expected = vec![0.0f64; N_COS * N_PHI];
    for i in 0..N_COS {
        for j in 0..N_PHI {
            let mut integral = 0.0;
            for a in 0..SUB {
                for b in 0..SUB {
                    let cos = -1.0 + (i as f64 + (a as f64 + 0.5) / SUB as f64) * d_cos;
                    let phi = (j as f64 + (b as f64 + 0.5) / SUB as f64) * d_phi;
                    integral += pdf(direction(cos, phi));
                }
            }
            expected[i * N_PHI + j] = integral * d_cos * d_phi / (SUB * SUB) as f64;
        }
    }
    let total: f64 = expected.iter().sum();
    expected.push(if lossy { (1.0 - total).max(0.0) } else { 0.0 });
    // Pool the bins expecting fewer than 5 into one.
    let common::Pearson { mut stat, mut cells, pooled_observed: pooled_o, pooled_expected: pooled_e } =
        common::pearson(&observed, &expected, SAMPLES);
    if pooled_e >= 5.0 {
        stat += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e;
        cells += 1;
    } else {
        assert!(pooled_o <= 5.0 + 5.0 * pooled_e, "{pooled_o} samples where the pdf expects {pooled_e}");
    }
    let dof = (cells - 1) as f64;
    (stat, dof, chi2_tail(stat, dof), total)
}

fn assert_matches(what: &str, seed: u64, sample: impl FnMut(&mut Sampler) -> Vec3A, pdf: impl Fn(Vec3A) -> f64) {
    let (stat, dof, p, total) = chi2(seed, sample, pdf);
    report(what, stat, dof, p, total);
}

/// As `assert_matches` for a sampler that may absorb: ∫pdf is then the share that leaves, ≤ 1.
fn assert_matches_lossy(
    what: &str,
    seed: u64,
    sample: impl FnMut(&mut Sampler) -> Option<Vec3A>,
    pdf: impl Fn(Vec3A) -> f64,
) {
    let (stat, dof, p, total) = chi2_lossy(seed, sample, pdf, true);
    println!("{what}: χ² = {stat:.1}, {dof} dof, p = {p:.3}, ∫pdf = {total:.6}");
    assert!(total <= 1.0 + 1e-3, "{what}: the pdf integrates to {total} > 1");
    assert!(p > ALPHA, "{what}: χ² = {stat:.1} for {dof} degrees of freedom, p = {p:.2e} < {ALPHA}");
}

fn report(what: &str, stat: f64, dof: f64, p: f64, total: f64) {
    println!("{what}: χ² = {stat:.1}, {dof} dof, p = {p:.3}, ∫pdf = {total:.6}");
    assert!((total - 1.0).abs() < 1e-3, "{what}: the pdf integrates to {total}, not 1");
    assert!(p > ALPHA, "{what}: χ² = {stat:.1} for {dof} degrees of freedom, p = {p:.2e} < {ALPHA}");
}

fn uv(s: &mut Sampler) -> (f32, f32) {
    (s.uniform_f32(), s.uniform_f32())
}

#[test]
fn the_harness_rejects_a_sampler_paired_with_the_wrong_pdf() {
    // Cosine-weighted directions judged against the uniform hemisphere pdf, and cos^5 against cos^4.
    let n = Vec3A::Z;
    let (_, _, p, _) = chi2(
        1,
        |s| {
            let (a, b) = uv(s);
            cosine_hemisphere(n, a, b)
        },
        |w| if w.z > 0.0 { 1.0 / (2.0 * PI) } else { 0.0 },
    );
    assert!(p < 1e-12, "p = {p}");
    let (_, _, p, _) = chi2(
        2,
        |s| {
            let (a, b) = uv(s);
            cosine_power_lobe(n, 5.0, a, b)
        },
        |w| if w.z > 0.0 { 5.0 / (2.0 * PI) * (w.z as f64).powi(4) } else { 0.0 },
    );
    assert!(p < 1e-12, "p = {p}");
}

#[test]
fn uniform_and_cosine_warps_match_their_pdfs() {
    let n = Vec3A::new(0.3, -0.5, 0.8).normalize();
    let cos = |w: Vec3A| w.dot(n) as f64;
    assert_matches(
        "uniform sphere",
        3,
        |s| {
            let (a, b) = uv(s);
            uniform_sphere(a, b)
        },
        |_| 1.0 / (4.0 * PI),
    );
    assert_matches(
        "uniform hemisphere",
        4,
        |s| {
            let (a, b) = uv(s);
            uniform_hemisphere(n, a, b)
        },
        |w| if cos(w) > 0.0 { 1.0 / (2.0 * PI) } else { 0.0 },
    );
    assert_matches(
        "cosine hemisphere",
        5,
        |s| {
            let (a, b) = uv(s);
            cosine_hemisphere(n, a, b)
        },
        |w| cos(w).max(0.0) / PI,
    );
    for (k, e) in [1.0f64, 5.0, 50.0].into_iter().enumerate() {
        assert_matches(
            &format!("cos^{e} lobe"),
            6 + k as u64,
            |s| {
                let (a, b) = uv(s);
                cosine_power_lobe(n, e as f32, a, b)
            },
            |w| if cos(w) > 0.0 { (e + 1.0) / (2.0 * PI) * cos(w).powf(e) } else { 0.0 },
        );
    }
}

#[test]
fn phase_functions_match_their_pdfs_and_a_neighbouring_g_is_rejected() {
    // A medium's scattering direction about an arbitrary direction of travel: isotropic, and
    // Henyey–Greenstein backward, nearly isotropic (below the isotropic cut-off), mildly and
    // strongly forward (g = 0.75 is tissue's, 0.9 a cloud's).
    let dir = Vec3A::new(-0.2, 0.6, 0.77).normalize();
    let cos = |w: Vec3A| w.dot(dir) as f64;
    assert_matches(
        "isotropic phase",
        60,
        |s| phase::sample(Phase::Isotropic, dir, s.uniform(), s.uniform()),
        |w| phase::pdf(Phase::Isotropic, cos(w)),
    );
    for (k, g) in [-0.5, 1e-6, 0.3, 0.75, 0.9].into_iter().enumerate() {
        let hg = Phase::HenyeyGreenstein { g };
        assert_matches(
            &format!("Henyey–Greenstein g = {g}"),
            61 + k as u64,
            |s| phase::sample(hg, dir, s.uniform(), s.uniform()),
            |w| phase::pdf(hg, cos(w)),
        );
    }
    // g = 0.75 judged against g = 0.7: the harness tells them apart.
    let (_, _, p, _) = chi2(
        67,
        |s| phase::sample(Phase::HenyeyGreenstein { g: 0.75 }, dir, s.uniform(), s.uniform()),
        |w| phase::pdf(Phase::HenyeyGreenstein { g: 0.7 }, cos(w)),
    );
    assert!(p < 1e-9, "p = {p}");
}

#[test]
fn lambertian_scattering_reflects_and_transmits_by_its_pdf() {
    // ρ = 0.3, τ = 0.5: given a scattering, the direction has density (ρ cos⁺ + τ cos⁻)/(π(ρ + τ))
    // about the normal on the side the photon came from.
    let m = Material::Lambertian { reflectance: Spectrum::Constant(0.3), transmittance: Spectrum::Constant(0.5) };
    let n = Vec3A::Z;
    let d = Vec3A::new(0.3, 0.2, -0.9).normalize();
    assert_matches(
        "lambertian reflect + transmit",
        9,
        |s| {
            Bsdf::<1>::new::<true>(&m, prepared(&m), &[550.0], n, || Vec3A::ZERO)
                .sample(-d, Mode::Importance, s)
                .unwrap()
                .wi
        },
        |w| {
            let c = w.z as f64;
            (0.3 * c.max(0.0) + 0.5 * (-c).max(0.0)) / (PI * 0.8)
        },
    );
    // Arriving from below, the lobes swap sides.
    let up = Vec3A::new(0.1, -0.2, 0.95).normalize();
    assert_matches(
        "lambertian from below",
        10,
        |s| {
            Bsdf::<1>::new::<true>(&m, prepared(&m), &[550.0], n, || Vec3A::ZERO)
                .sample(-up, Mode::Importance, s)
                .unwrap()
                .wi
        },
        |w| {
            let c = w.z as f64;
            (0.3 * (-c).max(0.0) + 0.5 * c.max(0.0)) / (PI * 0.8)
        },
    );
}

/// A point light with `distribution` aimed along `direction`, and its emitter.
fn point_light(distribution: &str) -> (Emitter, Vec3A) {
    let root = env!("CARGO_MANIFEST_DIR");
    let toml = format!(
        "[[lights]]\nname = \"lamp\"\nshape = {{ type = \"point\", position = [0, 0, 0] }}\npower_w = 1\n\
         direction = [0.2, 0.1, -1]\ndistribution = {distribution}\n"
    );
    let scene = photon::scene::load_str(Path::new(&format!("{root}/tests/data/ies/inline.toml")), &toml).unwrap();
    let axis = match scene.lights[0].shape {
        LightShape::Point { axis, .. } => axis.as_vec3a(),
        _ => unreachable!(),
    };
    (Emitter::new(&scene), axis)
}

#[test]
fn emission_directions_match_their_pdfs_for_every_distribution() {
    // The emitter's own sampler and pdf, as every integrator uses them: cosine power and the IES
    // tables (inverse CDF over sub-cells; the bilateral and the C90 lobe files are asymmetric).
    let cases = [
        "\"lambertian\"",
        "{ cosine_power = 7 }",
        "{ ies = \"cosine.ies\" }",
        "{ ies = \"bilateral.ies\", c0 = [1, 0, 0] }",
        "{ ies = \"c90_lobe.ies\", c0 = [0, 1, 0] }",
    ];
    for (k, distribution) in cases.into_iter().enumerate() {
        let (emitter, axis) = point_light(distribution);
        assert_matches(
            distribution,
            20 + k as u64,
            |s| {
                let (a, b) = uv(s);
                emitter.sample_direction(0, axis, a, b).0
            },
            |w| emitter.direction_pdf(0, axis, w) as f64,
        );
    }
    // An isotropic point light: the whole sphere.
    let (emitter, axis) = point_light("\"isotropic\"");
    assert_matches(
        "isotropic",
        30,
        |s| {
            let (a, b) = uv(s);
            emitter.sample_direction(0, axis, a, b).0
        },
        |w| emitter.direction_pdf(0, axis, w) as f64,
    );
}

/// GGX at grazing incidence needs finer integration than the harness's bins give a sharp lobe,
/// so the roughnesses tested are ≥ 0.3 for normals and ≥ 0.2 for reflected directions (twice as
/// wide; the lobe spans several bins); α = 0.05 is covered by the
/// smooth-limit test in tests/surfaces.rs.
#[test]
fn ggx_visible_normals_match_their_density_isotropic_and_anisotropic_up_to_grazing() {
    use photon::bsdf::microfacet::{Frame, Ggx};
    let mut seed = 40;
    for (ax, ay) in [(0.3, 0.3), (0.5, 0.5), (0.9, 0.9), (0.3, 0.7)] {
        let g = Ggx::new(ax, ay);
        for deg in [0.0f64, 45.0, 80.0, 89.0] {
            let (st, ct) = deg.to_radians().sin_cos();
            // Off the x axis, so an anisotropic lobe is seen obliquely.
            let w = Vec3A::new((st * 0.8) as f32, (st * 0.6) as f32, ct as f32).normalize();
            seed += 1;
            // Judged in a frame whose normal is not the harness's pole: at grazing incidence a
            // sliver of visible normals lies within 1° of the normal, finer than a polar bin's
            // integration grid, while elsewhere the grid resolves it.
            let frame = Frame::new(Vec3A::new(0.3, -0.5, 0.8).normalize(), Vec3A::X);
            assert_matches(
                &format!("GGX visible normals α = ({ax}, {ay}), θ = {deg}°"),
                seed,
                |s| {
                    let (a, b) = uv(s);
                    frame.to_world(g.sample_visible(w, [a, b]))
                },
                |m| g.visible_pdf(w, frame.to_local(m)),
            );
        }
    }
}

#[test]
fn rough_conductor_reflection_matches_its_pdf_from_both_sides() {
    let n = Vec3A::Z;
    let mut seed = 60;
    for alpha in [0.2, 0.5, 0.9] {
        let metal = Material::Conductor {
            eta: Spectrum::Constant(0.96),
            k: Spectrum::Constant(6.69),
            specular_reflectance: Spectrum::Constant(1.0),
            roughness: alpha.into(),
            scatter: None,
        };
        let bsdf = Bsdf::<1>::new::<false>(&metal, prepared(&metal), &[f64::NAN], n, || Vec3A::ZERO);
        for (deg, side) in [(0.0f64, 1.0f32), (45.0, 1.0), (80.0, -1.0), (89.0, 1.0)] {
            let (st, ct) = deg.to_radians().sin_cos();
            let wo = Vec3A::new(st as f32, 0.0, side * ct as f32).normalize();
            seed += 1;
            assert_matches_lossy(
                &format!("rough conductor α = {alpha}, θ_o = {deg}°, side {side}"),
                seed,
                |s| bsdf.sample(wo, Mode::Importance, s).map(|x| x.wi),
                |wi| bsdf.pdf(wo, wi, Mode::Importance),
            );
        }
    }
}

#[test]
fn the_lossy_harness_rejects_a_neighbouring_roughness() {
    // Samples of α = 0.5 judged against the pdf of α = 0.4: the lobe's width and lost share differ.
    let n = Vec3A::Z;
    let metal = |alpha: f64| Material::Conductor {
        eta: Spectrum::Constant(0.96),
        k: Spectrum::Constant(6.69),
        specular_reflectance: Spectrum::Constant(1.0),
        roughness: alpha.into(),
        scatter: None,
    };
    let (sampled, judged) = (metal(0.5), metal(0.4));
    let (a, b) = (
        Bsdf::<1>::new::<false>(&sampled, prepared(&sampled), &[f64::NAN], n, || Vec3A::ZERO),
        Bsdf::<1>::new::<false>(&judged, prepared(&judged), &[f64::NAN], n, || Vec3A::ZERO),
    );
    let wo = Vec3A::new(0.5, 0.0, 0.866).normalize();
    let (_, _, p, _) =
        chi2_lossy(70, |s| a.sample(wo, Mode::Importance, s).map(|x| x.wi), |wi| b.pdf(wo, wi, Mode::Importance), true);
    assert!(p < 1e-12, "p = {p}");
}

fn rough_glass(alpha: f64) -> Material {
    Material::Dielectric {
        ior: Spectrum::Constant(1.5),
        outside_ior: Spectrum::Constant(1.0),
        absorption_per_m: None,
        roughness: alpha.into(),
        scatter: None,
    }
}

#[test]
fn rough_dielectric_reflection_and_transmission_match_their_pdf_from_both_sides() {
    // From outside (front) and from inside, where beyond ~42° most light is totally reflected.
    // The normal is tilted off the harness's pole: refraction narrows the transmitted lobe (by
    // about 1 − 1/η), which at a pole would be finer than the bins' integration grid.
    let frame = photon::bsdf::microfacet::Frame::new(Vec3A::new(0.3, -0.5, 0.8).normalize(), Vec3A::X);
    let n = frame.n;
    let mut seed = 80;
    for alpha in [0.2, 0.5] {
        let bsdf =
            Bsdf::<1>::new::<false>(&rough_glass(alpha), prepared(&rough_glass(alpha)), &[f64::NAN], n, || Vec3A::ZERO);
        for (deg, side) in [(0.0f64, 1.0f32), (50.0, 1.0), (85.0, 1.0), (20.0, -1.0), (45.0, -1.0), (70.0, -1.0)] {
            let (st, ct) = deg.to_radians().sin_cos();
            let wo = frame.to_world(Vec3A::new(st as f32, 0.0, side * ct as f32)).normalize();
            for mode in [Mode::Importance, Mode::Radiance] {
                seed += 1;
                assert_matches_lossy(
                    &format!("rough dielectric α = {alpha}, θ_o = {deg}°, side {side}, {mode:?}"),
                    seed,
                    |s| bsdf.sample(wo, mode, s).map(|x| x.wi),
                    |wi| bsdf.pdf(wo, wi, mode),
                );
            }
        }
    }
}

#[test]
fn plastic_base_matches_its_pdf_with_the_coat_reflection_as_the_lost_share() {
    // The coat's mirror lobe is a delta: its samples fill the extra cell, expected p_s = 1 − ∫pdf.
    let frame = photon::bsdf::microfacet::Frame::new(Vec3A::new(0.3, -0.5, 0.8).normalize(), Vec3A::X);
    let mut seed = 120;
    for (rho, eta) in [(0.8, 1.5), (0.2, 1.5), (0.9, 2.2)] {
        let m = Material::Plastic { diffuse_reflectance: Spectrum::Constant(rho), ior: eta, roughness: 0.0.into() };
        let bsdf = Bsdf::<1>::new::<false>(&m, prepared(&m), &[f64::NAN], frame.n, || Vec3A::ZERO);
        for (deg, side) in [(0.0f64, 1.0f32), (60.0, 1.0), (85.0, -1.0)] {
            let (st, ct) = deg.to_radians().sin_cos();
            let wo = frame.to_world(Vec3A::new(st as f32, 0.0, side * ct as f32)).normalize();
            seed += 1;
            assert_matches_lossy(
                &format!("plastic ρ = {rho}, η = {eta}, θ_o = {deg}°, side {side}"),
                seed,
                |s| bsdf.sample(wo, Mode::Importance, s).filter(|x| !x.lobe.is_delta()).map(|x| x.wi),
                |wi| bsdf.pdf(wo, wi, Mode::Importance),
            );
        }
    }
}

#[test]
fn rough_plastic_matches_its_mixture_pdf() {
    let frame = photon::bsdf::microfacet::Frame::new(Vec3A::new(0.3, -0.5, 0.8).normalize(), Vec3A::X);
    let mut seed = 140;
    for (rho, alpha) in [(0.8, 0.2), (0.3, 0.5)] {
        let m = Material::Plastic { diffuse_reflectance: Spectrum::Constant(rho), ior: 1.5, roughness: alpha.into() };
        let bsdf = Bsdf::<1>::new::<false>(&m, prepared(&m), &[f64::NAN], frame.n, || Vec3A::ZERO);
        for (deg, side) in [(0.0f64, 1.0f32), (60.0, -1.0), (85.0, 1.0)] {
            let (st, ct) = deg.to_radians().sin_cos();
            let wo = frame.to_world(Vec3A::new(st as f32, 0.0, side * ct as f32)).normalize();
            seed += 1;
            assert_matches_lossy(
                &format!("rough plastic ρ = {rho}, α = {alpha}, θ_o = {deg}°, side {side}"),
                seed,
                |s| bsdf.sample(wo, Mode::Importance, s).map(|x| x.wi),
                |wi| bsdf.pdf(wo, wi, Mode::Importance),
            );
        }
    }
}

/// The anisotropic roughnesses tested, [αu, αv]: a brush narrow along the tangent and wide across
/// it, and the reverse, milder.
const ANISOTROPIC: [(f64, f64); 2] = [(0.05, 0.4), (0.3, 0.1)];

/// A frame tilted off the harness's pole (see the isotropic tests), whose x is the surface tangent.
fn tilted_frame() -> photon::bsdf::microfacet::Frame {
    photon::bsdf::microfacet::Frame::new(Vec3A::new(0.3, -0.5, 0.8).normalize(), Vec3A::new(0.6, 0.7, 0.2))
}

/// The direction at polar angle `theta_deg` from `frame.n` (`side` −1: below) and azimuth `phi_deg`
/// from the tangent `frame.t`.
fn toward(frame: &photon::bsdf::microfacet::Frame, theta_deg: f64, phi_deg: f64, side: f32) -> Vec3A {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    frame.to_world(Vec3A::new((st * cp) as f32, (st * sp) as f32, side * ct as f32)).normalize()
}

fn anisotropic_metal(au: f64, av: f64) -> Material {
    Material::Conductor {
        eta: Spectrum::Constant(0.96),
        k: Spectrum::Constant(6.69),
        specular_reflectance: Spectrum::Constant(1.0),
        roughness: photon::scene::Roughness { u: au, v: av },
        scatter: None,
    }
}

#[test]
fn anisotropic_ggx_visible_normals_match_their_density_at_every_azimuth() {
    // An anisotropic lobe depends on the azimuth of w about the α_x axis; 89° is grazing.
    use photon::bsdf::microfacet::Ggx;
    let frame = photon::bsdf::microfacet::Frame::new(Vec3A::new(0.3, -0.5, 0.8).normalize(), Vec3A::X);
    let mut seed = 500;
    for (ax, ay) in ANISOTROPIC {
        let g = Ggx::new(ax, ay);
        for (deg, phi) in [(0.0f64, 0.0f64), (40.0, 30.0), (70.0, 90.0), (80.0, 135.0), (89.0, 60.0), (89.0, 0.0)] {
            let (st, ct) = deg.to_radians().sin_cos();
            let (sp, cp) = phi.to_radians().sin_cos();
            let w = Vec3A::new((st * cp) as f32, (st * sp) as f32, ct as f32).normalize();
            seed += 1;
            assert_matches(
                &format!("GGX visible normals α = ({ax}, {ay}), θ = {deg}°, φ = {phi}°"),
                seed,
                |s| {
                    let (a, b) = uv(s);
                    frame.to_world(g.sample_visible(w, [a, b]))
                },
                |m| g.visible_pdf(w, frame.to_local(m)),
            );
        }
    }
}

#[test]
fn anisotropic_rough_conductor_matches_its_pdf_at_every_azimuth_from_both_sides() {
    let frame = tilted_frame();
    let mut seed = 540;
    for (au, av) in ANISOTROPIC {
        let metal = anisotropic_metal(au, av);
        let bsdf = Bsdf::<1>::new::<false>(&metal, prepared(&metal), &[f64::NAN], frame.n, || frame.t);
        for (deg, phi, side) in
            [(0.0f64, 0.0f64, 1.0f32), (45.0, 30.0, 1.0), (60.0, 90.0, -1.0), (80.0, 135.0, 1.0), (87.0, 60.0, -1.0)]
        {
            let wo = toward(&frame, deg, phi, side);
            seed += 1;
            assert_matches_lossy(
                &format!("rough conductor α = [{au}, {av}], θ_o = {deg}°, φ_o = {phi}°, side {side}"),
                seed,
                |s| bsdf.sample(wo, Mode::Importance, s).map(|x| x.wi),
                |wi| bsdf.pdf(wo, wi, Mode::Importance),
            );
        }
    }
}

#[test]
fn the_lossy_harness_rejects_a_lobe_turned_about_the_normal() {
    // Samples with the tangent along t judged against the pdf with it 30° away: same widths,
    // another orientation.
    let frame = tilted_frame();
    let metal = anisotropic_metal(0.05, 0.4);
    let turned = frame.to_world(Vec3A::new(30f32.to_radians().cos(), 30f32.to_radians().sin(), 0.0));
    let a = Bsdf::<1>::new::<false>(&metal, prepared(&metal), &[f64::NAN], frame.n, || frame.t);
    let b = Bsdf::<1>::new::<false>(&metal, prepared(&metal), &[f64::NAN], frame.n, || turned);
    let wo = toward(&frame, 40.0, 20.0, 1.0);
    let (_, _, p, _) = chi2_lossy(
        590,
        |s| a.sample(wo, Mode::Importance, s).map(|x| x.wi),
        |wi| b.pdf(wo, wi, Mode::Importance),
        true,
    );
    assert!(p < 1e-12, "p = {p}");
}

#[test]
fn anisotropic_rough_dielectric_matches_its_pdf_at_every_azimuth_from_both_sides() {
    // Reflection and refraction together (the refracted lobe is the narrower), from outside and
    // from inside (total internal reflection beyond ~42°), in both modes.
    let frame = tilted_frame();
    let mut seed = 600;
    for (au, av) in ANISOTROPIC {
        let glass = Material::Dielectric {
            ior: Spectrum::Constant(1.5),
            outside_ior: Spectrum::Constant(1.0),
            absorption_per_m: None,
            roughness: photon::scene::Roughness { u: au, v: av },
            scatter: None,
        };
        let bsdf = Bsdf::<1>::new::<false>(&glass, prepared(&glass), &[f64::NAN], frame.n, || frame.t);
        for (deg, phi, side) in
            [(0.0f64, 0.0f64, 1.0f32), (50.0, 30.0, 1.0), (85.0, 135.0, 1.0), (30.0, 60.0, -1.0), (60.0, 100.0, -1.0)]
        {
            let wo = toward(&frame, deg, phi, side);
            for mode in [Mode::Importance, Mode::Radiance] {
                seed += 1;
                assert_matches_lossy(
                    &format!("rough dielectric α = [{au}, {av}], θ_o = {deg}°, φ_o = {phi}°, side {side}, {mode:?}"),
                    seed,
                    |s| bsdf.sample(wo, mode, s).map(|x| x.wi),
                    |wi| bsdf.pdf(wo, wi, mode),
                );
            }
        }
    }
}

#[test]
fn anisotropic_rough_plastic_matches_its_mixture_pdf_at_every_azimuth() {
    // The base's directions follow the coat's transmittance, which now varies with azimuth too.
    let frame = tilted_frame();
    let mut seed = 660;
    for (au, av) in ANISOTROPIC {
        let m = Material::Plastic {
            diffuse_reflectance: Spectrum::Constant(0.6),
            ior: 1.5,
            roughness: photon::scene::Roughness { u: au, v: av },
        };
        let bsdf = Bsdf::<1>::new::<false>(&m, prepared(&m), &[f64::NAN], frame.n, || frame.t);
        for (deg, phi, side) in [(0.0f64, 0.0f64, 1.0f32), (45.0, 30.0, 1.0), (70.0, 90.0, -1.0), (85.0, 135.0, 1.0)] {
            let wo = toward(&frame, deg, phi, side);
            seed += 1;
            assert_matches_lossy(
                &format!("rough plastic α = [{au}, {av}], θ_o = {deg}°, φ_o = {phi}°, side {side}"),
                seed,
                |s| bsdf.sample(wo, Mode::Importance, s).map(|x| x.wi),
                |wi| bsdf.pdf(wo, wi, Mode::Importance),
            );
        }
    }
}

/// The emitter view's pixel jitter (`owen_sobol_2d`): point k of a seed's sequence, over many
/// seeds, is uniform on the unit square (the scrambling randomises each point on its own), and
/// that for every k tried, early and late in the sequence. Seeds drawn from a random stream
/// (consecutive seeds would test the hash's mixing of neighbours too, which it need not pass).
#[test]
fn scrambled_sobol_points_are_uniform_over_seeds() {
    use photon::sampling::owen_sobol_2d;
    const CELLS: usize = 16;
    const SEEDS: usize = 51_200;
    let mut s = Sampler::for_batch(31, 0);
    for index in [0u32, 1, 2, 3, 5, 17, 1000, 65_537] {
        let mut counts = [0u32; CELLS * CELLS];
        for _ in 0..SEEDS {
            let (x, y) = owen_sobol_2d(index, (s.uniform() * 4_294_967_296.0) as u32);
            counts[(y * CELLS as f32) as usize * CELLS + (x * CELLS as f32) as usize] += 1;
        }
        let expected = SEEDS as f64 / (CELLS * CELLS) as f64;
        let stat: f64 = counts.iter().map(|&c| (c as f64 - expected).powi(2) / expected).sum();
        let dof = (CELLS * CELLS - 1) as f64;
        report(&format!("scrambled Sobol point {index}"), stat, dof, chi2_tail(stat, dof), 1.0);
    }
    // The harness sees a bias of this size: the same points with x warped to x^1.2.
    let mut counts = [0u32; CELLS * CELLS];
    for _ in 0..SEEDS {
        let (x, y) = owen_sobol_2d(17, (s.uniform() * 4_294_967_296.0) as u32);
        let (x, y) = (x.powf(1.2), y);
        counts[(y * CELLS as f32) as usize * CELLS + (x * CELLS as f32) as usize] += 1;
    }
    let expected = SEEDS as f64 / (CELLS * CELLS) as f64;
    let stat: f64 = counts.iter().map(|&c| (c as f64 - expected).powi(2) / expected).sum();
    let dof = (CELLS * CELLS - 1) as f64;
    assert!(chi2_tail(stat, dof) < 1e-6, "a warped square passed: χ² = {stat:.1}");
}

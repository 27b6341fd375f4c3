//! `photon info` reports exactly the effects each bundled scene contains (table-driven).

use std::process::Command;

#[test]
fn info_lists_the_effects_each_bundled_scene_calls_for() {
    let table = [
        ("cornell_box", "spectral", "spectral, diffuse_reflection, camera"),
        ("cornell_metals", "spectral", "spectral, diffuse_reflection, glossy_reflection, camera"),
        (
            "cornell_glossy",
            "spectral",
            "spectral, diffuse_reflection, glossy_reflection, glossy_transmission, refraction, camera",
        ),
        ("furnace", "grey", "diffuse_reflection"),
        ("parallel_plates", "grey", ""),
        ("office", "grey", "diffuse_reflection"),
        ("luminaire", "grey", ""),
        ("reflector", "spectral", "spectral, specular_reflection, glossy_reflection"),
        ("spotlight", "spectral", "spectral, glossy_reflection"),
        ("tissue_slab", "grey", "specular_reflection, refraction, absorbing_media, volume_scattering"),
        ("lsc_plate", "spectral", "spectral, specular_reflection, refraction, absorbing_media, fluorescence"),
        (
            "led_phosphor",
            "spectral",
            "spectral, diffuse_reflection, specular_reflection, refraction, absorbing_media, volume_scattering, \
             fluorescence, camera",
        ),
        (
            "glass",
            "spectral",
            "spectral, diffuse_reflection, specular_reflection, refraction, dispersion, absorbing_media, camera",
        ),
    ];
    let mut listed: Vec<String> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes"))
        .unwrap()
        .filter_map(|e| e.ok()?.path().file_stem().map(|s| s.to_string_lossy().into_owned()))
        .filter(|s| s != "meshes" && s != "luminaires")
        .collect();
    listed.sort();
    let mut names: Vec<&str> = table.iter().map(|t| t.0).collect();
    names.sort();
    assert_eq!(listed, names, "every bundled scene needs a row in this table");
    for (scene, transport, effects) in table {
        let path = format!("{}/scenes/{scene}.toml", env!("CARGO_MANIFEST_DIR"));
        let o = Command::new(env!("CARGO_BIN_EXE_photon")).args(["info", &path]).output().unwrap();
        assert!(o.status.success());
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains(&format!("transport: {transport}\n")), "{scene}:\n{text}");
        assert!(text.contains(&format!("effects: {effects}\n")), "{scene}:\n{text}");
    }
}

#[test]
fn effects_follow_the_materials_not_the_file_layout() {
    use photon::scene::load_str;
    let base = |material: &str| {
        format!(
            "[materials.m]\n{material}\n[[surfaces]]\nname = \"s\"\nmaterial = \"m\"\n\
             shape = {{ type = \"box\", min = [0, 0, 0], max = [1, 1, 1] }}\n\
             [[lights]]\nname = \"l\"\nshape = {{ type = \"point\", position = [3, 3, 3] }}\npower_w = 1\n"
        )
    };
    let fx =
        |material: &str| load_str(std::path::Path::new("x.toml"), &base(material)).unwrap().effects.names().join(", ");
    assert_eq!(fx("type = \"lambertian\"\nreflectance = 0.5"), "diffuse_reflection");
    // A table that is flat over the whole range is grey.
    assert_eq!(fx("type = \"lambertian\"\nreflectance = { table = [[300, 0.4], [900, 0.4]] }"), "diffuse_reflection");
    assert_eq!(
        fx("type = \"lambertian\"\nreflectance = { table = [[300, 0.2], [900, 0.4]] }"),
        "spectral, diffuse_reflection"
    );
    assert_eq!(fx("type = \"lambertian\"\nreflectance = 0\ntransmittance = 0.5"), "diffuse_transmission");
    assert_eq!(fx("type = \"mirror\""), "specular_reflection");
    assert_eq!(fx("type = \"dielectric\""), "specular_reflection, refraction");
    assert_eq!(fx("type = \"dielectric\"\nabsorption_per_m = 2"), "specular_reflection, refraction, absorbing_media");
    assert_eq!(
        fx("type = \"dielectric\"\nior = { cauchy = [1.5, 0.004] }"),
        "spectral, specular_reflection, refraction, dispersion"
    );
    assert_eq!(fx("type = \"absorber\""), "");
}

#[test]
fn each_bundled_scene_does_only_the_work_its_effects_call_for() {
    // Shown by counters, not by belief: a grey scene draws no wavelength, a scene without
    // dielectrics evaluates no Fresnel term, a scene without a camera casts no shadow ray toward
    // one and splats nothing; and each effect a scene has does run.
    use photon::run::{apply_options, simulate, RunOptions};
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");
    for scene in ["cornell_box", "furnace", "parallel_plates", "office", "luminaire", "glass", "tissue_slab"] {
        let mut s = photon::scene::load(std::path::Path::new(&format!("{dir}/{scene}.toml"))).unwrap();
        let photons = 20_000;
        let opts = RunOptions { photons: Some(photons), threads: Some(2), ..Default::default() };
        let chosen = apply_options(&mut s, &opts).unwrap();
        let r = simulate(&s, &opts, &chosen, &std::sync::atomic::AtomicBool::new(false)).unwrap();
        let c = r.tallies.counters;
        let fx = &s.effects;
        assert_eq!(c.wavelength_samples, if fx.spectral { photons } else { 0 }, "{scene}: wavelengths");
        assert_eq!(c.fresnel_evaluations > 0, fx.refraction, "{scene}: {} Fresnel terms", c.fresnel_evaluations);
        assert_eq!(c.shadow_rays > 0, fx.camera, "{scene}: {} shadow rays", c.shadow_rays);
        assert_eq!(c.splats > 0, fx.camera, "{scene}: {} splats", c.splats);
        assert_eq!(c.free_flights > 0, fx.volume_scattering, "{scene}: {} free flights", c.free_flights);
        assert_eq!(c.phase_samples > 0, fx.volume_scattering, "{scene}: {} phase samples", c.phase_samples);
    }
}

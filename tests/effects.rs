//! `photon info` reports exactly the effects each bundled scene contains (table-driven).

use std::process::Command;

#[test]
fn info_lists_the_effects_each_bundled_scene_calls_for() {
    let table = [
        ("cornell_box", "spectral", "spectral, diffuse_reflection, camera"),
        ("furnace", "grey", "diffuse_reflection"),
        ("parallel_plates", "grey", ""),
        ("office", "grey", "diffuse_reflection"),
        ("luminaire", "grey", ""),
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

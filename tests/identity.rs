//! Restructuring the source must change no output: every bundled scene, with each integrator
//! making the image, at a fixed seed and photon count, writes byte for byte the files it wrote
//! when `tests/data/output_hashes.txt` was made (FNV-1a 64 of each file; run.json is left out,
//! as it holds timings). After a change that is meant to alter results, regenerate the table
//! with `PHOTON_WRITE_HASHES=1 cargo test --release --test identity` and say why in the commit.

use std::path::Path;
use std::process::Command;

const SCENES: [&str; 6] = ["cornell_box", "furnace", "parallel_plates", "glass", "office", "luminaire"];
const INTEGRATORS: [&str; 3] = ["light", "path", "bdpt"];
const TABLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/output_hashes.txt");

/// FNV-1a, 64 bit: enough to tell two files apart, with no dependency.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// Every output file but run.json under `dir`, relative and sorted.
fn outputs(dir: &Path, prefix: &str, out: &mut Vec<(String, u64)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().collect();
    entries.sort_by_key(|e| e.file_name());
    for e in entries {
        let name = format!("{prefix}{}", e.file_name().to_string_lossy());
        if e.path().is_dir() {
            outputs(&e.path(), &format!("{name}/"), out);
        } else if name != "run.json" && !name.ends_with(".png") {
            out.push((name, fnv1a(&std::fs::read(e.path()).unwrap())));
        }
    }
}

#[test]
fn bundled_scenes_write_the_same_bytes_as_before() {
    let root = env!("CARGO_MANIFEST_DIR");
    let base = std::env::temp_dir().join(format!("photon-identity-{}", std::process::id()));
    let mut lines = Vec::new();
    for scene in SCENES {
        for integrator in INTEGRATORS {
            let out = base.join(format!("{scene}-{integrator}"));
            let o = Command::new(env!("CARGO_BIN_EXE_photon"))
                .current_dir(root)
                // The luminaire files' issue date, fixed (1970-01-01) so their bytes are too.
                .env("SOURCE_DATE_EPOCH", "0")
                .args(["run", &format!("scenes/{scene}.toml"), "--photons", "40000", "--seed", "1"])
                .args(["--threads", "2", "--integrator", integrator, "--quiet", "--out"])
                .arg(&out)
                .output()
                .unwrap();
            assert!(o.status.success(), "{scene} {integrator}: {}", String::from_utf8_lossy(&o.stderr));
            let mut files = Vec::new();
            outputs(&out, "", &mut files);
            lines.extend(files.into_iter().map(|(f, h)| format!("{scene} {integrator} {f} {h:016x}")));
        }
    }
    let _ = std::fs::remove_dir_all(&base);
    let table = lines.join("\n") + "\n";
    if std::env::var_os("PHOTON_WRITE_HASHES").is_some() {
        std::fs::write(TABLE, &table).unwrap();
        return;
    }
    let expected = std::fs::read_to_string(TABLE).unwrap();
    let differ: Vec<String> = expected
        .lines()
        .zip(table.lines())
        .filter(|(a, b)| a != b)
        .map(|(a, b)| format!("expected {a}\n   found {b}"))
        .collect();
    assert!(
        differ.is_empty() && expected.lines().count() == table.lines().count(),
        "outputs changed:\n{}",
        differ.join("\n")
    );
}

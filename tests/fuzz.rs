//! Fuzz harness for the scene loader (TOML, OBJ, spectrum CSV, IES) and the run (issue #16).
//!
//! A deterministic mutation fuzzer that runs inside `cargo test`: seed inputs (the bundled scenes
//! with their meshes, spectra and IES files, and small hand-written scenes), mutated by structural
//! TOML edits (extreme numbers, swapped/deleted/duplicated keys and tables, odd names, inserted
//! keys and tables) and by byte-level edits (flip, insert, delete, splice) of the scene and of its
//! auxiliary files. Each case is written into a fresh folder under the system temp dir, loaded with
//! `photon::scene::load_str`, and, when it loads, simulated with a few thousand photons on one
//! thread; the outputs are then built and written through the library as `src/main.rs` does. A
//! case fails when
//!
//! * anything panics (the loader, the run — `simulate`'s "batch N failed" is a caught panic —, or
//!   the output code): class "panic";
//! * a number that would be written (flux.json, flux.csv, run.json, the image's XYZ/RGB/Y_var, the
//!   maps, the far-field and spectrum tables) is not finite: class "non-finite";
//! * writing the outputs fails after the whole simulation ran: class "late failure";
//! * an error message is empty, does not name a file of the case, or names a line the file does
//!   not have: class "bad message";
//! * the loader accepts a scene that cannot be run (a camera of 0 pixels after an overflowing
//!   resolution such as [4294967296, 4294967296]): class "accepted".
//!
//! The command line is fuzzed too, through the built binary, with a handful of cases (exit status
//! other than 0/1/2, or "panicked" on stderr, fails).
//!
//! Default: 400 cases (about 6-12 s in release mode on 2 cores, the command line about 4 s more). Longer runs
//! (about 30 ms a case):
//!
//! ```sh
//! PHOTON_FUZZ_CASES=20000 cargo test --release --test fuzz -- --nocapture
//! PHOTON_FUZZ_CASES=20000 PHOTON_FUZZ_SEED=7 cargo test --release --test fuzz -- --nocapture
//! ```
//!
//! Every case is reproducible from the seed and its index: `PHOTON_FUZZ_SEED=S PHOTON_FUZZ_ONLY=I`
//! runs case I alone and prints its whole input (`-- --nocapture`). `PHOTON_FUZZ_KEEP=1` keeps the
//! case folders.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Mutex;
use std::time::Instant;

use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use photon::error::Error;
use photon::integrators::camera::Integrator;
use photon::integrators::particle::{Estimator, TransportOptions};
use photon::run::{apply_options, simulate, RunOptions};
use photon::scene::Scene;

const DEFAULT_CASES: usize = 400;
const DEFAULT_SEED: u64 = 0x16_F0_22;
/// Scenes bigger than this are not run (counted as "skipped: too large").
const MAX_RUN_PIXELS: u64 = 250_000;
const MAX_RUN_TRIANGLES: usize = 300_000;
const MAX_RUN_BINS: usize = 100_000;
/// Bytes of an input shown in a report.
const EXCERPT: usize = 1500;

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|s| s.trim().parse().ok())
}

// ------------------------------------------------------------------------------ panic capture

static PANICS: Mutex<Vec<String>> = Mutex::new(Vec::new());
thread_local! {
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// Records every panic's message and location; prints it as usual only outside fuzz cases.
fn install_panic_hook() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let msg = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "?".into());
            let loc = info.location().map(|l| format!("{}:{}", l.file(), l.line())).unwrap_or_default();
            let in_case = QUIET.with(|q| q.get()) || rayon::current_thread_index().is_some();
            if in_case {
                PANICS.lock().unwrap_or_else(|e| e.into_inner()).push(format!("{msg} at {loc}"));
            } else {
                previous(info);
            }
        }));
    });
}

fn take_panics() -> Vec<String> {
    std::mem::take(&mut *PANICS.lock().unwrap_or_else(|e| e.into_inner()))
}

fn payload_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "?".into())
}

// ------------------------------------------------------------------------------ inputs

/// One case's files, by path relative to the case folder; `scene` is the scene file's path.
#[derive(Clone)]
struct Input {
    label: String,
    scene: String,
    files: BTreeMap<String, Vec<u8>>,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Auxiliary files every case folder gets (the layout of the repository: scenes/, scenes/meshes,
/// scenes/luminaires, spectra/).
fn aux_files() -> BTreeMap<String, Vec<u8>> {
    let r = root();
    let mut m = BTreeMap::new();
    let mut add = |rel: &str, from: PathBuf| {
        m.insert(rel.to_string(), std::fs::read(&from).unwrap_or_else(|e| panic!("{}: {e}", from.display())));
    };
    for f in ["cornell_short_block.obj", "cornell_tall_block.obj"] {
        add(&format!("scenes/meshes/{f}"), r.join("scenes/meshes").join(f));
    }
    add("scenes/luminaires/office_downlight.ies", r.join("scenes/luminaires/office_downlight.ies"));
    for f in ["bilateral.ies", "c90_lobe.ies", "cosine.ies", "isotropic.ies"] {
        add(&format!("scenes/luminaires/{f}"), r.join("tests/data/ies").join(f));
    }
    for f in ["cornell_green.csv", "cornell_light.csv", "cornell_red.csv", "cornell_white.csv"] {
        add(&format!("spectra/{f}"), r.join("spectra").join(f));
    }
    m.insert("scenes/meshes/uvquad.obj".into(), UV_QUAD_OBJ.as_bytes().to_vec());
    m.insert("spectra/tiny.csv".into(), TINY_CSV.as_bytes().to_vec());
    m
}

const UV_QUAD_OBJ: &str = "# a textured unit quad, z = 0, facing +z\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";
const TINY_CSV: &str = "wavelength_nm,value\n400,0.2\n550,0.9\n700,0.4\n";

/// Hand-written seed scenes, small and quick.
const HAND_SCENES: &[(&str, &str)] = &[
    (
        "base",
        r#"[simulation]
photons = 2000

[materials.white]
type = "lambertian"
reflectance = 0.5

[[surfaces]]
name = "floor"
material = "white"
shape = { type = "quad", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }

[[lights]]
name = "lamp"
shape = { type = "quad", corners = [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]] }
power_w = 10
"#,
    ),
    (
        "camera_bdpt",
        r#"[simulation]
integrator = "bdpt"
wavelength_range_nm = [400, 700]

[camera]
position = [0.5, 0.5, 3]
look_at = [0.5, 0.5, 0]
up = [0, 1, 0]
fov_deg = 50
resolution = [12, 10]

[materials.red]
type = "lambertian"
reflectance = { table = [[400, 0.1], [600, 0.2], [700, 0.8]] }
transmittance = 0.1

[materials.chrome]
type = "mirror"
reflectance = 0.9

[[surfaces]]
name = "back"
material = "red"
shape = { type = "quad", corners = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]] }
map = { resolution = [4, 3] }
spectrum_bins = 3

[[surfaces]]
name = "mirror"
material = "chrome"
shape = { type = "disk", center = [0.5, 0.1, 0.5], normal = [0, 1, 0], radius = 0.3, segments = 16 }

[[lights]]
name = "panel"
shape = { type = "quad", corners = [[0, 1, 1], [1, 1, 1], [1, 1, 0], [0, 1, 0]] }
radiance = 0.02
distribution = { cosine_power = 3 }
spectrum = { blackbody_k = 3000 }
"#,
    ),
    (
        "glass_tank",
        r#"[simulation]
photons = 3000
integrator = "path"

[scene]
unit = "cm"

[camera]
position = [0, 30, -60]
look_at = [0, 5, 0]
fov_deg = 40
resolution = [10, 8]

[materials.water]
type = "dielectric"
ior = { cauchy = [1.32, 0.003] }
absorption_per_m = { table = [[380, 0.1], [780, 2.0]] }

[materials.glass]
type = "dielectric"
ior = 1.5
outside_ior = 1.33

[materials.floor]
type = "lambertian"
reflectance = { file = "../spectra/tiny.csv" }

[[surfaces]]
name = "tank"
material = "water"
shape = { type = "box", min = [-10, 0.1, -10], max = [10, 10, 10] }

[[surfaces]]
name = "ball"
material = "glass"
shape = { type = "sphere", center = [0, 5, 0], radius = 2, subdivisions = 2, transform = { scale = 1.5, rotate_deg = [10, 20, 30], translate = [0, 0, 0] } }

[[surfaces]]
name = "floor"
material = "floor"
shape = { type = "quad", corners = [[-30, 0, -30], [-30, 0, 30], [30, 0, 30], [30, 0, -30]] }
map = { resolution = [5, 5] }

[[lights]]
name = "bulb"
shape = { type = "point", position = [0, 5, 0] }
power_lm = 800
spectrum = { file = "../spectra/cornell_light.csv" }

[[lights]]
name = "beam"
shape = { type = "point", position = [5, 40, 0] }
direction = [0, -1, 0]
distribution = "collimated"
power_w = 2
"#,
    ),
    (
        "ies_farfield",
        r#"[simulation]
photons = 2000

[materials.grey]
type = "lambertian"
reflectance = 0.3

[[surfaces]]
name = "plate"
material = "grey"
shape = { type = "mesh", file = "meshes/uvquad.obj", transform = { translate = [-0.5, -0.5, -1] } }
map = { resolution = [3, 3] }

[[lights]]
name = "lobe"
shape = { type = "point", position = [0, 0, 0] }
direction = [0, 0, -1]
distribution = { ies = "luminaires/c90_lobe.ies", c0 = [1, 0, 0] }

[[lights]]
name = "panel"
shape = { type = "disk", center = [0, 0, 1], normal = [0, 0, -1], radius = 0.2, segments = 8 }
distribution = { ies = "luminaires/cosine.ies" }
power_w = 1

[[detectors]]
type = "farfield"
name = "gonio"
resolution = [6, 8]
nadir = [0, 0, -1]
c0 = [1, 0, 0]
"#,
    ),
    (
        "surfaces",
        r#"[simulation]
photons = 3000
integrator = "bdpt"
wavelength_range_nm = [400, 700]

[camera]
position = [0.5, 0.5, 3]
look_at = [0.5, 0.5, 0]
fov_deg = 50
resolution = [10, 8]

[materials.alu]
type = "conductor"
metal = "Al"
roughness = 0.2

[materials.gold]
type = "conductor"
eta = { table = [[400, 1.5], [700, 0.2]] }
k = 3.2
specular_reflectance = 0.9
scatter = { abg = [0.02, 0.001, 2] }

[materials.satin]
type = "plastic"
diffuse_reflectance = { file = "../spectra/tiny.csv" }
ior = 1.5
roughness = 0.3

[materials.gloss]
type = "plastic"
diffuse_reflectance = 0.8

[materials.frosted]
type = "dielectric"
ior = "BK7"
roughness = 0.1

[materials.crown]
type = "dielectric"
ior = { sellmeier = { B = [1.03961212, 0.231792344, 1.01046945], C = [0.00600069867, 0.0200179144, 103.560653] } }
scatter = { abg = [0.1, 0.05, 1.5] }

[[surfaces]]
name = "back"
material = "satin"
shape = { type = "quad", corners = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]] }

[[surfaces]]
name = "floor"
material = "gloss"
shape = { type = "quad", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }

[[surfaces]]
name = "plate"
material = "alu"
shape = { type = "disk", center = [0.3, 0.5, 0.5], normal = [1, 0, 0], radius = 0.2, segments = 12 }

[[surfaces]]
name = "bar"
material = "gold"
shape = { type = "box", min = [0.7, 0.0, 0.2], max = [0.9, 0.3, 0.4] }

[[surfaces]]
name = "ball"
material = "frosted"
shape = { type = "sphere", center = [0.5, 0.3, 0.6], radius = 0.15, subdivisions = 2 }

[[surfaces]]
name = "lens"
material = "crown"
shape = { type = "sphere", center = [0.2, 0.2, 0.3], radius = 0.08, subdivisions = 1 }

[[lights]]
name = "panel"
shape = { type = "quad", corners = [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]] }
power_w = 5
"#,
    ),
];

/// The bundled scenes, with cameras shrunk to a few pixels.
fn seeds() -> Vec<Input> {
    let aux = aux_files();
    let mut out = Vec::new();
    let mut names: Vec<PathBuf> = std::fs::read_dir(root().join("scenes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    names.sort();
    for p in names {
        let text = std::fs::read_to_string(&p).unwrap();
        let mut in_camera = false;
        let shrunk: Vec<String> = text
            .lines()
            .map(|l| {
                if l.starts_with('[') {
                    in_camera = l.trim() == "[camera]";
                }
                if in_camera && l.trim_start().starts_with("resolution") {
                    "resolution = [16, 12]".to_string()
                } else {
                    l.to_string()
                }
            })
            .collect();
        let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
        let scene = format!("scenes/{stem}.toml");
        let mut files = aux.clone();
        files.insert(scene.clone(), (shrunk.join("\n") + "\n").into_bytes());
        out.push(Input { label: format!("scenes/{stem}.toml"), scene, files });
    }
    for (name, text) in HAND_SCENES {
        let scene = format!("scenes/{name}.toml");
        let mut files = aux.clone();
        files.insert(scene.clone(), text.as_bytes().to_vec());
        out.push(Input { label: format!("hand-written `{name}`"), scene, files });
    }
    out
}

// ------------------------------------------------------------------------------ mutators

struct Fuzz {
    rng: Xoshiro256PlusPlus,
}

impl Fuzz {
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.rng.next_u64() % n as u64) as usize
        }
    }
    fn chance(&mut self, p: f64) -> bool {
        (self.rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }
    fn pick<'a, T: ?Sized>(&mut self, xs: &'a [&'a T]) -> &'a T {
        xs[self.below(xs.len())]
    }
}

/// Numbers for TOML values.
const TOML_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1e-300",
    "1e300",
    "1e308",
    "-1e308",
    "-0.0",
    "5e-324",
    "8589934592",
    "4294967296",
    "4294967295",
    "2147483648",
    "9223372036854775807",
    "18446744073709551615",
    "1e19",
    "9e18",
    "nan",
    "inf",
    "-inf",
    "+nan",
    "\"nan\"",
    "1e-9",
    "1e15",
    "1e16",
    "-1e-300",
    "0.9999999999",
    "1.0000000001",
    "1",
    "2",
    "3",
    "0.5",
    "100000",
];

/// Whole values for `key = value` lines.
const TOML_VALUES: &[&str] = &[
    "[4294967296, 4294967296]",
    "[8589934592, 2147483648]",
    "[4611686018427387904, 4]",
    "[0, 1]",
    "[1, 1]",
    "[1, 0]",
    "[1024, 1024]",
    "[1025, 1]",
    "[4096, 4096]",
    "[65536, 256]",
    "[]",
    "[1e308, 1e308, 1e308]",
    "[-1e308, 1e308, 0]",
    "[0, 0, 0]",
    "[nan, 0, 0]",
    "[1e-300, 0, 0]",
    "[1, 2]",
    "{}",
    "\"\"",
    "\"x\"",
    "true",
    "1979-05-27T07:32:00Z",
    "{ blackbody_k = 1e-300 }",
    "{ blackbody_k = 1e300 }",
    "{ blackbody_k = 1 }",
    "{ table = [[500, 1e300]] }",
    "{ table = [[500, 1e308], [600, 1e308]] }",
    "{ table = [[1, 0], [100000, 1]] }",
    "{ table = [[500, 0]] }",
    "{ table = [[1e-300, 1], [1e300, 1]] }",
    "{ table = [] }",
    "{ file = \"../spectra/cornell_light.csv\" }",
    "{ file = \"../spectra/tiny.csv\" }",
    "{ file = \"/\" }",
    "{ file = \"\" }",
    "{ file = \"nonexistent.csv\" }",
    "{ cauchy = [1e300, 0] }",
    "{ cauchy = [1.5, -1e300] }",
    "{ cauchy = [1.5, 1e300] }",
    "{ cauchy = [1e-300, 0] }",
    "{ cosine_power = 1e300 }",
    "{ cosine_power = 1e-300 }",
    "{ cosine_power = 0 }",
    "\"collimated\"",
    "\"isotropic\"",
    "\"lambertian\"",
    "{ ies = \"luminaires/office_downlight.ies\" }",
    "{ ies = \"luminaires/bilateral.ies\", c0 = [0, 0, 1] }",
    "{ ies = \"luminaires/isotropic.ies\", c0 = [1e-300, 0, 0] }",
    "{ ies = \"luminaires\" }",
    "{ resolution = [1, 1] }",
    "{ resolution = [1024, 1024] }",
    "{ resolution = [4294967296, 4294967296] }",
    "{ type = \"point\", position = [0, 0, 0] }",
    "{ type = \"sphere\", center = [0, 0, 0], radius = 1e-300 }",
    "{ type = \"sphere\", center = [0, 0, 0], radius = 1e300 }",
    "{ type = \"disk\", center = [0, 0, 0], normal = [0, 0, 1], radius = 1, segments = 3 }",
    "{ type = \"disk\", center = [0, 0, 0], normal = [0, 0, 1e-300], radius = 1e-300 }",
    "{ type = \"box\", min = [0, 0, 0], max = [0, 0, 0] }",
    "{ type = \"box\", min = [1, 1, 1], max = [0, 0, 0] }",
    "{ type = \"mesh\", file = \"meshes/cornell_short_block.obj\" }",
    "{ type = \"mesh\", file = \"meshes/uvquad.obj\", transform = { scale = 1e-300 } }",
    "{ type = \"quad\", corners = [[0, 0, 0], [1e-300, 0, 0], [0, 1e-300, 0], [0, 0, 0]] }",
    "{ type = \"quad\", corners = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]] }",
    "{ type = \"quad\", corners = [[0, 0, 0], [1e15, 0, 0], [1e15, 1e-15, 0], [0, 1e-15, 0]] }",
    "{ translate = [1e15, 0, 0] }",
    "{ scale = 1e-300 }",
    "{ scale = 0 }",
    "{ scale = [1, 1, 0] }",
    "{ scale = [-1, 1, 1] }",
    "{ rotate_deg = [1e300, 0, 0] }",
    "\"mm\"",
    "\"km\"",
    "\"path\"",
    "\"bdpt\"",
    "\"light\"",
    "\"absorber\"",
    "\"mirror\"",
    "\"dielectric\"",
    "\"conductor\"",
    "\"plastic\"",
    "\"Al\"",
    "\"BK7\"",
    "\"water\"",
    "\"LASF9\"",
    "{ sellmeier = { B = [1.0], C = [0.16] } }",
    "{ sellmeier = { B = [1e300], C = [1e-300] } }",
    "{ sellmeier = { B = [], C = [] } }",
    "\"farfield\"",
];

/// `key = value` lines to insert anywhere.
const TOML_KEYS: &[&str] = &[
    "spectrum_bins = 3",
    "spectrum_bins = 10000",
    "spectrum_bins = 1",
    "map = { resolution = [3, 2] }",
    "map = { resolution = [1024, 1024] }",
    "map = { resolution = [1, 1] }",
    "transmittance = 0.5",
    "transmittance = 1",
    "roughness = 1e-300",
    "roughness = 1",
    "roughness = 0.5",
    "roughness = [0.1, 0.3]",
    "scatter = { abg = [0.1, 0.01, 2] }",
    "scatter = { abg = [1e300, 1e-300, 8] }",
    "scatter = { abg = [1e-300, 1e300, 0] }",
    "scatter = { abg = [1e-300, 1e-300, 8] }",
    "scatter = { abg = [0.3, 0, 0] }",
    "scatter = { abg = [] }",
    "medium = \"fog\"",
    "phase = { henyey_greenstein = 0.9999999999 }",
    "metal = \"Au\"",
    "metal = \"Fe\"",
    "k = 1e300",
    "eta = 1e-300",
    "specular_reflectance = 0",
    "diffuse_reflectance = 1",
    "ior = \"SF10\"",
    "reflectance = 1",
    "reflectance = 0",
    "absorption_per_m = 1e300",
    "absorption_per_m = 1e-300",
    "outside_ior = 1e300",
    "outside_ior = 1e-300",
    "ior = 1e-300",
    "ior = 1e300",
    "power_lm = 1e-300",
    "power_lm = 1e300",
    "power_w = 0",
    "power_w = 1e300",
    "power_w = 1e-300",
    "radiance = 1e300",
    "radiance = 1e-300",
    "direction = [0, 0, 0]",
    "direction = [1e-300, 0, 0]",
    "direction = [1e300, 1e300, 0]",
    "distribution = { cosine_power = 1e300 }",
    "distribution = \"collimated\"",
    "distribution = \"isotropic\"",
    "spectrum = { blackbody_k = 1e-300 }",
    "spectrum = { blackbody_k = 1e300 }",
    "spectrum = { table = [[1, 1e308], [2, 1e308]] }",
    "integrator = \"bdpt\"",
    "integrator = \"path\"",
    "max_bounces = 0",
    "photons = 1",
    "wavelength_range_nm = [1, 1.0000001]",
    "wavelength_range_nm = [99999, 100000]",
    "wavelength_range_nm = [1, 100000]",
    "transform = { scale = -1 }",
    "transform = { scale = 1e-300 }",
    "nadir = [0, 0, 0]",
    "nadir = [0, 0, 1e-300]",
    "c0 = [0, 0, -1]",
    "c0 = [0, 0, 1]",
    "unit = \"mm\"",
    "fov_deg = 179.99999",
    "fov_deg = 1e-300",
];

/// Tables to append.
const TOML_TABLES: &[&str] = &[
    "[camera]\nposition = [0.5, 0.5, 3]\nlook_at = [0.5, 0.5, 0]\nup = [0, 1, 0]\nfov_deg = 60\nresolution = [RES]\n",
    "[camera]\nposition = [0, 0, 1e15]\nlook_at = [0, 0, 0]\nfov_deg = 1e-9\nresolution = [RES]\n",
    "[camera]\nposition = [0.5, -5, 0.5]\nlook_at = [0.5, -6, 0.5]\nup = [0, 0, 1]\nfov_deg = 179.9\nresolution = [RES]\n",
    "[[detectors]]\ntype = \"farfield\"\nname = \"ff\"\nresolution = [RES]\n",
    "[[detectors]]\ntype = \"volume\"\nname = \"vol\"\nmin = [-1e-30, 0, 0]\nmax = [1e-30, 1e15, 1]\nresolution = [3, 1, 1024]\n",
    "[[detectors]]\ntype = \"farfield\"\nname = \"ff2\"\nresolution = [2, 3]\nnadir = [1e-300, 0, 1e-300]\nc0 = [1, 1e-300, 0]\n",
    "[simulation]\nintegrator = \"bdpt\"\n",
    "[[lights]]\nname = \"p\"\nshape = { type = \"point\", position = [0.5, 0.5, 0.5] }\ndirection = [0, -1, 0]\ndistribution = { ies = \"luminaires/cosine.ies\" }\n",
    "[[lights]]\nname = \"weak\"\nshape = { type = \"point\", position = [0.5, 0.5, 0.5] }\npower_w = 1e-300\n",
    "[[lights]]\nname = \"strong\"\nshape = { type = \"point\", position = [0.5, 0.5, 0.5] }\npower_w = 1e300\n",
    "[[lights]]\nname = \"sky\"\nshape = { type = \"disk\", center = [0.5, 2, 0.5], normal = [0, -1, 0], radius = 1e-9 }\nradiance = 1\ndistribution = { cosine_power = 1e300 }\n",
    "[reference]\nsurface = \"floor\"\nincident_w = nan\n",
    "[reference]\nsurface = \"floor\"\nincident_w = 0\n",
    "[materials.m2]\ntype = \"mirror\"\nreflectance = { table = [[1, 1], [100000, 0]] }\n\n[[surfaces]]\nname = \"m2s\"\nmaterial = \"m2\"\nshape = { type = \"sphere\", center = [0.5, 0.5, 0.5], radius = 0.1, subdivisions = 1 }\nspectrum_bins = 2\n",
    "[materials.g2]\ntype = \"dielectric\"\nior = 1e300\nabsorption_per_m = 1e300\n\n[[surfaces]]\nname = \"g2s\"\nmaterial = \"g2\"\nshape = { type = \"box\", min = [0.2, 0.2, 0.2], max = [0.8, 0.8, 0.8] }\n",
    "[media.fog]\nabsorption_per_m = 1e-300\nscattering_per_m = 3\nphase = { henyey_greenstein = -0.999999 }\n\n[materials.f2]\ntype = \"dielectric\"\nior = 1.33\nmedium = \"fog\"\n\n[[surfaces]]\nname = \"f2s\"\nmaterial = \"f2\"\nshape = { type = \"sphere\", center = [0.5, 0.5, 0.5], radius = 0.3, subdivisions = 2 }\n",
    "[media.ink]\nabsorption_per_m = 1e300\nscattering_per_m = { table = [[1, 0], [100000, 50]] }\n\n[materials.f3]\ntype = \"dielectric\"\nior = 1\noutside_ior = 1\nmedium = \"ink\"\n\n[[surfaces]]\nname = \"f3s\"\nmaterial = \"f3\"\nshape = { type = \"box\", min = [0.1, 0.1, 0.1], max = [0.4, 0.4, 0.4] }\n",
    "[media.dye]\nscattering_per_m = 1e-300\nfluorescence = { absorption_per_m = { table = [[1, 1e300], [600, 0]] }, emission = { table = [[599, 0], [600, 1e300], [601, 0]] }, quantum_yield = 1 }\n\n[materials.f4]\ntype = \"dielectric\"\nior = 1.5\nmedium = \"dye\"\n\n[[surfaces]]\nname = \"f4s\"\nmaterial = \"f4\"\nshape = { type = \"box\", min = [0.6, 0.6, 0.6], max = [0.9, 0.9, 0.9] }\n",
    "[[surfaces]]\nname = \"tiny\"\nmaterial = \"absorber\"\nshape = { type = \"quad\", corners = [[0, 0, 0], [1e-12, 0, 0], [1e-12, 1e-12, 0], [0, 1e-12, 0]] }\nmap = { resolution = [2, 2] }\n",
];

const RESOLUTIONS: &[&str] = &[
    "4294967296, 4294967296",
    "8589934592, 2147483648",
    "4611686018427387904, 4",
    "1, 1",
    "3, 2",
    "0, 5",
    "1024, 1024",
    "7, 1",
];

fn long_name(f: &mut Fuzz) -> String {
    let unit = f.pick(&["a", "é", "/", "../", "漢", " ", "\\\\", "\\u0000", ",", "\\\""]);
    unit.repeat(1 + f.below(300))
}

/// Byte spans of number-looking tokens (not inside identifiers).
fn number_spans(text: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < text.len() {
        let c = text[i];
        let prev_ident = i > 0 && (text[i - 1].is_ascii_alphanumeric() || text[i - 1] == b'_' || text[i - 1] == b'.');
        let starts = c.is_ascii_digit()
            || ((c == b'-' || c == b'+' || c == b'.') && text.get(i + 1).is_some_and(|d| d.is_ascii_digit()));
        if starts && !prev_ident {
            let s = i;
            i += 1;
            while i < text.len() {
                let d = text[i];
                let ok = d.is_ascii_digit()
                    || d == b'.'
                    || d == b'_'
                    || d == b'e'
                    || d == b'E'
                    || ((d == b'-' || d == b'+') && matches!(text[i - 1], b'e' | b'E'));
                if !ok {
                    break;
                }
                i += 1;
            }
            out.push((s, i));
        } else {
            i += 1;
        }
    }
    out
}

fn excerpt(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(bytes);
    if s.len() <= EXCERPT {
        s.into_owned()
    } else {
        let mut end = EXCERPT;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        format!("{}\n[... {} more bytes]", &s[..end], s.len() - end)
    }
}

fn one_line(s: &[u8]) -> String {
    let t = String::from_utf8_lossy(s).replace('\n', "\\n");
    if t.chars().count() > 120 {
        format!("{}…", t.chars().take(120).collect::<String>())
    } else {
        t
    }
}

/// Replaces one number token with `pool[..]`; returns a description.
fn mutate_number(f: &mut Fuzz, text: &mut Vec<u8>, pool: &[&str], restrict: Option<(usize, usize)>) -> Option<String> {
    let mut spans = number_spans(text);
    if let Some((lo, hi)) = restrict {
        let inside: Vec<_> = spans.iter().copied().filter(|&(s, _)| s >= lo && s < hi).collect();
        if !inside.is_empty() {
            spans = inside;
        }
    }
    if spans.is_empty() {
        return None;
    }
    let (s, e) = spans[f.below(spans.len())];
    let old = String::from_utf8_lossy(&text[s..e]).into_owned();
    let new = match f.below(5) {
        0 => format!("-{old}"),
        1 => format!("{old}0000000000"),
        _ => f.pick(pool).to_string(),
    };
    let line = text[..s].iter().filter(|&&b| b == b'\n').count() + 1;
    text.splice(s..e, new.bytes());
    Some(format!("line {line}: number `{old}` -> `{new}`"))
}

fn lines_of(text: &[u8]) -> Vec<Vec<u8>> {
    text.split(|&b| b == b'\n').map(|l| l.to_vec()).collect()
}

fn join_lines(lines: &[Vec<u8>]) -> Vec<u8> {
    lines.join(&b'\n')
}

/// Byte-level mutation: flip, insert, delete, duplicate, splice from another file.
fn mutate_bytes(f: &mut Fuzz, text: &mut Vec<u8>, donor: &[u8]) -> String {
    let n = text.len();
    match f.below(6) {
        0 if n > 0 => {
            let i = f.below(n);
            let bit = 1u8 << f.below(8);
            let old = text[i];
            text[i] ^= bit;
            format!("byte {i}: flip {old:#04x} -> {:#04x}", text[i])
        }
        1 => {
            let i = f.below(n + 1);
            let ins = f.pick(&[
                "\n", "\0", "=", "[", "]", "\"", "#", ",", "{", "}", "-", ".", "e", "9", " ", "\u{feff}", "\r", "/",
                "\\",
            ]);
            text.splice(i..i, ins.bytes());
            format!("byte {i}: insert {ins:?}")
        }
        2 if n > 0 => {
            let i = f.below(n);
            let len = 1 + f.below(16.min(n - i));
            let old = one_line(&text[i..i + len]);
            text.drain(i..i + len);
            format!("byte {i}: delete {len} bytes `{old}`")
        }
        3 if n > 0 => {
            let i = f.below(n);
            let len = 1 + f.below(64.min(n - i));
            let chunk = text[i..i + len].to_vec();
            let at = f.below(n + 1);
            text.splice(at..at, chunk.iter().copied());
            format!("byte {at}: insert copy of bytes {i}..{} `{}`", i + len, one_line(&chunk))
        }
        4 if !donor.is_empty() => {
            let i = f.below(donor.len());
            let len = 1 + f.below(80.min(donor.len() - i));
            let chunk = donor[i..i + len].to_vec();
            let at = f.below(n + 1);
            let cut = f.below(32.min(n - at) + 1);
            text.splice(at..at + cut, chunk.iter().copied());
            format!("byte {at}: replace {cut} bytes by donor bytes `{}`", one_line(&chunk))
        }
        _ => {
            // truncate
            let at = f.below(n + 1);
            text.truncate(at);
            format!("truncate at byte {at}")
        }
    }
}

/// Line-level mutation of any text file: delete, duplicate, swap lines, or a number.
fn mutate_lines(f: &mut Fuzz, text: &mut Vec<u8>, pool: &[&str]) -> Option<String> {
    let mut lines = lines_of(text);
    let n = lines.len();
    let d = match f.below(4) {
        0 if n > 1 => {
            let i = f.below(n);
            let old = lines.remove(i);
            format!("delete line {}: `{}`", i + 1, one_line(&old))
        }
        1 if n > 0 => {
            let i = f.below(n);
            let l = lines[i].clone();
            let at = f.below(n + 1);
            lines.insert(at, l.clone());
            format!("copy line {} `{}` before line {}", i + 1, one_line(&l), at + 1)
        }
        2 if n > 1 => {
            let (i, j) = (f.below(n), f.below(n));
            lines.swap(i, j);
            format!("swap lines {} and {}", i + 1, j + 1)
        }
        _ => return mutate_number(f, text, pool, None),
    };
    *text = join_lines(&lines);
    Some(d)
}

/// `key = value` lines: (line index, byte offset of the value in the line).
fn assignments(lines: &[Vec<u8>]) -> Vec<(usize, usize)> {
    lines
        .iter()
        .enumerate()
        .filter_map(|(i, l)| {
            let s = String::from_utf8_lossy(l);
            let t = s.trim_start();
            if t.starts_with('#') || t.starts_with('[') {
                return None;
            }
            s.find(" = ").map(|p| (i, p + 3))
        })
        .collect()
}

/// Structural TOML mutation; None when it found nothing to change.
fn mutate_toml(f: &mut Fuzz, text: &mut Vec<u8>) -> Option<String> {
    let mut lines = lines_of(text);
    let assigns = assignments(&lines);
    let kind = f.below(100);
    let d = if kind < 30 {
        return mutate_number(f, text, TOML_NUMBERS, None);
    } else if kind < 45 {
        // replace a whole value
        let &(i, at) = assigns.get(f.below(assigns.len()))?;
        let mut v = f.pick(TOML_VALUES).to_string();
        if v.contains("RES") {
            v = v.replace("RES", f.pick(RESOLUTIONS));
        }
        let old = one_line(&lines[i]);
        lines[i].truncate(at);
        lines[i].extend_from_slice(v.as_bytes());
        format!("line {}: `{old}` -> `{}`", i + 1, one_line(&lines[i]))
    } else if kind < 52 {
        // resolution-targeted (cameras, maps, detectors)
        let res: Vec<usize> = assigns
            .iter()
            .filter(|(i, _)| String::from_utf8_lossy(&lines[*i]).contains("resolution"))
            .map(|x| x.0)
            .collect();
        if res.is_empty() {
            let t = TOML_TABLES[0].replace("RES", f.pick(RESOLUTIONS));
            lines.push(Vec::new());
            lines.extend(lines_of(t.as_bytes()));
            format!("append `{}`", one_line(t.as_bytes()))
        } else {
            let i = res[f.below(res.len())];
            let old = one_line(&lines[i]);
            let s = String::from_utf8_lossy(&lines[i]).into_owned();
            let p = s.find("resolution").unwrap();
            let new =
                format!("{}resolution = [{}]{}", &s[..p], f.pick(RESOLUTIONS), if s.contains('{') { " }" } else { "" });
            lines[i] = new.into_bytes();
            format!("line {}: `{old}` -> `{}`", i + 1, one_line(&lines[i]))
        }
    } else if kind < 58 {
        // rename
        let names: Vec<usize> = assigns
            .iter()
            .filter(|(i, _)| String::from_utf8_lossy(&lines[*i]).trim_start().starts_with("name ="))
            .map(|x| x.0)
            .collect();
        let i = *names.get(f.below(names.len()))?;
        let old = one_line(&lines[i]);
        let new = if f.chance(0.3) {
            // another entry's name (duplicates)
            let j = names[f.below(names.len())];
            String::from_utf8_lossy(&lines[j]).into_owned()
        } else {
            format!("name = \"{}\"", long_name(f))
        };
        lines[i] = new.into_bytes();
        format!("line {}: `{old}` -> `{}`", i + 1, one_line(&lines[i]))
    } else if kind < 68 {
        // insert a key line
        let k = f.pick(TOML_KEYS);
        let at = f.below(lines.len() + 1);
        lines.insert(at, k.as_bytes().to_vec());
        format!("insert `{k}` before line {}", at + 1)
    } else if kind < 76 {
        // append a table
        let t = f.pick(TOML_TABLES).replace("RES", f.pick(RESOLUTIONS));
        lines.push(Vec::new());
        lines.extend(lines_of(t.as_bytes()));
        format!("append `{}`", one_line(t.as_bytes()))
    } else if kind < 82 {
        // delete a key line
        let &(i, _) = assigns.get(f.below(assigns.len()))?;
        let old = lines.remove(i);
        format!("delete line {}: `{}`", i + 1, one_line(&old))
    } else if kind < 87 {
        // swap the values of two key lines
        if assigns.len() < 2 {
            return None;
        }
        let (a, b) = (assigns[f.below(assigns.len())], assigns[f.below(assigns.len())]);
        let va = lines[a.0][a.1..].to_vec();
        let vb = lines[b.0][b.1..].to_vec();
        lines[a.0].truncate(a.1);
        lines[a.0].extend_from_slice(&vb);
        lines[b.0].truncate(b.1);
        lines[b.0].extend_from_slice(&va);
        format!(
            "swap values of lines {} and {}: now `{}` / `{}`",
            a.0 + 1,
            b.0 + 1,
            one_line(&lines[a.0]),
            one_line(&lines[b.0])
        )
    } else if kind < 93 {
        // duplicate or delete a table (header to the next header)
        let heads: Vec<usize> = (0..lines.len()).filter(|&i| lines[i].first() == Some(&b'[')).collect();
        let k = f.below(heads.len());
        let s = *heads.get(k)?;
        let e = heads.get(k + 1).copied().unwrap_or(lines.len());
        let block: Vec<Vec<u8>> = lines[s..e].to_vec();
        let head = one_line(&lines[s]);
        if f.chance(0.5) {
            lines.drain(s..e);
            format!("delete table `{head}` (lines {}..{})", s + 1, e)
        } else {
            lines.push(Vec::new());
            lines.extend(block);
            format!("duplicate table `{head}` (lines {}..{}) at the end", s + 1, e)
        }
    } else {
        // change a string enum value
        let strs: Vec<(usize, usize)> =
            assigns.iter().copied().filter(|&(i, at)| lines[i].get(at) == Some(&b'"')).collect();
        let &(i, at) = strs.get(f.below(strs.len()))?;
        let old = one_line(&lines[i]);
        let v = f.pick(&[
            "\"quad\"",
            "\"disk\"",
            "\"sphere\"",
            "\"box\"",
            "\"mesh\"",
            "\"point\"",
            "\"mirror\"",
            "\"dielectric\"",
            "\"absorber\"",
            "\"lambertian\"",
            "\"bdpt\"",
            "\"path\"",
            "\"absorber\"",
            "\"white\"",
            "\"floor\"",
        ]);
        lines[i].truncate(at);
        lines[i].extend_from_slice(v.as_bytes());
        format!("line {}: `{old}` -> `{}`", i + 1, one_line(&lines[i]))
    };
    *text = join_lines(&lines);
    Some(d)
}

/// Numbers for OBJ, CSV and IES files.
const TEXT_NUMBERS: &[&str] = &[
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e309",
    "1e308",
    "-1e308",
    "0",
    "-0",
    "-1",
    "1e-300",
    "5e-324",
    "4294967296",
    "8589934592",
    "18446744073709551615",
    "99999999999",
    "1e18",
    "10000",
    "10001",
    "3",
    "2",
    "1",
    "",
    "--1",
    "0x10",
    "1,2",
    "9999",
    "-2147483648",
    "1e-9",
];

/// Mutates the case; returns the log of what was done.
fn mutate(f: &mut Fuzz, input: &mut Input, donors: &[Vec<u8>]) -> Vec<String> {
    let mut log = Vec::new();
    let rounds = match f.below(10) {
        0..=4 => 1,
        5..=7 => 2,
        _ => 3 + f.below(2),
    };
    let aux: Vec<String> = input.files.keys().filter(|k| **k != input.scene).cloned().collect();
    for _ in 0..rounds {
        let donor = &donors[f.below(donors.len())];
        let r = f.below(100);
        if r < 62 {
            let text = input.files.get_mut(&input.scene).unwrap();
            if let Some(d) = mutate_toml(f, text) {
                log.push(format!("{}: {d}", input.scene));
            }
        } else if r < 72 {
            let text = input.files.get_mut(&input.scene).unwrap();
            let d = mutate_bytes(f, text, donor);
            log.push(format!("{}: {d}", input.scene));
        } else {
            // an auxiliary file the scene names (else any)
            let scene_text = String::from_utf8_lossy(&input.files[&input.scene]).into_owned();
            let named: Vec<&String> = aux
                .iter()
                .filter(|a| scene_text.contains(Path::new(a.as_str()).file_name().unwrap().to_str().unwrap()))
                .collect();
            let file =
                if named.is_empty() { aux[f.below(aux.len())].clone() } else { named[f.below(named.len())].clone() };
            let text = input.files.get_mut(&file).unwrap();
            let d = if f.chance(0.3) {
                Some(mutate_bytes(f, text, donor))
            } else if file.ends_with(".ies") && f.chance(0.5) {
                // the two count lines after TILT=
                let s = String::from_utf8_lossy(text).into_owned();
                let restrict = s.find("TILT").map(|p| {
                    let after = p + s[p..].find('\n').unwrap_or(0);
                    let mut end = after + 1;
                    for _ in 0..2 {
                        end += s.get(end..).and_then(|x| x.find('\n')).map_or(0, |k| k + 1);
                    }
                    (after, end)
                });
                mutate_number(f, text, TEXT_NUMBERS, restrict)
            } else if file.ends_with(".obj") && f.chance(0.4) {
                let l = f.pick(&[
                    "f 1 1 1",
                    "f -100 2 3",
                    "f 1/99 2 3",
                    "f 0 1 2",
                    "f 1 2",
                    "vt nan 0",
                    "v 1e308 1e308 1e308",
                    "v 1e-300 0 0",
                    "f 9223372036854775807 1 2",
                    "f -9223372036854775808 1 2",
                    "f 1/1 2 3",
                    "f 1 2 3 4 5 6 7 8",
                ]);
                let mut lines = lines_of(text);
                let at = f.below(lines.len() + 1);
                lines.insert(at, l.as_bytes().to_vec());
                *text = join_lines(&lines);
                Some(format!("insert `{l}` before line {}", at + 1))
            } else if file.ends_with(".csv") && f.chance(0.3) {
                let l =
                    f.pick(&["500,nan", "1e308,1", "0,1", "500,1e308", "600,-0", "1e-300,0", "500", ",", "5e2,1,2"]);
                let mut lines = lines_of(text);
                let at = f.below(lines.len() + 1);
                lines.insert(at, l.as_bytes().to_vec());
                *text = join_lines(&lines);
                Some(format!("insert `{l}` before line {}", at + 1))
            } else {
                mutate_lines(f, text, TEXT_NUMBERS)
            };
            if let Some(d) = d {
                log.push(format!("{file}: {d}"));
            }
        }
    }
    log
}

// ------------------------------------------------------------------------------ checks

#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
enum Class {
    Panic,
    NonFinite,
    LateFailure,
    BadMessage,
    Accepted,
}

impl Class {
    fn name(self) -> &'static str {
        match self {
            Class::Panic => "panic",
            Class::NonFinite => "non-finite output",
            Class::LateFailure => "failure after the simulation",
            Class::BadMessage => "bad message",
            Class::Accepted => "accepted at load",
        }
    }
}

struct Finding {
    class: Class,
    /// What failed, for grouping (panic location, output name, message problem).
    signature: String,
    detail: String,
}

#[derive(Default)]
struct Stats {
    cases: usize,
    load_errors: usize,
    ran: usize,
    skipped_large: usize,
    slow: Vec<(usize, f64)>,
    load_s: f64,
    run_s: f64,
    output_s: f64,
}

/// JSON paths holding null (a NaN or infinity serialized by serde_json).
fn nulls(v: &serde_json::Value, path: &str, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Null => out.push(path.to_string()),
        serde_json::Value::Array(a) => a.iter().enumerate().for_each(|(i, x)| nulls(x, &format!("{path}[{i}]"), out)),
        serde_json::Value::Object(o) => o.iter().for_each(|(k, x)| nulls(x, &format!("{path}.{k}"), out)),
        _ => {}
    }
}

/// Non-finite fields of a written CSV: (line, column name, text).
fn csv_nonfinite(text: &str) -> Vec<String> {
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let mut out = Vec::new();
    for (i, l) in lines.enumerate() {
        for (j, c) in l.split(',').enumerate() {
            // Only fields that read as numbers (a surface name may say "info").
            if c.trim().parse::<f64>().is_ok_and(|x| !x.is_finite()) {
                out.push(format!("line {} `{}` = {c}", i + 2, head.get(j).unwrap_or(&"?")));
            }
        }
    }
    out
}

fn first_few(v: &[String]) -> String {
    let mut s = v.iter().take(4).cloned().collect::<Vec<_>>().join("; ");
    if v.len() > 4 {
        let _ = write!(s, "; … ({} in all)", v.len());
    }
    s
}

/// Writes the outputs as `photon run` does (staged, checked, committed) and checks every number
/// written. A refusal (exit 2: the scene's magnitudes leave no finite answer) writes nothing
/// and is no finding; any other failure after the simulation is one.
fn check_outputs(scene: &Scene, result: &photon::run::RunResult, out_dir: &Path, findings: &mut Vec<Finding>) {
    fn push_nonfinite(findings: &mut Vec<Finding>, what: &str, bad: Vec<String>) {
        if !bad.is_empty() {
            findings.push(Finding {
                class: Class::NonFinite,
                signature: format!("non-finite {what}"),
                detail: format!("{what}: {}", first_few(&bad)),
            });
        }
    }
    let late = |what: &str, e: &Error| Finding {
        class: Class::LateFailure,
        signature: format!("{what} fails"),
        detail: format!("{what}: {e}"),
    };
    let names = photon::output::run_file_names(scene, result.film.is_some(), false);
    let staged = match photon::output::OutputDir::prepare(out_dir, &names) {
        Ok(s) => s,
        Err(e) => return findings.push(late("preparing the output folder", &e)),
    };
    match photon::output::write_run(staged.path(), scene, result) {
        Ok(_) => {}
        Err(Error::Usage(_) | Error::Input(_)) => return,
        Err(e) => return findings.push(late("writing the outputs", &e)),
    }
    if let Err(e) = staged.commit(&photon::output::previous_run_files(out_dir)) {
        return findings.push(late("committing the outputs", &e));
    }
    // What was written, read back.
    let mut written = Vec::new();
    collect_files(out_dir, &mut written);
    for p in written {
        let name = p.strip_prefix(out_dir).unwrap_or(&p).to_string_lossy().into_owned();
        if name.ends_with(".json") {
            let mut bad = Vec::new();
            match serde_json::from_slice::<serde_json::Value>(&std::fs::read(&p).unwrap_or_default()) {
                Ok(v) => nulls(&v, &name, &mut bad),
                Err(e) => bad.push(format!("unreadable: {e}")),
            }
            push_nonfinite(findings, &name, bad);
        } else if name.ends_with(".csv") {
            let text = std::fs::read_to_string(&p).unwrap_or_default();
            push_nonfinite(findings, &name, csv_nonfinite(&text));
        }
    }
    // The f32 images as they were encoded (write_run checked them; check it did).
    if let Some(film) = &result.film {
        let image = film.image(result.emitted_w);
        let all = image.xyz.iter().chain(image.rgb.iter()).chain(image.y_var.iter());
        let n = all.filter(|x| !x.is_finite()).count();
        push_nonfinite(findings, "image.exr", if n > 0 { vec![format!("{n} non-finite values")] } else { vec![] });
    }
    for m in photon::output::maps::estimates(scene, result) {
        let fits = |xs: Vec<(f64, f64)>| xs.iter().all(|x| (x.0 as f32).is_finite() && (x.1 as f32).is_finite());
        if !(fits(m.irradiance_w_m2()) && fits(m.illuminance_lx())) {
            push_nonfinite(findings, "maps/*.exr", vec![format!("map {}", m.surface)]);
        }
    }
}

fn collect_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            collect_files(&p, out);
        } else {
            out.push(p);
        }
    }
}

/// Checks an error message: non-empty, naming a file of the case, with a line the file has.
fn check_error(e: &Error, case_dir: &Path, files: &BTreeMap<String, Vec<u8>>, scene_rel: &str) -> Option<Finding> {
    let text = e.to_string();
    let bad = |sig: &str, why: String| {
        Some(Finding {
            class: Class::BadMessage,
            signature: sig.to_string(),
            detail: format!("{why}; message: {text}"),
        })
    };
    let Error::Input(ie) = e else {
        return bad("not an input error", format!("load_str returned {:?}", std::mem::discriminant(e)));
    };
    if ie.message.trim().is_empty() {
        return bad("empty message", "the message is empty".into());
    }
    let Ok(rel) = ie.file.strip_prefix(case_dir) else {
        // A file outside the case is fine when the scene named it so (`file = "/"`).
        let named = files.values().any(|b| String::from_utf8_lossy(b).contains(&*ie.file.to_string_lossy()));
        if named && text.contains(&case_dir.join(scene_rel).display().to_string()) {
            return None;
        }
        return bad("names no file of the case", format!("names {}", ie.file.display()));
    };
    if !text.contains(&case_dir.join(scene_rel).display().to_string()) && !text.contains(&ie.file.display().to_string())
    {
        return bad("file not in the text", "the text does not name the file".into());
    }
    let rel = rel.to_string_lossy().replace('\\', "/");
    if let (Some(line), Some(bytes)) = (ie.line, files.get(&rel)) {
        let lines = String::from_utf8_lossy(bytes).lines().count().max(1);
        if line == 0 || line > lines {
            return bad("line beyond the file", format!("line {line} of {rel}, which has {lines} lines"));
        }
    }
    // A missing top-level table (`lights`) has no line to name; anything deeper has one.
    if rel == scene_rel && ie.line.is_none() && ie.key.contains(['.', '[']) {
        return bad(
            &format!("scene error without a line (key {})", ie.key),
            "an error in the scene file gives no line".into(),
        );
    }
    None
}

fn write_case(dir: &Path, input: &Input) {
    let _ = std::fs::remove_dir_all(dir);
    // Only the files the scene names (by file name), to keep the case cheap.
    let scene = String::from_utf8_lossy(&input.files[&input.scene]).into_owned();
    let named =
        |rel: &str| *rel == input.scene || scene.contains(Path::new(rel).file_name().unwrap().to_str().unwrap());
    for (rel, bytes) in input.files.iter().filter(|(rel, _)| named(rel)) {
        let p = dir.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, bytes).unwrap();
    }
}

/// Runs one case; returns its findings.
fn run_case(index: usize, input: &Input, dir: &Path, f: &mut Fuzz, stats: &mut Stats) -> Vec<Finding> {
    let mut findings = Vec::new();
    write_case(dir, input);
    let scene_path = dir.join(&input.scene);
    let text = String::from_utf8_lossy(&input.files[&input.scene]).into_owned();
    take_panics();
    let t0 = Instant::now();
    let loaded = catch_unwind(AssertUnwindSafe(|| photon::scene::load_str(&scene_path, &text)));
    stats.load_s += t0.elapsed().as_secs_f64();
    let mut scene = match loaded {
        Err(p) => {
            let where_ = take_panics().pop().unwrap_or_else(|| payload_text(&*p));
            findings.push(Finding {
                class: Class::Panic,
                signature: format!("load_str panics: {where_}"),
                detail: where_,
            });
            return findings;
        }
        Ok(Err(e)) => {
            stats.load_errors += 1;
            findings.extend(check_error(&e, dir, &input.files, &input.scene));
            return findings;
        }
        Ok(Ok(s)) => s,
    };
    if let Some(c) = &scene.camera {
        let [w, h] = c.resolution;
        if w == 0 || h == 0 {
            let raw = text.lines().filter(|l| l.contains("resolution")).map(str::trim).collect::<Vec<_>>().join(" | ");
            findings.push(Finding {
                class: Class::Accepted,
                signature: "camera resolution overflow accepted".into(),
                detail: format!("the loader accepted a camera of {w}×{h} pixels from `{raw}`"),
            });
            return findings;
        }
        if w as u64 * h as u64 > MAX_RUN_PIXELS {
            stats.skipped_large += 1;
            return findings;
        }
    }
    if scene.geometry.len() > MAX_RUN_TRIANGLES
        || scene.map_texels() > MAX_RUN_BINS
        || scene.farfield_bins() > MAX_RUN_BINS
    {
        stats.skipped_large += 1;
        return findings;
    }
    let estimator = if f.chance(0.05) { Estimator::Auto } else { *f.pick(&[&Estimator::Expected, &Estimator::Analog]) };
    let opts = RunOptions {
        photons: Some(*f.pick(&[&1u64, &2, &1500, &3000, &4000])),
        seed: Some(f.rng.next_u64() % 1000),
        threads: Some(1),
        max_bounces: Some(*f.pick(&[&0u32, &1, &64, &64])),
        no_image: f.chance(0.1),
        integrator: if f.chance(0.2) {
            Some(*f.pick(&[&Integrator::Light, &Integrator::Path, &Integrator::Bdpt]))
        } else {
            None
        },
        transport: TransportOptions { estimator, stratified: f.chance(0.2), hero: f.chance(0.7) },
        ..Default::default()
    };
    let describe_opts = format!(
        "photons {:?}, seed {:?}, max_bounces {:?}, no_image {}, integrator {:?}, {:?}",
        opts.photons, opts.seed, opts.max_bounces, opts.no_image, opts.integrator, opts.transport
    );
    let t0 = Instant::now();
    let ran = catch_unwind(AssertUnwindSafe(|| {
        let chosen = apply_options(&mut scene, &opts)?;
        simulate(&scene, &opts, &chosen, &AtomicBool::new(false))
    }));
    stats.ran += 1;
    stats.run_s += t0.elapsed().as_secs_f64();
    let result = match ran {
        Err(p) => {
            let where_ = take_panics().pop().unwrap_or_else(|| payload_text(&*p));
            findings.push(Finding {
                class: Class::Panic,
                signature: format!("simulate panics: {where_}"),
                detail: format!("{where_} ({describe_opts})"),
            });
            return findings;
        }
        Ok(Err(e)) => {
            let panics = take_panics();
            let msg = e.to_string();
            if msg.contains("failed") || !panics.is_empty() {
                let where_ = panics.last().cloned().unwrap_or(msg.clone());
                findings.push(Finding {
                    class: Class::Panic,
                    signature: format!("batch panics: {where_}"),
                    detail: format!("simulate: {msg}; panic: {where_} ({describe_opts})"),
                });
            } else {
                findings.push(Finding {
                    class: Class::LateFailure,
                    signature: format!("simulate fails: {msg}"),
                    detail: format!("{msg} ({describe_opts})"),
                });
            }
            return findings;
        }
        Ok(Ok(r)) => r,
    };
    let out_dir = dir.join("out");
    let t0 = Instant::now();
    let checked = catch_unwind(AssertUnwindSafe(|| {
        let mut v = Vec::new();
        check_outputs(&scene, &result, &out_dir, &mut v);
        v
    }));
    stats.output_s += t0.elapsed().as_secs_f64();
    match checked {
        Ok(v) => findings.extend(v.into_iter().map(|mut x| {
            x.detail = format!("{} ({describe_opts})", x.detail);
            x
        })),
        Err(p) => {
            let where_ = take_panics().pop().unwrap_or_else(|| payload_text(&*p));
            findings.push(Finding {
                class: Class::Panic,
                signature: format!("output panics: {where_}"),
                detail: format!("{where_} ({describe_opts})"),
            });
        }
    }
    let _ = index;
    findings
}

/// Lines of `new` that are not in `old`: the mutation's footprint.
fn changed_lines(old: &[u8], new: &[u8]) -> String {
    let old = String::from_utf8_lossy(old);
    let olds: std::collections::HashSet<&str> = old.lines().collect();
    let new = String::from_utf8_lossy(new);
    let mut out = String::new();
    for (i, l) in new.lines().enumerate() {
        if !olds.contains(l) {
            let _ = writeln!(out, "      +{:>4}| {}", i + 1, one_line(l.as_bytes()));
        }
    }
    if out.len() > EXCERPT {
        out.truncate(EXCERPT);
        out.push_str("      [...]\n");
    }
    out
}

#[test]
fn fuzz_scene_loader_and_run() {
    install_panic_hook();
    let cases = env_u64("PHOTON_FUZZ_CASES").map_or(DEFAULT_CASES, |n| n as usize);
    let seed = env_u64("PHOTON_FUZZ_SEED").unwrap_or(DEFAULT_SEED);
    let only = env_u64("PHOTON_FUZZ_ONLY").map(|n| n as usize);
    let keep = std::env::var("PHOTON_FUZZ_KEEP").is_ok();
    let seeds = seeds();
    let donors: Vec<Vec<u8>> = seeds.iter().flat_map(|s| s.files.values().cloned()).collect();
    let base_dir = std::env::temp_dir().join(format!("photon-fuzz-{}", std::process::id()));
    let start = Instant::now();
    let mut stats = Stats::default();
    // signature -> (class, count, first report)
    let mut groups: BTreeMap<(Class, String), (usize, String)> = BTreeMap::new();
    let mut failing_cases = 0;
    QUIET.with(|q| q.set(true));
    for index in 0..cases {
        if only.is_some_and(|o| o != index) {
            continue;
        }
        // Each case has its own stream, from (seed, index) alone.
        let mut f =
            Fuzz { rng: Xoshiro256PlusPlus::seed_from_u64(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)) };
        let k = f.below(seeds.len());
        let mut input = seeds[k].clone();
        // A tenth of the cases run a seed unchanged.
        let log = if index < seeds.len() { Vec::new() } else { mutate(&mut f, &mut input, &donors) };
        let dir = base_dir.join(format!("case{index}"));
        let t0 = Instant::now();
        let findings = run_case(index, &input, &dir, &mut f, &mut stats);
        let dt = t0.elapsed().as_secs_f64();
        stats.cases += 1;
        if dt > 2.0 {
            stats.slow.push((index, dt));
        }
        if only.is_some() {
            println!("case {index} from {} ({:.3} s)\nmutations: {log:#?}", seeds[k].label, dt);
            for (rel, bytes) in &input.files {
                if seeds[k].files.get(rel) != Some(bytes) || *rel == input.scene {
                    println!("--- {rel}\n{}", String::from_utf8_lossy(bytes));
                }
            }
        }
        if !findings.is_empty() {
            failing_cases += 1;
        }
        for fi in findings {
            let entry = groups.entry((fi.class, fi.signature.clone())).or_insert((0, String::new()));
            entry.0 += 1;
            if entry.1.is_empty() {
                let mut r = format!(
                    "    case {index} (PHOTON_FUZZ_SEED={seed} PHOTON_FUZZ_ONLY={index}), from {}\n",
                    seeds[k].label
                );
                let _ = writeln!(r, "    what: {}", fi.detail);
                for m in &log {
                    let _ = writeln!(r, "    mutation: {m}");
                }
                for (rel, bytes) in &input.files {
                    if let Some(orig) = seeds[k].files.get(rel).filter(|o| *o != bytes) {
                        let _ = writeln!(r, "    {rel}, changed lines:\n{}", changed_lines(orig, bytes));
                    }
                }
                if log.is_empty() {
                    let _ = writeln!(r, "    input (unmutated):\n{}", excerpt(&input.files[&input.scene]));
                }
                entry.1 = r;
            }
        }
        if !keep {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
    QUIET.with(|q| q.set(false));
    if !keep {
        let _ = std::fs::remove_dir_all(&base_dir);
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "fuzz: {} cases in {secs:.1} s (seed {seed}): {} refused at load, {} ran, {} skipped: too large, {} slow (> 2 s): {:?}",
        stats.cases,
        stats.load_errors,
        stats.ran,
        stats.skipped_large,
        stats.slow.len(),
        stats.slow
    );
    println!("fuzz: seconds in load {:.1}, simulate {:.1}, outputs {:.1}", stats.load_s, stats.run_s, stats.output_s);
    if groups.is_empty() {
        return;
    }
    let mut report = String::new();
    for ((class, sig), (count, first)) in &groups {
        let _ = writeln!(report, "[{}] {sig} — {count} finding(s); first:\n{first}", class.name());
    }
    panic!("fuzz: {failing_cases} of {} cases failed, {} distinct failures:\n\n{report}", stats.cases, groups.len());
}

// ------------------------------------------------------------------------------ command line

#[test]
fn fuzz_command_line() {
    let r = root();
    let dir = std::env::temp_dir().join(format!("photon-fuzz-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let base = dir.join("base.toml");
    std::fs::write(&base, HAND_SCENES[0].1).unwrap();
    let overflow = dir.join("overflow.toml");
    std::fs::write(
        &overflow,
        format!("{}\n{}", HAND_SCENES[0].1, TOML_TABLES[0].replace("RES", "4294967296, 4294967296")),
    )
    .unwrap();
    let scene = |s: &str| r.join("scenes").join(s).display().to_string();
    let base = base.display().to_string();
    let overflow = overflow.display().to_string();
    let cases: Vec<Vec<String>> = vec![
        vec!["converge".into(), scene("luminaire.toml"), "--budget".into(), "1".into()],
        vec![
            "converge".into(),
            scene("parallel_plates.toml"),
            "--budget".into(),
            "0.3".into(),
            "--reference".into(),
            "nan".into(),
        ],
        vec![
            "converge".into(),
            scene("parallel_plates.toml"),
            "--budget".into(),
            "0.3".into(),
            "--reference".into(),
            "0".into(),
        ],
        vec!["converge".into(), base.clone(), "--budget".into(), "1e-9".into()],
        vec!["run".into(), base.clone(), "--photons".into(), "1".into(), "--quiet".into()],
        vec![
            "run".into(),
            base.clone(),
            "--photons".into(),
            "2000".into(),
            "--time".into(),
            "1e-300".into(),
            "--quiet".into(),
        ],
        vec![
            "run".into(),
            base.clone(),
            "--photons".into(),
            "2000".into(),
            "--rel-error".into(),
            "1e308".into(),
            "--quiet".into(),
        ],
        vec!["run".into(), base.clone(), "--photons".into(), "18446744073709551616".into()],
        vec!["run".into(), base.clone(), "--threads".into(), "18446744073709551615".into()],
        vec![
            "run".into(),
            base.clone(),
            "--seed".into(),
            "18446744073709551615".into(),
            "--photons".into(),
            "100".into(),
            "--quiet".into(),
        ],
        vec![
            "run".into(),
            base.clone(),
            "--max-bounces".into(),
            "4294967295".into(),
            "--photons".into(),
            "100".into(),
            "--quiet".into(),
        ],
        vec!["info".into(), overflow.clone()],
        vec!["run".into(), overflow, "--photons".into(), "100".into(), "--quiet".into()],
    ];
    let mut failures = Vec::new();
    for (k, args) in cases.iter().enumerate() {
        let out_dir = dir.join(format!("out{k}"));
        let mut a = args.clone();
        if a[0] != "info" {
            a.extend(["--out".into(), out_dir.display().to_string()]);
        }
        let t0 = Instant::now();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_photon"))
            .args(&a)
            .current_dir(&dir)
            .env("RUST_BACKTRACE", "0")
            .output()
            .expect("cannot start photon");
        let stderr = String::from_utf8_lossy(&out.stderr);
        let code = out.status.code();
        let shown = format!("photon {}", a.join(" "));
        let tail: String = stderr.lines().take(3).collect::<Vec<_>>().join(" | ");
        if !matches!(code, Some(0..=2)) || stderr.contains("panicked") {
            failures.push(format!("[panic] `{shown}`: exit {code:?}, stderr: {tail}"));
        } else if code == Some(0) {
            let mut bad = Vec::new();
            for e in std::fs::read_dir(&out_dir).into_iter().flatten().flatten() {
                let p = e.path();
                let name = p.file_name().unwrap().to_string_lossy().into_owned();
                let text = std::fs::read_to_string(&p).unwrap_or_default();
                if name.ends_with(".csv") {
                    bad.extend(csv_nonfinite(&text).into_iter().map(|s| format!("{name} {s}")));
                } else if name.ends_with(".json") {
                    let mut n = Vec::new();
                    if let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) {
                        nulls(&v, &name, &mut n);
                    }
                    bad.extend(n);
                }
            }
            if !bad.is_empty() {
                failures.push(format!("[non-finite output] `{shown}` exit 0: {}", first_few(&bad)));
            }
            if args[0] == "info" && args[1].ends_with("overflow.toml") {
                failures.push(format!(
                    "[accepted at load] `{shown}` exit 0 for resolution [4294967296, 4294967296]: {}",
                    String::from_utf8_lossy(&out.stdout).lines().find(|l| l.starts_with("camera")).unwrap_or("")
                ));
            }
        } else if code == Some(1) {
            // None of these cases has an I/O problem: exit 1 is a failure found late (or mislabelled).
            failures.push(format!("[failure after the simulation] `{shown}`: exit 1: {tail}"));
        } else if code == Some(2) && stderr.trim().is_empty() {
            failures.push(format!("[bad message] `{shown}`: exit 2 with nothing on stderr"));
        }
        println!("cli: `{shown}` -> {code:?} in {:.2} s: {tail}", t0.elapsed().as_secs_f64());
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "fuzz (command line): {} failing cases:\n{}", failures.len(), failures.join("\n"));
}

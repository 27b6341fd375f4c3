//! The source tree reads as the data path: each top-level module of `src/` sits in one layer of
//! `LAYERS`, and it may name (`crate::x`) only modules of layers below its own. So there is no
//! import cycle, and a module added without a place in the order fails here until it gets one.

use std::collections::BTreeMap;
use std::path::Path;

/// Bottom to top. The README's "How it works" draws the same order.
const LAYERS: &[&[&str]] = &[
    &["error", "pages", "geometry"],
    &["sampling"],
    &["spectrum"],
    &["scene"],
    &["bsdf", "media", "lights", "detectors"],
    &["integrators"],
    &["run"],
    &["output"],
    &["validate"],
    // The binary's own module beside main.rs (the MPI driver, `--features mpi`): the top.
    &["mpi_run"],
];

/// Every `crate::name` a file names: in paths, and inside `use crate::{a, b::c}` groups.
fn named_modules(text: &str) -> Vec<String> {
    let code: String = text.lines().map(|l| l.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n");
    let mut names = Vec::new();
    let ident = |s: &str| -> String { s.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect() };
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let group = group.split('}').next().unwrap_or("");
            // Only the first segment of each item: `a`, `b` of `{a, b::c}`.
            for item in group.split(',') {
                let n = ident(item.trim());
                if !n.is_empty() {
                    names.push(n);
                }
            }
        } else {
            names.push(ident(rest));
        }
    }
    names
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_module_names_only_modules_of_lower_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let layer_of: BTreeMap<&str, usize> =
        LAYERS.iter().enumerate().flat_map(|(i, l)| l.iter().map(move |m| (*m, i))).collect();
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut wrong = Vec::new();
    let mut seen = 0;
    for file in files {
        let rel = file.strip_prefix(&src).unwrap();
        let top = rel.iter().next().unwrap().to_string_lossy().trim_end_matches(".rs").to_string();
        if top == "lib" || top == "main" {
            continue;
        }
        let Some(&own) = layer_of.get(top.as_str()) else {
            wrong.push(format!("{}: module `{top}` has no layer in LAYERS", rel.display()));
            continue;
        };
        seen += 1;
        for name in named_modules(&std::fs::read_to_string(&file).unwrap()) {
            if name == top {
                continue;
            }
            match layer_of.get(name.as_str()) {
                Some(&l) if l < own => {}
                Some(&l) => wrong.push(format!(
                    "{}: `{top}` (layer {own}) names `crate::{name}` (layer {l}), which is not below it",
                    rel.display()
                )),
                None if src.join(format!("{name}.rs")).exists() || src.join(&name).is_dir() => {
                    wrong.push(format!("{}: `crate::{name}` has no layer in LAYERS", rel.display()))
                }
                None => {}
            }
        }
    }
    assert!(seen > 20, "only {seen} source files were read");
    assert!(wrong.is_empty(), "layering broken:\n{}", wrong.join("\n"));
}

#[test]
fn the_layer_check_sees_grouped_and_plain_paths() {
    // The reader must not miss an import, or the check above could not fail.
    let text = "use crate::{scene::Scene, run};\nlet x = crate::output::flux(); // crate::validate\n";
    assert_eq!(named_modules(text), ["scene", "run", "output"]);
}

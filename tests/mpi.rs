//! MPI runs (`--features mpi`): `mpirun -n K photon run` writes the bytes of a one-process run
//! for K = 1, 2, 3 (oversubscribed on a 2-core machine), with an image and with maps, and a
//! `--rel-error` stop under 3 ranks is reproduced by a one-process run of its recorded photons.
#![cfg(feature = "mpi")]

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

const BIN: &str = env!("CARGO_BIN_EXE_photon");

fn scene(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name).display().to_string()
}

fn run(ranks: Option<u32>, args: &[&str]) {
    let mut cmd = match ranks {
        // As root (CI) Open MPI needs --allow-run-as-root; more ranks than cores, --oversubscribe.
        Some(k) => {
            let mut c = Command::new("mpirun");
            c.args(["--allow-run-as-root", "--oversubscribe", "-n", &k.to_string(), BIN]);
            c
        }
        None => Command::new(BIN),
    };
    let out = cmd.args(args).output().expect("mpirun and photon run");
    assert!(out.status.success(), "{ranks:?} ranks, {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

fn run_json(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("run.json")).unwrap()).unwrap()
}

/// The files `dir`'s run.json lists, but run.json (timings) and the PNG previews (drawn from
/// the same f32 values as the EXRs).
fn result_files(dir: &Path) -> Vec<String> {
    run_json(dir)["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().to_string())
        .filter(|f| f != "run.json" && !f.ends_with(".png"))
        .collect()
}

#[test]
fn any_rank_count_writes_the_one_process_bytes() {
    let dir = common::temp_dir("mpi-ranks");
    // 1 200 000 photons: 74 batches, so 3 ranks hold a decision round (8 batches each) and end
    // on a partial batch.
    for (name, extra) in [("cornell_box.toml", &[][..]), ("office.toml", &["--no-image"][..])] {
        let s = scene(name);
        let one = dir.join(format!("{name}-one"));
        let base = ["run", s.as_str(), "--photons", "1200000", "--quiet", "--out"];
        let with = |out: &PathBuf| -> Vec<String> {
            base.iter()
                .map(|a| a.to_string())
                .chain([out.display().to_string()])
                .chain(extra.iter().map(|a| a.to_string()))
                .collect()
        };
        run(None, &with(&one).iter().map(String::as_str).collect::<Vec<_>>());
        let files = result_files(&one);
        assert!(files.iter().any(|f| f.ends_with(".exr")), "{name}: {files:?}");
        for k in [1, 2, 3] {
            let out = dir.join(format!("{name}-{k}"));
            run(Some(k), &with(&out).iter().map(String::as_str).collect::<Vec<_>>());
            assert_eq!(result_files(&out), files, "{name}, {k} ranks");
            for f in &files {
                let same = std::fs::read(one.join(f)).unwrap() == std::fs::read(out.join(f)).unwrap();
                assert!(same, "{name}, {k} ranks: {f} differs from the one-process run");
            }
            let info = run_json(&out);
            assert_eq!(info["ranks"], k, "{name}");
            assert_eq!(info["photons"], 1_200_000, "{name}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_rel_error_stop_under_three_ranks_reproduces_from_its_photon_count() {
    let dir = common::temp_dir("mpi-rel-error");
    let s = scene("cornell_box.toml");
    let three = dir.join("three");
    run(Some(3), &["run", &s, "--rel-error", "0.02", "--no-image", "--quiet", "--out", three.to_str().unwrap()]);
    let info = run_json(&three);
    assert_eq!(info["stop_reason"], "rel_error");
    let photons = info["photons"].as_u64().unwrap();
    // The stop falls on a round: 3 ranks × 8 batches × rounds.
    assert_eq!(photons % (3 * 8 * 16_384), 0, "{photons}");
    let one = dir.join("one");
    run(None, &["run", &s, "--photons", &photons.to_string(), "--no-image", "--quiet", "--out", one.to_str().unwrap()]);
    for f in ["flux.json", "flux.csv"] {
        assert!(std::fs::read(one.join(f)).unwrap() == std::fs::read(three.join(f)).unwrap(), "{f} differs");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_under_mpi_exits_2_with_one_message() {
    let dir = common::temp_dir("mpi-bad");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "bad").unwrap();
    let file = dir.join("a-file");
    std::fs::write(&file, "").unwrap();
    let cornell = scene("cornell_box.toml");
    // A bad scene fails on every rank; an --out only rank 0 tries fails there alone: either way
    // no rank starts, and one message is printed.
    for args in [
        vec!["run", bad.to_str().unwrap(), "--quiet"],
        vec!["run", cornell.as_str(), "--quiet", "--out", file.to_str().unwrap()],
    ] {
        let out = Command::new("mpirun")
            .args(["--allow-run-as-root", "--oversubscribe", "-n", "2", BIN])
            .args(&args)
            .output()
            .expect("mpirun runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        // photon's own lines (mpirun adds a report of its own).
        assert_eq!(stderr.lines().filter(|l| l.starts_with("error:")).count(), 1, "{args:?}: {stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

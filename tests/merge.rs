//! Partial runs and `photon merge`: parts covering batches 0..N, merged in any order, write the
//! bytes one run of those N batches writes (run.json's timings aside); a gap, an overlap, a part
//! of another scene or seed, a changed scene and a truncated or corrupt state file are refused
//! with exit status 2 and a message, and nothing is written.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

const BIN: &str = env!("CARGO_BIN_EXE_photon");
const BATCH: u64 = 16_384;

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name)
}

/// Runs photon with `args`; returns (exit status, stderr).
fn photon(args: &[&str]) -> (i32, String) {
    let out = Command::new(BIN).args(args).output().expect("photon runs");
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn ok(args: &[&str]) {
    let (code, err) = photon(args);
    assert_eq!(code, 0, "photon {args:?} failed: {err}");
}

/// run.json without what depends on timing (and the thread count, which changes no result).
fn without_timing(path: &Path) -> serde_json::Value {
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let o = v.as_object_mut().unwrap();
    for key in ["wall_seconds", "photons_per_second", "rays_per_second", "fom", "threads"] {
        o.remove(key);
    }
    o["counters"].as_object_mut().unwrap().remove("trace_seconds");
    v
}

/// Every file of `a` is in `b` with the same bytes (run.json: the same but for timings), and
/// `b` has no others but the state file.
fn assert_same_outputs(a: &Path, b: &Path, what: &str) {
    let files: Vec<String> = serde_json::from_slice::<serde_json::Value>(&std::fs::read(a.join("run.json")).unwrap())
        .unwrap()["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().to_string())
        .collect();
    assert!(files.len() >= 3, "{what}: {files:?}");
    for f in &files {
        if f == "run.json" {
            assert_eq!(without_timing(&a.join(f)), without_timing(&b.join(f)), "{what}: run.json differs");
        } else {
            let (x, y) = (std::fs::read(a.join(f)).unwrap(), std::fs::read(b.join(f)).unwrap());
            assert!(x == y, "{what}: {f} differs between the merge and the single run");
        }
    }
}

#[test]
fn parts_merged_in_any_order_write_the_single_runs_bytes() {
    let dir = common::temp_dir("merge-order");
    // (scene, extra flags, parts as batch ranges, the order they are given to merge): the light
    // tracer's film, maps with stratified batches (their between-batch errors), the camera
    // integrators' film part.
    // (scene file, flags, parts' batch ranges, merge order)
    type Case<'a> = (&'a str, &'a [&'a str], &'a [(u64, u64)], &'a [usize]);
    let cases: [Case; 4] = [
        ("cornell_box.toml", &[], &[(0, 2), (2, 3), (3, 5)], &[1, 2, 0]),
        ("office.toml", &["--no-image", "--stratified"], &[(0, 1), (1, 4)], &[1, 0]),
        ("glass.toml", &["--integrator", "bdpt", "--seed", "4"], &[(0, 1), (1, 2)], &[1, 0]),
        // A film of fewer pixels (128 × 96) than a batch's samples: pixels take several a batch.
        ("led_phosphor.toml", &["--integrator", "path"], &[(0, 1), (1, 3)], &[1, 0]),
    ];
    for (name, flags, parts, order) in cases {
        let s = scene(name);
        let s = s.to_str().unwrap();
        let n = parts.last().unwrap().1;
        let single = dir.join(format!("{name}-single"));
        let photons = (n * BATCH).to_string();
        let mut args = vec!["run", s, "--photons", &photons, "--threads", "2", "--quiet", "--out"];
        args.push(single.to_str().unwrap());
        args.extend_from_slice(flags);
        ok(&args);
        let mut part_dirs = Vec::new();
        for (k, &(a, b)) in parts.iter().enumerate() {
            let out = dir.join(format!("{name}-part{k}"));
            let range = format!("{a}..{b}");
            // Parts on different thread counts: results do not depend on it.
            let threads = if k % 2 == 0 { "1" } else { "2" };
            let mut args = vec!["run", s, "--batches", &range, "--threads", threads, "--quiet", "--out"];
            args.push(out.to_str().unwrap());
            args.extend_from_slice(flags);
            ok(&args);
            assert!(out.join("state.photon").is_file(), "{name}: part {range} wrote no state");
            part_dirs.push(out);
        }
        let merged = dir.join(format!("{name}-merged"));
        let mut args = vec!["merge".to_string(), "--quiet".into(), "--out".into(), merged.display().to_string()];
        args.extend(order.iter().map(|&k| part_dirs[k].display().to_string()));
        ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert_same_outputs(&single, &merged, name);
        assert!(!merged.join("state.photon").exists(), "{name}: a merge writes no state of its own");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_parts_are_refused_with_exit_status_2() {
    let dir = common::temp_dir("merge-bad");
    let cornell = scene("cornell_box.toml");
    let furnace = scene("furnace.toml");
    let part = |name: &str, s: &Path, range: &str, extra: &[&str]| {
        let out = dir.join(name);
        let mut args = vec!["run", s.to_str().unwrap(), "--batches", range, "--no-image", "--quiet", "--out"];
        args.push(out.to_str().unwrap());
        args.extend_from_slice(extra);
        ok(&args);
        out
    };
    let a = part("a", &cornell, "0..2", &[]);
    let b = part("b", &cornell, "2..3", &[]);
    let c = part("c", &cornell, "3..4", &[]);
    let overlapping = part("overlap", &cornell, "1..3", &[]);
    let other_seed = part("seed", &cornell, "2..3", &["--seed", "2"]);
    let other_scene = part("furnace", &furnace, "2..3", &[]);
    let truncated = dir.join("truncated");
    std::fs::create_dir_all(&truncated).unwrap();
    let bytes = std::fs::read(b.join("state.photon")).unwrap();
    std::fs::write(truncated.join("state.photon"), &bytes[..bytes.len() - 100]).unwrap();
    let corrupt = dir.join("corrupt");
    std::fs::create_dir_all(&corrupt).unwrap();
    let mut flipped = bytes.clone();
    let middle = flipped.len() / 2;
    flipped[middle] ^= 0x10;
    std::fs::write(corrupt.join("state.photon"), &flipped).unwrap();
    let out = dir.join("merged");
    let cases: [(&str, &[&PathBuf], &str); 6] = [
        ("a gap", &[&a, &c], "batches 2..3 are in no part"),
        ("an overlap", &[&a, &overlapping], "overlap"),
        ("another seed", &[&a, &other_seed], "seed differs"),
        ("another scene", &[&a, &other_scene], "input_digest"),
        ("a truncated state", &[&a, &truncated], "truncated or corrupt"),
        ("a corrupt state", &[&a, &corrupt], "truncated or corrupt"),
    ];
    for (what, parts, message) in cases {
        let mut args = vec!["merge", "--quiet", "--out", out.to_str().unwrap()];
        args.extend(parts.iter().map(|p| p.to_str().unwrap()));
        let (code, err) = photon(&args);
        assert_eq!(code, 2, "{what}: exit status {code}, stderr {err}");
        assert!(err.contains(message), "{what}: the message should say \"{message}\": {err}");
        assert!(!out.exists(), "{what}: a refused merge wrote {}", out.display());
    }
    // A good merge of the same parts works.
    ok(&["merge", "--quiet", "--out", out.to_str().unwrap(), a.to_str().unwrap(), b.to_str().unwrap()]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_changed_scene_and_bad_batch_ranges_are_refused() {
    let dir = common::temp_dir("merge-changed");
    let s = dir.join("box.toml");
    std::fs::write(&s, common::cornell_toml()).unwrap();
    let part = dir.join("part");
    ok(&["run", s.to_str().unwrap(), "--batches", "0..1", "--no-image", "--quiet", "--out", part.to_str().unwrap()]);
    std::fs::write(&s, common::cornell_toml().replace("seed = 1", "seed = 1\n# edited")).unwrap();
    let (code, err) = photon(&["merge", "--quiet", "--out", dir.join("m").to_str().unwrap(), part.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("changed since"), "{err}");
    for (range, extra, message) in [
        ("3..3", &[][..], "holds no batch"),
        ("4..2", &[][..], "holds no batch"),
        ("a..2", &[][..], "not a batch number"),
        ("0..2", &["--photons", "100"][..], "cannot be combined with --photons"),
        ("0..2", &["--rel-error", "0.1"][..], "cannot be combined with --rel-error"),
    ] {
        let mut args = vec!["run", s.to_str().unwrap(), "--batches", range, "--quiet", "--out"];
        let out = dir.join("bad");
        args.push(out.to_str().unwrap());
        args.extend_from_slice(extra);
        let (code, err) = photon(&args);
        assert_eq!(code, 2, "--batches {range} {extra:?}: {err}");
        assert!(err.contains(message), "--batches {range} {extra:?}: {err}");
        assert!(!out.exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A copy of part `from` as `to`, its state's body edited by `edit(bytes, body_start)` and its
/// checksum made to match again: a state that no run writes but that reads as whole.
fn crafted(from: &Path, to: &Path, edit: impl Fn(&mut [u8], usize)) -> PathBuf {
    let mut bytes = std::fs::read(from.join("state.photon")).unwrap();
    // Magic (16 bytes), version (u32), header length n (u32), header: the body starts after.
    let n = u32::from_le_bytes(bytes[20..24].try_into().unwrap()) as usize;
    edit(&mut bytes, 24 + n);
    let end = bytes.len() - 8;
    let check =
        bytes[..end].iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3));
    bytes[end..].copy_from_slice(&check.to_le_bytes());
    std::fs::create_dir_all(to).unwrap();
    std::fs::write(to.join("state.photon"), &bytes).unwrap();
    to.to_path_buf()
}

#[test]
fn crafted_states_whose_sums_overflow_are_refused() {
    let dir = common::temp_dir("merge-overflow");
    let cornell = scene("cornell_box.toml");
    let part = |name: &str, range: &str| {
        let out = dir.join(name);
        let args = ["run", cornell.to_str().unwrap(), "--batches", range, "--no-image", "--quiet", "--out"];
        ok(&[&args[..], &[out.to_str().unwrap()]].concat());
        out
    };
    let (a, b) = (part("a", "0..1"), part("b", "1..2"));
    // The body: 12 counts (u64), the trace seconds (f64), then the escaped sum (top i32, three
    // i64 words). Words near i64::MAX in both parts overflow when added, however their windows
    // align (a shift of 0, 1 or 2 words still adds one pair); a run's words stay below 2^63 for
    // up to 2^35 batches (`exact::MAX_VALUES`), so only a crafted state reaches this.
    let huge_words = |bytes: &mut [u8], body: usize| {
        for k in 0..3 {
            let at = body + 12 * 8 + 8 + 4 + 8 * k;
            bytes[at..at + 8].copy_from_slice(&(i64::MAX - 1).to_le_bytes());
        }
    };
    let huge_count =
        |bytes: &mut [u8], body: usize| bytes[body..body + 8].copy_from_slice(&(u64::MAX - 1).to_le_bytes());
    let endless = |bytes: &mut [u8], body: usize| {
        bytes[body + 96..body + 104].copy_from_slice(&f64::INFINITY.to_le_bytes());
    };
    let cases: [(&str, [PathBuf; 2], &str); 3] = [
        (
            "escaped sums near 2^63",
            [crafted(&a, &dir.join("a-sum"), huge_words), crafted(&b, &dir.join("b-sum"), huge_words)],
            "exact sums overflow",
        ),
        (
            "photon counts near 2^64",
            [crafted(&a, &dir.join("a-count"), huge_count), crafted(&b, &dir.join("b-count"), huge_count)],
            "counts overflow",
        ),
        ("infinite trace seconds", [a.clone(), crafted(&b, &dir.join("b-time"), endless)], "not a run's time"),
    ];
    let out = dir.join("merged");
    for (what, [x, y], message) in cases {
        let (code, err) =
            photon(&["merge", "--quiet", "--out", out.to_str().unwrap(), x.to_str().unwrap(), y.to_str().unwrap()]);
        assert_eq!(code, 2, "{what}: exit status {code}, stderr {err}");
        assert!(err.contains(message), "{what}: the message should say \"{message}\": {err}");
        assert!(!out.exists(), "{what}: a refused merge wrote {}", out.display());
    }
    // The uncrafted parts merge.
    ok(&["merge", "--quiet", "--out", out.to_str().unwrap(), a.to_str().unwrap(), b.to_str().unwrap()]);
    let _ = std::fs::remove_dir_all(&dir);
}

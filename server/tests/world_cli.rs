//! `horizon build` and `horizon cut` on the village world: the descriptor cache, the
//! complete-view invariant of the cut, one-line errors on bad input, and a closed stdout
//! ending a command quietly.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use serde_json::Value;

fn horizon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_horizon"))
        .args(args)
        .output()
        .expect("the horizon binary runs")
}

fn ok(args: &[&str]) -> String {
    let out = horizon(args);
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn fails_with_one_line(args: &[&str]) {
    let out = horizon(args);
    assert_eq!(out.status.code(), Some(1), "{args:?} should fail with 1");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.trim_end().lines().count(), 1, "{args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

fn cut_args<'a>(dir: &'a str, angle: &'a str) -> Vec<&'a str> {
    vec![
        "cut",
        dir,
        "--pos",
        "100,20,-50",
        "--min-solid-angle",
        angle,
        "--max-results",
        "100000",
    ]
}

fn cut(dir: &str, angle: &str) -> Value {
    let mut args = cut_args(dir, angle);
    args.extend(["--json", "--explain"]);
    serde_json::from_str(&ok(&args)).expect("cut --json prints JSON")
}

/// The village, seed 3, written by the library the demo and the lab use.
fn village(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("horizon-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    horizon_server::generated::write_world("village", &dir, 3, &[]).expect("village written");
    dir
}

#[test]
fn village_build_and_cut_cover_every_object_once() {
    let tmp = village("world-cli");
    let dir = tmp.to_str().expect("utf-8 temp path");

    // The BVH only: aggregates are checked in release by tests/reference/check_aggregates.py
    // and in horizon-aggregate's own tests; a debug build of 1,227 atlases is minutes.
    let first: Value =
        serde_json::from_str(&ok(&["build", dir, "--json", "--bvh-only"])).expect("json");
    assert_eq!(first["objects"], 10_000);
    assert_eq!(first["descriptors_computed"], 6);
    // A rebuild with other weights reuses every descriptor.
    let second: Value =
        serde_json::from_str(&ok(&["build", dir, "--json", "--mu", "0.5", "--bvh-only"]))
            .expect("json");
    assert_eq!(second["descriptors_reused"], 6);

    let fine = cut(dir, "0.0001");
    let coarse = cut(dir, "0.01");
    for c in [&fine, &coarse] {
        let mut seen: HashMap<u64, u32> = HashMap::new();
        for e in c["entries"].as_array().expect("entries") {
            let objects = e["objects"].as_array().expect("objects with --explain");
            assert_eq!(objects.len() as u64, e["covers"].as_u64().expect("covers"));
            for o in objects {
                *seen.entry(o.as_u64().expect("id")).or_default() += 1;
            }
            assert!(e["kind"] == "object" || e["kind"] == "aggregate");
        }
        assert_eq!(seen.len(), 10_000, "every object");
        assert!(seen.values().all(|&n| n == 1), "complete-view invariant");
        assert!(c["nodes_visited"].as_u64().expect("nodes_visited") > 0);
        assert!(c["seconds"].as_f64().is_some());
    }
    let len = |c: &Value| c["entries"].as_array().map_or(0, Vec::len);
    assert!(
        len(&coarse) < len(&fine),
        "{} vs {}",
        len(&coarse),
        len(&fine)
    );

    // A reader that stops after one line (`horizon cut ... | head -1`): status 0, no panic.
    let mut child = Command::new(env!("CARGO_BIN_EXE_horizon"))
        .args(cut_args(dir, "0.0001"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("horizon cut starts");
    let mut first_line = String::new();
    BufReader::new(child.stdout.take().expect("stdout"))
        .read_line(&mut first_line)
        .expect("one line");
    assert!(first_line.starts_with("cut at "), "{first_line}");
    let out = child.wait_with_output().expect("horizon cut ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.is_empty(), "{stderr}");

    // Bad input: one line, exit code 1.
    fails_with_one_line(&["cut", dir, "--pos", "1,2", "--min-solid-angle", "0.01"]);
    fails_with_one_line(&[
        "cut",
        "/nonexistent/world",
        "--pos",
        "1,2,3",
        "--min-solid-angle",
        "0.01",
    ]);
    fails_with_one_line(&["build", "/nonexistent/world"]);
    std::fs::write(Path::new(dir).join("world.db"), b"not a database").expect("write");
    fails_with_one_line(&["build", dir]);
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn a_world_never_built_is_cut_through_a_tree_built_on_the_spot() {
    let tmp = village("unbuilt");
    let dir = tmp.to_str().expect("utf-8 temp path");
    let c = cut(dir, "0.01");
    let covered: u64 = c["entries"]
        .as_array()
        .expect("entries")
        .iter()
        .map(|e| e["covers"].as_u64().expect("covers"))
        .sum();
    assert_eq!(covered, 10_000, "every object, once");
    let _ = std::fs::remove_dir_all(&tmp);
}
#[test]
fn horizon_lists_only_product_commands() {
    let help = ok(&["--help"]);
    for product in ["mesh", "simplify", "descriptors", "build", "cut", "demo"] {
        assert!(help.contains(product), "{product} missing: {help}");
    }
    for lab in [
        "gen",
        "report",
        "sweep",
        "calibrate",
        "bench-bvh",
        "bench-aggregates",
    ] {
        assert!(
            !help.lines().any(|l| l.trim_start().starts_with(lab)),
            "{lab} is a lab command: {help}"
        );
    }
}

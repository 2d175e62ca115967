//! Integration test of `horizon gen world`, `horizon build` and `horizon cut` (issue 5) on the
//! village world: the written directory, the descriptor cache, the complete-view invariant of
//! the cut and one-line errors on bad input.

use std::path::Path;
use std::process::{Command, Output};

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

fn cut(dir: &str, angle: &str) -> Value {
    let stdout = ok(&[
        "cut",
        dir,
        "--pos",
        "100,20,-50",
        "--min-solid-angle",
        angle,
        "--max-results",
        "100000",
        "--json",
        "--explain",
    ]);
    serde_json::from_str(&stdout).expect("cut --json prints JSON")
}

#[test]
fn village_gen_build_cut_covers_every_object_once() {
    let tmp = std::env::temp_dir().join(format!("horizon-world-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    let dir = tmp.to_str().expect("utf-8 temp path");

    ok(&["gen", "world", "village", dir, "--seed", "3"]);
    let manifest: Value = serde_json::from_slice(
        &std::fs::read(Path::new(dir).join("world.json")).expect("world.json"),
    )
    .expect("world.json parses");
    assert_eq!(manifest["object_count"], 10_000);
    assert_eq!(manifest["model_count"], 6);
    let models = std::fs::read_dir(Path::new(dir).join("models"))
        .expect("models/")
        .count();
    assert_eq!(models, 6);

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
        let mut seen = vec![0u32; 10_000];
        for e in c["entries"].as_array().expect("entries") {
            let objects = e["objects"].as_array().expect("objects with --explain");
            assert_eq!(objects.len() as u64, e["covers"].as_u64().expect("covers"));
            for o in objects {
                seen[o.as_u64().expect("id") as usize] += 1;
            }
            assert!(e["kind"] == "object" || e["kind"] == "aggregate");
        }
        assert!(seen.iter().all(|&n| n == 1), "complete-view invariant");
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

    // Figure 5's sweep: one row per (mu, w), then the obvhs baseline.
    let rows: Value =
        serde_json::from_str(&ok(&["sweep", dir, "--views", "3", "--json"])).expect("json");
    let rows = rows.as_array().expect("rows");
    let trees = |name: &str| rows.iter().filter(|r| r["tree"] == name).count();
    assert_eq!(
        (trees("similarity"), trees("obvhs"), rows.len()),
        (24, 1, 25)
    );
    assert!(rows.iter().all(|r| r["mean_cut_size"].as_f64() > Some(0.0)));

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
    std::fs::write(Path::new(dir).join("objects.json"), b"{not json").expect("write");
    fails_with_one_line(&["build", dir]);
    fails_with_one_line(&["gen", "world", "moon", dir]);
    let _ = std::fs::remove_dir_all(&tmp);
}

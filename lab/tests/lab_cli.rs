//! `horizon-lab gen world` and `horizon-lab sweep` on the village: the written world
//! directory, Figure 5's rows, and one-line errors on bad input.

use std::path::Path;
use std::process::{Command, Output};

use horizon_bvh::{DEFAULT_MU, DEFAULT_W};
use serde_json::Value;

fn lab(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_horizon-lab"))
        .args(args)
        .output()
        .expect("the horizon-lab binary runs")
}

fn ok(args: &[&str]) -> String {
    let out = lab(args);
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn village_gen_and_sweep() {
    let tmp = std::env::temp_dir().join(format!("horizon-lab-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    let dir = tmp.to_str().expect("utf-8 temp path");

    ok(&["gen", "world", "village", dir, "--seed", "3"]);
    assert!(Path::new(dir).join("world.db").is_file());
    // The sweep needs the models described; the trees it builds itself.
    let world = horizon_world::World::open(&tmp).expect("open");
    let status = world.status().expect("status");
    assert_eq!((status.objects, status.models), (10_000, 6));
    world.describe_models(&|_, _| {}).expect("describe");
    world.build_tree(DEFAULT_MU, DEFAULT_W).expect("tree");
    drop(world);

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
    for args in [
        &["gen", "world", "moon", dir][..],
        &["sweep", "/nonexistent/world"][..],
        &["report", dir, "--views", "0"][..],
    ] {
        let out = lab(args);
        assert_eq!(out.status.code(), Some(1), "{args:?} should fail with 1");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.trim_end().lines().count(), 1, "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&tmp);
}

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

/// A box of side `s` with its corner at the origin (12 triangles, counter-clockwise outside).
fn cube(s: f32) -> horizon_mesh::InstancedMesh {
    use glam::{Affine3A, Vec3};
    let positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { 0.0 } else { s },
                if i & 2 == 0 { 0.0 } else { s },
                if i & 4 == 0 { 0.0 } else { s },
            )
        })
        .collect();
    let indices = vec![
        0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6,
        1, 3, 5, 3, 7, 5,
    ];
    horizon_mesh::InstancedMesh {
        submeshes: vec![horizon_mesh::Submesh {
            positions,
            indices,
            ..Default::default()
        }],
        instances: vec![horizon_mesh::Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        ..Default::default()
    }
}

#[test]
fn fidelity_of_a_small_world() {
    use glam::{Affine3A, Vec3};
    let tmp = std::env::temp_dir().join(format!("horizon-lab-fidelity-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    let dir = tmp.to_str().expect("utf-8 temp path");
    // 144 boxes of three sizes on a 12 x 12 grid, 8 m apart, with aggregates.
    let models: Vec<(String, horizon_mesh::InstancedMesh)> = [1.0, 1.5, 2.5]
        .iter()
        .enumerate()
        .map(|(i, &s)| (format!("box{i}"), cube(s)))
        .collect();
    let objects: Vec<(usize, Affine3A)> = (0..144)
        .map(|i| {
            let (x, z) = ((i % 12) as f32, (i / 12) as f32);
            (
                i % 3,
                Affine3A::from_translation(Vec3::new(x * 8.0, 0.0, z * 8.0)),
            )
        })
        .collect();
    let world = horizon_world::World::create(&tmp, "boxes", 1, &models, &objects).expect("world");
    world
        .rebuild_aggregates(Default::default(), &|_| {})
        .expect("aggregates");
    drop(world);
    let small = [
        "--width",
        "96",
        "--height",
        "54",
        "--samples",
        "1",
        "--json",
    ];
    let run = |extra: &[&str]| -> Value {
        let mut args = vec!["fidelity", dir];
        args.extend_from_slice(&small);
        args.extend_from_slice(extra);
        serde_json::from_str(&ok(&args)).expect("json")
    };

    // The default cut: three views, named, with the full world's costs the same in each.
    let report = run(&["--street", "1"]);
    let views = report["views"].as_array().expect("views");
    let names: Vec<&str> = views.iter().filter_map(|v| v["name"].as_str()).collect();
    assert_eq!(names, ["street-1", "overhead", "outside"]);
    for v in views {
        assert_eq!(v["full"]["triangles"], 144 * 12, "{v}");
        let (psnr, ssim, holes) = (
            v["psnr"].as_f64().expect("psnr"),
            v["ssim"].as_f64().expect("ssim"),
            v["holes"].as_f64().expect("holes"),
        );
        assert!(
            psnr > 0.0 && ssim <= 1.0 + 1e-9 && (0.0..=1.0).contains(&holes),
            "{v}"
        );
    }
    // Without rendering: the same cuts, costs and bounds, and no image figures.
    let costed = run(&["--street", "1", "--no-render"]);
    for (v, w) in views.iter().zip(costed["views"].as_array().expect("views")) {
        assert_eq!((&v["cut"], &v["full"]), (&w["cut"], &w["full"]), "{w}");
        assert_eq!(v["iou_min"], w["iou_min"], "{w}");
        assert!(w["psnr"].is_null() && w["holes"].is_null(), "{w}");
    }
    // A cut that shows every object as itself draws exactly the full world.
    let every = run(&[
        "--street",
        "1",
        "--min-solid-angle",
        "1e-9",
        "--max-entries",
        "100000",
    ]);
    for v in every["views"].as_array().expect("views") {
        assert_eq!(v["aggregates"], 0, "{v}");
        assert_eq!(
            (v["psnr"].as_f64(), v["holes"].as_f64()),
            (Some(100.0), Some(0.0))
        );
    }
    // One node's aggregate alone against what it covers.
    let node = run(&["--node", "0"]);
    let v = &node["views"][0];
    assert_eq!(v["name"], "node-0");
    let iou = v["iou_min"].as_f64().expect("iou");
    assert!(iou > 0.0 && iou <= 1.0, "{v}");

    // Bad input: one line, exit code 1.
    for args in [
        &["fidelity", "/nonexistent/world"][..],
        &["fidelity", dir, "--samples", "0"][..],
        &["fidelity", dir, "--node", "999999"][..],
    ] {
        let out = lab(args);
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&tmp);
}

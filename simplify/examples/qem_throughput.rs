//! Throughput of the QEM baseline on the expanded maple-tree (the IAS paper's Table 3 case),
//! with the bunny and IAS on maple-tree as guards:
//! `cargo run --release -p horizon-simplify --example qem_throughput -- [RUNS] [--error] [--dump DIR]
//! [--maple-only]`.
//!
//! `--error` adds the symmetric Hausdorff distance of each QEM result; `--dump DIR` writes the
//! expanded maple-tree welded by position as `DIR/maple.v.f64` and `DIR/maple.f.i64` (raw
//! little-endian arrays) for running fast-simplification on the same input.

use std::collections::HashMap;
use std::path::Path;

use horizon_mesh::{import_file, ImportOptions, InstancedMesh};
use horizon_simplify::distance::{hausdorff, DistanceOptions};
use horizon_simplify::{simplify, simplify_qem, SimplifyOptions, Target};

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn bench(name: &str, mesh: &InstancedMesh, runs: usize, qem: bool, error: bool) {
    let options = SimplifyOptions::default();
    let mut secs = Vec::new();
    let mut last = None;
    for _ in 0..runs {
        let out = if qem {
            simplify_qem(mesh, Target::Ratio(0.2), &options)
        } else {
            simplify(mesh, Target::Ratio(0.2), &options)
        }
        .expect("simplify");
        secs.push(out.report.seconds);
        last = Some(out);
    }
    let out = last.expect("at least one run");
    let s = median(secs.clone());
    println!(
        "{name} {}: {} -> {} tris, median {:.3} s (min {:.3}) of {:?} ({:.3} M tris/s), error {:.4e}",
        if qem { "qem" } else { "ias" },
        out.report.triangles_in,
        out.report.triangles_out,
        s,
        secs.iter().copied().fold(f64::INFINITY, f64::min),
        secs.iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
        out.report.triangles_in as f64 / s / 1e6,
        out.report.error
    );
    if error {
        let d = hausdorff(
            &mesh.expand(),
            &out.mesh.expand(),
            &DistanceOptions::default(),
        )
        .expect("distance");
        println!(
            "  hausdorff {:.5e} ({:.5e} of diagonal)",
            d.hausdorff, d.hausdorff_rel_diag
        );
    }
}

fn dump(mesh: &InstancedMesh, dir: &Path) {
    let e = mesh.expand();
    let mut ids: HashMap<[u32; 3], i64> = HashMap::new();
    let mut v: Vec<f64> = Vec::new();
    let remap: Vec<i64> = e
        .positions
        .iter()
        .map(|p| {
            *ids.entry(p.to_array().map(f32::to_bits))
                .or_insert_with(|| {
                    v.extend(p.to_array().map(f64::from));
                    (v.len() / 3 - 1) as i64
                })
        })
        .collect();
    let f: Vec<i64> = e.indices.iter().map(|&i| remap[i as usize]).collect();
    let bytes = |xs: Vec<[u8; 8]>| xs.concat();
    std::fs::write(
        dir.join("maple.v.f64"),
        bytes(v.iter().map(|x| x.to_le_bytes()).collect()),
    )
    .expect("write");
    std::fs::write(
        dir.join("maple.f.i64"),
        bytes(f.iter().map(|x| x.to_le_bytes()).collect()),
    )
    .expect("write");
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let runs = args.first().and_then(|a| a.parse().ok()).unwrap_or(3);
    let error = args.iter().any(|a| a == "--error");
    let maple = horizon_worldgen::generate_model("maple-tree", 1).expect("maple-tree");
    if let Some(i) = args.iter().position(|a| a == "--dump") {
        dump(&maple, Path::new(&args[i + 1]));
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let bunny = import_file(
        &root.join("assets/models/bunny_trimesh/bunny.ply"),
        &ImportOptions::default(),
    )
    .expect("bunny")
    .mesh;
    bench("maple-tree", &maple, runs, true, error);
    if args.iter().any(|a| a == "--maple-only") {
        return;
    }
    bench("bunny", &bunny, runs, true, error);
    bench("maple-tree", &maple, runs, false, false);
}

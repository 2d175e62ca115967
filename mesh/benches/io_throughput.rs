//! Import and export throughput of GLB, in MB/s of GLB bytes, on a generated model of more
//! than one million unique triangles (images: none, so nothing is decoded).
//!
//! Run: `cargo bench -p horizon-mesh --bench io_throughput`
//!
//! The peer, in the same run on the same bytes, is the `gltf` crate's own loader
//! (`gltf::import_slice` plus reading every position, normal, UV and index through its
//! `Reader`), which does no bounds-checked validation of the kind ours does. Each figure is the
//! median of 5 runs. Results go to stdout as a markdown table and to
//! `target/bench/io_throughput.json`.

use std::time::Instant;

use glam::{Affine3A, Quat, Vec2, Vec3};
use horizon_mesh::{
    export_glb, import_bytes, ExportOptions, Format, ImageCheck, ImportOptions, Instance,
    InstancedMesh, Limits, Submesh,
};

const RUNS: usize = 5;

fn main() {
    // Stage 1: the model: 16 noisy height-field patches of 64,800 triangles, 4 instances each.
    let mesh = generate(16, 180, 4, 0x5EED);
    println!(
        "model: {} submeshes, {} instances, {} unique / {} expanded triangles",
        mesh.submeshes.len(),
        mesh.instances.len(),
        mesh.unique_triangle_count(),
        mesh.expanded_triangle_count()
    );
    let options = ImportOptions {
        limits: Limits::default(),
        images: ImageCheck::Header,
    };
    let mut rows = Vec::new();
    for (label, export) in [
        ("plain", ExportOptions::plain()),
        ("compressed", ExportOptions::compressed()),
    ] {
        // Stage 2: export, timed.
        let (glb, export_s) = median_time(|| export_glb(&mesh, &export).expect("exports"));
        // Stage 3: import of the same bytes, timed.
        let (imported, import_s) =
            median_time(|| import_bytes(&glb, Format::Glb, None, &options).expect("imports"));
        assert_eq!(
            imported.mesh.expanded_triangle_count(),
            mesh.expanded_triangle_count()
        );
        // Stage 4: the peer on the same bytes (it cannot read EXT_meshopt_compression).
        let peer_s = (!export.compress).then(|| median_time(|| gltf_crate_read(&glb)).1);
        rows.push(Row {
            label,
            bytes: glb.len(),
            export_s,
            import_s,
            peer_s,
        });
    }
    report(&rows);
}

struct Row {
    label: &'static str,
    bytes: usize,
    export_s: f64,
    import_s: f64,
    peer_s: Option<f64>,
}

fn report(rows: &[Row]) {
    let mb = |bytes: usize, s: f64| bytes as f64 / 1e6 / s;
    println!("\n| GLB | bytes | export MB/s | import MB/s | gltf crate import MB/s | ours / gltf crate |");
    println!("|---|---|---|---|---|---|");
    for r in rows {
        let peer = r
            .peer_s
            .map_or("n/a (cannot decode meshopt)".to_string(), |p| {
                format!("{:.0}", mb(r.bytes, p))
            });
        let ratio = r
            .peer_s
            .map_or("n/a".to_string(), |p| format!("{:.2}", p / r.import_s));
        println!(
            "| {} | {} | {:.0} | {:.0} | {} | {} |",
            r.label,
            r.bytes,
            mb(r.bytes, r.export_s),
            mb(r.bytes, r.import_s),
            peer,
            ratio
        );
    }
    let plain = rows[0].bytes as f64;
    for r in &rows[1..] {
        println!(
            "\n{} size / plain size = {:.3}",
            r.label,
            r.bytes as f64 / plain
        );
    }
    let json: Vec<_> = rows
        .iter()
        .map(|r| {
            serde_json::json!({
                "glb": r.label, "bytes": r.bytes,
                "export_seconds": r.export_s, "import_seconds": r.import_s,
                "export_mb_per_s": mb(r.bytes, r.export_s), "import_mb_per_s": mb(r.bytes, r.import_s),
                "gltf_crate_import_seconds": r.peer_s,
            })
        })
        .collect();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/bench");
    std::fs::create_dir_all(&dir).expect("bench dir");
    std::fs::write(
        dir.join("io_throughput.json"),
        serde_json::to_vec_pretty(&json).expect("json"),
    )
    .expect("write results");
}

/// Runs `f` RUNS times; returns the last result and the median seconds.
fn median_time<T>(mut f: impl FnMut() -> T) -> (T, f64) {
    let mut times = Vec::new();
    let mut out = None;
    for _ in 0..RUNS {
        let start = Instant::now();
        out = Some(std::hint::black_box(f()));
        times.push(start.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    (out.expect("ran"), times[RUNS / 2])
}

/// The peer: the gltf crate's loader, reading every attribute the way an application would.
/// Every value is folded into a checksum so that no read can be optimised away.
fn gltf_crate_read(glb: &[u8]) -> f64 {
    let (doc, buffers, _images) = gltf::import_slice(glb).expect("gltf crate loads it");
    let mut sum = 0.0f64;
    for mesh in doc.meshes() {
        for prim in mesh.primitives() {
            let reader = prim.reader(|b| Some(&buffers[b.index()]));
            for p in reader.read_positions().into_iter().flatten() {
                sum += f64::from(p[0] + p[1] + p[2]);
            }
            for n in reader.read_normals().into_iter().flatten() {
                sum += f64::from(n[0] + n[1] + n[2]);
            }
            for t in reader
                .read_tex_coords(0)
                .into_iter()
                .flat_map(|t| t.into_f32())
            {
                sum += f64::from(t[0] + t[1]);
            }
            for i in reader.read_indices().into_iter().flat_map(|i| i.into_u32()) {
                sum += f64::from(i);
            }
        }
    }
    sum
}

/// A seeded model: `submeshes` height-field patches of `grid` x `grid` quads with normals and
/// UVs, each placed `instances` times with rotation and non-uniform scale (some mirrored).
fn generate(submeshes: usize, grid: usize, instances: usize, seed: u64) -> InstancedMesh {
    let mut rng = seed;
    let mut next = move || {
        // xorshift64*: a fixed, dependency-free sequence for a reproducible model.
        rng ^= rng >> 12;
        rng ^= rng << 25;
        rng ^= rng >> 27;
        (rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut mesh = InstancedMesh::default();
    for s in 0..submeshes {
        let side = grid + 1;
        let mut positions = Vec::with_capacity(side * side);
        let mut uvs = Vec::with_capacity(side * side);
        let (fx, fz) = (1.0 + next() * 4.0, 1.0 + next() * 4.0);
        for i in 0..side {
            for j in 0..side {
                let (u, v) = (i as f32 / grid as f32, j as f32 / grid as f32);
                let h = 0.1
                    * ((u * fx * std::f32::consts::TAU).sin()
                        * (v * fz * std::f32::consts::TAU).cos())
                    + 0.01 * next();
                positions.push(Vec3::new(u, h, v));
                uvs.push(Vec2::new(u, v));
            }
        }
        let mut indices = Vec::with_capacity(grid * grid * 6);
        for i in 0..grid {
            for j in 0..grid {
                let a = (i * side + j) as u32;
                let (b, c, d) = (a + 1, a + side as u32, a + side as u32 + 1);
                indices.extend_from_slice(&[a, b, c, b, d, c]);
            }
        }
        let mut normals = vec![Vec3::ZERO; positions.len()];
        for t in indices.chunks_exact(3) {
            let [p0, p1, p2] = [0, 1, 2].map(|k| positions[t[k] as usize]);
            let n = (p1 - p0).cross(p2 - p0);
            for &k in t {
                normals[k as usize] += n;
            }
        }
        for n in &mut normals {
            *n = n.normalize_or(Vec3::Y);
        }
        mesh.submeshes.push(Submesh {
            positions,
            normals: Some(normals),
            uvs: Some(uvs),
            colors: None,
            indices,
            material: None,
        });
        for k in 0..instances {
            let mut scale = Vec3::new(1.0 + next(), 1.0 + next(), 1.0 + next()) * 10.0;
            if k % 3 == 2 {
                scale.x = -scale.x;
            }
            let rotation = Quat::from_rotation_y(next() * std::f32::consts::TAU);
            let translation = Vec3::new(s as f32 * 30.0, 0.0, k as f32 * 30.0);
            mesh.instances.push(Instance {
                submesh: s,
                transform: Affine3A::from_scale_rotation_translation(scale, rotation, translation),
            });
        }
    }
    mesh
}

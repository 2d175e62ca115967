//! The generated benchmark models match the IAS paper's Table 2 (Azim et al. 2014): exact
//! submesh and instance counts, expanded triangles within 3% (exact for the patio chair), and
//! they are well-formed: valid, deterministic, closed where declared, mirrored and non-uniformly
//! scaled in places, textured with decodable images, and they survive a GLB round trip.

use std::collections::HashMap;
use std::sync::OnceLock;

use horizon_mesh::{
    export_glb, import_bytes, ExportOptions, Format, ImportOptions, InstancedMesh, Submesh,
};
use horizon_worldgen::{
    generate_model, generate_model_with_info, GeneratedModel, WorldgenError, MODEL_NAMES,
};
use proptest::prelude::*;

/// Table 2: name, submeshes, instances, expanded triangles, allowed relative deviation.
const TABLE_2: [(&str, usize, usize, u64, f64); 4] = [
    ("maple-tree", 18, 9_324, 1_818_074, 0.03),
    ("village-mesh", 79, 13_523, 1_254_696, 0.03),
    ("patio-chair", 6, 68, 2_240, 0.0),
    ("stonehenge", 59, 80, 10_061, 0.03),
];

const SEED: u64 = 2014;

/// Each model generated once with [`SEED`], shared by the tests of this file.
fn models() -> &'static HashMap<&'static str, GeneratedModel> {
    static MODELS: OnceLock<HashMap<&'static str, GeneratedModel>> = OnceLock::new();
    MODELS.get_or_init(|| {
        MODEL_NAMES
            .iter()
            .map(|&name| {
                let model = generate_model_with_info(name, SEED).expect("generates");
                (name, model)
            })
            .collect()
    })
}

fn model(name: &str) -> &'static GeneratedModel {
    &models()[name]
}

#[test]
fn counts_match_table_2() {
    for (name, submeshes, instances, triangles, tolerance) in TABLE_2 {
        let m = &model(name).mesh;
        let expanded = m.expanded_triangle_count();
        let texture_bytes: usize = m.textures.iter().map(|t| t.bytes.len()).sum();
        eprintln!(
            "{name}: {} submeshes, {} instances, {} unique triangles, {expanded} expanded \
             ({:+.2}% of {triangles}), {} textures in {texture_bytes} bytes",
            m.submeshes.len(),
            m.instances.len(),
            m.unique_triangle_count(),
            100.0 * (expanded as f64 / triangles as f64 - 1.0),
            m.textures.len(),
        );
        assert_eq!(m.submeshes.len(), submeshes, "{name} submeshes");
        assert_eq!(m.instances.len(), instances, "{name} instances");
        let deviation = (expanded as f64 - triangles as f64).abs() / triangles as f64;
        assert!(
            deviation <= tolerance,
            "{name}: {expanded} expanded triangles, Table 2 has {triangles}"
        );
    }
}

#[test]
fn every_model_is_valid_with_normals_and_uvs_everywhere() {
    for name in MODEL_NAMES {
        let g = model(name);
        g.mesh.validate().expect("valid");
        assert_eq!(g.submeshes.len(), g.mesh.submeshes.len());
        for (s, sub) in g.mesh.submeshes.iter().enumerate() {
            let what = format!("{name} submesh {s} ({})", g.submeshes[s].name);
            assert!(sub.triangle_count() > 0, "{what} is empty");
            assert!(sub.normals.is_some(), "{what} has no normals");
            assert!(sub.uvs.is_some(), "{what} has no UVs");
            let normals = sub.normals.as_deref().unwrap_or_default();
            assert!(
                normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-3),
                "{what} has a normal that is not unit length"
            );
        }
        let used: Vec<usize> = g.mesh.instances.iter().map(|i| i.submesh).collect();
        for s in 0..g.mesh.submeshes.len() {
            assert!(used.contains(&s), "{name} submesh {s} is never placed");
        }
    }
}

#[test]
fn same_seed_gives_the_same_mesh_and_another_seed_moves_things() {
    for name in MODEL_NAMES {
        let again = generate_model(name, SEED).expect("generates");
        assert!(again == model(name).mesh, "{name} differs between two runs");
        let other = generate_model(name, SEED + 1).expect("generates");
        assert_eq!(other.instances.len(), again.instances.len());
        let moved = other
            .instances
            .iter()
            .zip(&again.instances)
            .filter(|(a, b)| a.transform != b.transform)
            .count();
        assert!(
            moved * 2 > again.instances.len(),
            "{name}: only {moved} placements changed"
        );
    }
}

#[test]
fn unknown_names_list_the_valid_ones() {
    let err = generate_model("bunny", 1).expect_err("no bunny");
    assert!(matches!(err, WorldgenError::UnknownModel { .. }));
    let message = err.to_string();
    for name in MODEL_NAMES {
        assert!(message.contains(name), "{message}");
    }
}

#[test]
fn submeshes_declared_closed_are_watertight_and_outward() {
    for name in MODEL_NAMES {
        let g = model(name);
        let closed = g.submeshes.iter().filter(|i| i.closed).count();
        assert!(closed > 0, "{name} declares nothing closed");
        for (sub, info) in g.mesh.submeshes.iter().zip(&g.submeshes) {
            if info.closed {
                if let Err(why) = check_closed(sub) {
                    panic!("{name} {}: {why}", info.name);
                }
            }
        }
    }
}

#[test]
fn some_instances_are_mirrored_and_some_scaled_non_uniformly() {
    for name in MODEL_NAMES {
        let m = &model(name).mesh;
        let mirrored = m
            .instances
            .iter()
            .filter(|i| i.transform.matrix3.determinant() < 0.0)
            .count();
        let non_uniform = m
            .instances
            .iter()
            .filter(|i| {
                let l = i.transform.matrix3;
                let s = [l.x_axis.length(), l.y_axis.length(), l.z_axis.length()];
                let (lo, hi) = (
                    s.iter().fold(f32::MAX, |a, &b| a.min(b)),
                    s.iter().fold(0.0f32, |a, &b| a.max(b)),
                );
                hi > lo * 1.02
            })
            .count();
        let n = m.instances.len();
        eprintln!("{name}: {mirrored} of {n} mirrored, {non_uniform} non-uniformly scaled");
        assert!(mirrored > 0, "{name} has no mirrored instance");
        assert!(mirrored * 3 < n, "{name}: {mirrored} of {n} mirrored");
        assert!(non_uniform > 0, "{name} has no non-uniform scale");
    }
}

#[test]
fn the_heavily_instanced_models_have_10_to_20_percent_mirrored_where_plausible() {
    // Leaves of the maple tree; trees, rocks and bushes of the village.
    for (name, prefixes) in [
        ("maple-tree", &["leaf"][..]),
        ("village-mesh", &["tree", "rock", "bush"][..]),
    ] {
        let g = model(name);
        let chosen: Vec<_> = g
            .mesh
            .instances
            .iter()
            .filter(|i| {
                let submesh = &g.submeshes[i.submesh].name;
                prefixes.iter().any(|p| submesh.starts_with(p))
            })
            .collect();
        let mirrored = chosen
            .iter()
            .filter(|i| i.transform.matrix3.determinant() < 0.0)
            .count();
        let share = mirrored as f64 / chosen.len() as f64;
        assert!((0.1..=0.2).contains(&share), "{name}: {share}");
    }
}

#[test]
fn closed_submeshes_keep_their_normal_and_uv_seams() {
    // Every closed primitive here has seams (per-face box vertices, cap vertices, a UV seam
    // column), so some positions must carry several vertices.
    for name in MODEL_NAMES {
        let g = model(name);
        for (sub, info) in g.mesh.submeshes.iter().zip(&g.submeshes) {
            if info.closed {
                let distinct: std::collections::HashSet<[u32; 3]> = sub
                    .positions
                    .iter()
                    .map(|p| [p.x, p.y, p.z].map(|c| (c + 0.0).to_bits()))
                    .collect();
                assert!(
                    distinct.len() < sub.positions.len(),
                    "{name} {} has no seam",
                    info.name
                );
            }
        }
    }
}

#[test]
fn leaves_are_open_double_sided_sheets_stored_once() {
    let g = model("maple-tree");
    let leaves: Vec<usize> = (0..g.submeshes.len())
        .filter(|&s| g.submeshes[s].name.starts_with("leaf"))
        .collect();
    assert_eq!(leaves.len(), 2);
    for &s in &leaves {
        assert!(!g.submeshes[s].closed);
        let material = g.mesh.submeshes[s].material.expect("has a material");
        assert!(g.mesh.materials[material].double_sided);
        assert!(g.mesh.materials[material].base_color_texture.is_some());
    }
    // Geometry lives once per submesh: stored triangles are a sliver of the drawn ones.
    for name in ["maple-tree", "village-mesh"] {
        let m = &model(name).mesh;
        assert!(
            m.unique_triangle_count() * 40 < m.expanded_triangle_count(),
            "{name}"
        );
    }
}

#[test]
fn textures_decode_and_stay_small() {
    for name in MODEL_NAMES {
        let m = &model(name).mesh;
        assert!(!m.textures.is_empty(), "{name} has no textures");
        let total: usize = m.textures.iter().map(|t| t.bytes.len()).sum();
        assert!(total < 1 << 20, "{name}: {total} texture bytes");
        for t in &m.textures {
            assert_eq!(t.mime_type, "image/png");
            let image = t.decode().expect("decodes");
            assert_eq!(image.dimensions(), t.size);
        }
        let textured = m
            .materials
            .iter()
            .filter(|m| m.base_color_texture.is_some())
            .count();
        assert!(textured > 0, "{name} has no textured material");
    }
}

#[test]
fn export_and_reimport_keep_the_expanded_triangle_count() {
    for name in MODEL_NAMES {
        let m = &model(name).mesh;
        let glb = export_glb(m, &ExportOptions::plain()).expect("exports");
        let back = import_bytes(&glb, Format::Glb, None, &ImportOptions::default())
            .expect("re-imports")
            .mesh;
        assert_eq!(
            back.expanded_triangle_count(),
            m.expanded_triangle_count(),
            "{name}"
        );
        assert_eq!(back.instances.len(), m.instances.len(), "{name}");
        assert_eq!(mirrored(&back), mirrored(m), "{name}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn small_models_keep_their_counts_for_any_seed(seed in any::<u64>()) {
        for (name, submeshes, instances, triangles) in [
            ("patio-chair", 6, 68, 2_240),
            ("stonehenge", 59, 80, model("stonehenge").mesh.expanded_triangle_count()),
        ] {
            let m = generate_model(name, seed).expect("generates");
            prop_assert!(m.validate().is_ok());
            prop_assert_eq!(m.submeshes.len(), submeshes);
            prop_assert_eq!(m.instances.len(), instances);
            prop_assert_eq!(m.expanded_triangle_count(), triangles);
        }
    }
}

fn mirrored(m: &InstancedMesh) -> usize {
    m.instances
        .iter()
        .filter(|i| i.transform.matrix3.determinant() < 0.0)
        .count()
}

/// Welded by position, every directed edge must appear exactly once and its reverse exactly
/// once (closed, manifold, consistently wound), and the signed volume must be positive
/// (outward).
fn check_closed(sub: &Submesh) -> Result<(), String> {
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let welded: Vec<u32> = sub
        .positions
        .iter()
        .map(|p| {
            let next = ids.len() as u32;
            *ids.entry([p.x, p.y, p.z].map(|c| (c + 0.0).to_bits()))
                .or_insert(next)
        })
        .collect();
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    let mut volume = 0.0f64;
    for t in sub.indices.chunks_exact(3) {
        let w = [t[0], t[1], t[2]].map(|i| welded[i as usize]);
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] {
            return Err(format!("degenerate triangle {t:?}"));
        }
        for e in 0..3 {
            *edges.entry((w[e], w[(e + 1) % 3])).or_default() += 1;
        }
        let [p, q, r] = [t[0], t[1], t[2]].map(|i| sub.positions[i as usize].as_dvec3());
        volume += p.dot(q.cross(r)) / 6.0;
    }
    for (&(a, b), &count) in &edges {
        if count != 1 {
            return Err(format!("directed edge {a}->{b} appears {count} times"));
        }
        if edges.get(&(b, a)) != Some(&1) {
            return Err(format!("edge {a}->{b} has no opposite edge"));
        }
    }
    if volume <= 0.0 {
        return Err(format!("signed volume {volume} is not positive"));
    }
    Ok(())
}

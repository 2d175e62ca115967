//! `horizon demo`: the main job on an embedded default, so a fresh clone shows what Horizon
//! does with no input of its own. It
//! 1. imports the embedded models, prints their statistics and writes each as plain and as
//!    compressed GLB;
//! 2. computes the shape and texture descriptors of those models and of two seeds of a
//!    generated one, and prints every pair's differences against the calibrated Table 1;
//! 3. generates the Table 2 benchmark models and simplifies each to 20% of its expanded
//!    triangles with instance-aware simplification (IAS) and with the quadric baseline on the
//!    expanded mesh, printing time, output size and error side by side;
//! 4. generates the village world, builds its BVH and every aggregate (the offline rebuild),
//!    and cuts it for a viewer standing in it.

use std::path::Path;

use anyhow::Context;
use horizon_aggregate::AggregateOptions;
use horizon_bvh::{CutItem, CutQuery, DEFAULT_MU, DEFAULT_W};
use horizon_mesh::{export_glb, import_bytes, ExportOptions, Format, ImportOptions, MeshStats};
use horizon_server::outln;
use horizon_world::write_atomically;

/// Embedded default models (third-party; licences in `assets/models/`).
const MODELS: &[(&str, &[u8])] = &[
    (
        "SimpleInstancing",
        include_bytes!("../../assets/models/SimpleInstancing/SimpleInstancing.glb"),
    ),
    (
        "CesiumMilkTruck",
        include_bytes!("../../assets/models/CesiumMilkTruck/CesiumMilkTruck.glb"),
    ),
    (
        "NegativeScaleTest",
        include_bytes!("../../assets/models/NegativeScaleTest/NegativeScaleTest.glb"),
    ),
];

/// Runs the demo and writes its output under `out`.
pub fn run(out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    outln!(
        "{:<20} {:>9} {:>9} {:>10} {:>10} {:>10} {:>10}",
        "model",
        "submeshes",
        "instances",
        "tris uniq",
        "tris exp",
        "plain B",
        "compr. B"
    )?;
    for (name, bytes) in MODELS {
        let imported = import_bytes(bytes, Format::Glb, None, &ImportOptions::default())
            .with_context(|| format!("embedded model {name}"))?;
        let stats = MeshStats::of(&imported.mesh);
        let plain = export_glb(&imported.mesh, &ExportOptions::plain())?;
        let compressed = export_glb(&imported.mesh, &ExportOptions::compressed())?;
        write_atomically(&out.join(format!("{name}.glb")), &plain)?;
        write_atomically(&out.join(format!("{name}.compressed.glb")), &compressed)?;
        outln!(
            "{:<20} {:>9} {:>9} {:>10} {:>10} {:>10} {:>10}",
            name,
            stats.submeshes,
            stats.instances,
            stats.triangles_unique,
            stats.triangles_expanded,
            plain.len(),
            compressed.len()
        )?;
    }
    outln!("wrote plain and compressed GLB files to {}", out.display())?;
    descriptors()?;
    simplification(out)?;
    world(out)
}

/// Stage 4: the village world, generated, built, and cut for a viewer at its centre.
fn world(out: &Path) -> anyhow::Result<()> {
    outln!()?;
    outln!("the village world: generate, build the BVH and every aggregate, cut")?;
    let dir = out.join("village");
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("cannot clear {}", dir.display()))?;
    }
    let generated = horizon_server::generated::write_world("village", &dir, 1, &[])?;
    let status = generated.world.status()?;
    outln!(
        "village -> {}: {} objects, {} unique models",
        dir.display(),
        status.objects,
        status.models
    )?;
    let options = AggregateOptions::default();
    crate::world_cmd::build(&dir, DEFAULT_MU, DEFAULT_W, Some(options), false)?;
    let world = horizon_world::World::open(&dir)?;
    let bounds = world
        .with_tree(|t| t.bvh.node(t.bvh.root()).map(|n| n.aabb()))?
        .context("the village is empty")?;
    let centre = (bounds.min + bounds.max) * 0.5;
    let eye = glam::Vec3::new(centre.x, 2.0, centre.z);
    let cut = world.cut(&CutQuery {
        position: eye,
        min_solid_angle: options.min_solid_angle as f32,
        max_results: 4000,
    })?;
    let aggregates = cut
        .entries
        .iter()
        .filter(|e| matches!(e.item, CutItem::Aggregate(_)))
        .count();
    outln!(
        "a viewer at {eye} sees all {} objects as {} entries: {} objects as themselves, {} aggregates",
        world.status()?.objects,
        cut.entries.len(),
        cut.entries.len() - aggregates,
        aggregates
    )?;
    outln!(
        "(the join download against naive and unoptimised aggregates: horizon-lab report {})",
        dir.display()
    )?;
    Ok(())
}

/// Stage 2: descriptors of the embedded and generated models, and which pairs the calibrated
/// Table 1 would deduplicate at the smallest on-screen size.
fn descriptors() -> anyhow::Result<()> {
    use horizon_descriptors::calibrate::Table1;
    use horizon_descriptors::{describe, t_diff, z_diff, DescriptorOptions};
    outln!()?;
    outln!("descriptors (3D Zernike 121 + Color Structure 32), one core")?;
    let mut models = Vec::new();
    for (name, bytes) in MODELS {
        let mesh = import_bytes(bytes, Format::Glb, None, &ImportOptions::default())?.mesh;
        models.push(((*name).to_string(), mesh));
    }
    for seed in [1, 2] {
        models.push((
            format!("patio-chair#{seed}"),
            horizon_worldgen::generate_model("patio-chair", seed)?,
        ));
    }
    let mut described = Vec::new();
    for (name, mesh) in &models {
        let r = describe(mesh, &DescriptorOptions::default())?;
        outln!(
            "{:<20} {:>8} voxels {:>7.1} ms",
            name,
            r.voxels,
            r.seconds * 1e3
        )?;
        described.push((name, r.descriptors));
    }
    let table = Table1::calibrated();
    let smallest = table.rows.first().map_or(0.0, |r| r.max_solid_angle * 0.5);
    outln!("pair                                      z_diff   t_diff  dedup when tiny")?;
    for i in 0..described.len() {
        for j in i + 1..described.len() {
            let (a, b) = (&described[i], &described[j]);
            let (z, t) = (z_diff(&a.1, &b.1), t_diff(&a.1, &b.1));
            outln!(
                "{:<40} {:>8.4} {:>8.1}  {}",
                format!("{} / {}", a.0, b.0),
                z,
                t,
                if table.allows(smallest, z, t) {
                    "yes"
                } else {
                    "no"
                }
            )?;
        }
    }
    Ok(())
}

/// Stage 3: IAS against the quadric baseline on the generated Table 2 models.
fn simplification(out: &Path) -> anyhow::Result<()> {
    use horizon_simplify::{simplify, simplify_qem, SimplifyOptions, Target};
    outln!()?;
    outln!(
        "simplification to 20% of the expanded triangles (IAS vs quadric on the expanded mesh)"
    )?;
    outln!(
        "{:<13} {:>10} {:>8} {:>9} {:>9} {:>11} {:>11} {:>10} {:>10}",
        "model",
        "tris exp",
        "instances",
        "IAS s",
        "QEM s",
        "IAS B",
        "QEM B",
        "IAS err",
        "QEM err"
    )?;
    let options = SimplifyOptions::default();
    for name in horizon_worldgen::MODEL_NAMES {
        let mesh = horizon_worldgen::generate_model(name, 1)?;
        let diagonal = f64::from(mesh.bounds().diagonal()).max(f64::MIN_POSITIVE);
        let ias = simplify(&mesh, Target::Ratio(0.2), &options)?;
        let qem = simplify_qem(&mesh, Target::Ratio(0.2), &options)?;
        let ias_glb = export_glb(&ias.mesh, &ExportOptions::plain())?;
        let qem_glb = export_glb(&qem.mesh, &ExportOptions::plain())?;
        write_atomically(&out.join(format!("{name}.ias.glb")), &ias_glb)?;
        write_atomically(&out.join(format!("{name}.qem.glb")), &qem_glb)?;
        outln!(
            "{:<13} {:>10} {:>8} {:>9.3} {:>9.3} {:>11} {:>11} {:>10.2e} {:>10.2e}",
            name,
            ias.report.triangles_in,
            mesh.instances.len(),
            ias.report.seconds,
            qem.report.seconds,
            ias_glb.len(),
            qem_glb.len(),
            ias.report.error / diagonal,
            qem.report.error / diagonal,
        )?;
    }
    outln!("errors are quadric errors (RMS distance) over the bounding-box diagonal; wrote *.ias.glb and *.qem.glb")?;
    Ok(())
}

//! `horizon demo`: the main job on an embedded default, so a fresh clone shows what Horizon
//! does with no input of its own. For now (the mesh layer) it imports the embedded models,
//! prints their statistics and writes each as plain and as compressed GLB.

use std::path::Path;

use anyhow::Context;
use horizon_mesh::{export_glb, import_bytes, ExportOptions, Format, ImportOptions, MeshStats};

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
    println!(
        "{:<20} {:>9} {:>9} {:>10} {:>10} {:>10} {:>10}",
        "model", "submeshes", "instances", "tris uniq", "tris exp", "plain B", "compr. B"
    );
    for (name, bytes) in MODELS {
        let imported = import_bytes(bytes, Format::Glb, None, &ImportOptions::default())
            .with_context(|| format!("embedded model {name}"))?;
        let stats = MeshStats::of(&imported.mesh);
        let plain = export_glb(&imported.mesh, &ExportOptions::plain())?;
        let compressed = export_glb(&imported.mesh, &ExportOptions::compressed())?;
        crate::mesh_cmd::write_atomically(&out.join(format!("{name}.glb")), &plain)?;
        crate::mesh_cmd::write_atomically(
            &out.join(format!("{name}.compressed.glb")),
            &compressed,
        )?;
        println!(
            "{:<20} {:>9} {:>9} {:>10} {:>10} {:>10} {:>10}",
            name,
            stats.submeshes,
            stats.instances,
            stats.triangles_unique,
            stats.triangles_expanded,
            plain.len(),
            compressed.len()
        );
    }
    println!("wrote plain and compressed GLB files to {}", out.display());
    Ok(())
}

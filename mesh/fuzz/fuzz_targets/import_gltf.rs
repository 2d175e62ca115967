//! Fuzzes glTF/GLB import: any bytes must give a model or a typed error, never a panic, and
//! an accepted model must pass `validate()` and export.
#![no_main]

use horizon_mesh::{export_glb, import_bytes, ExportOptions, Format, ImageCheck, ImportOptions, Limits};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Small limits keep each run fast and make the limit paths reachable.
    let options = ImportOptions {
        limits: Limits {
            max_bytes: 1 << 22,
            max_triangles: 1 << 20,
            max_instances: 1 << 14,
            max_textures: 16,
            max_texture_pixels: 1 << 20,
        },
        images: ImageCheck::Decode,
    };
    let format = if data.starts_with(b"glTF") { Format::Glb } else { Format::Gltf };
    if let Ok(imported) = import_bytes(data, format, None, &options) {
        imported.mesh.validate().expect("an accepted model is valid");
        for compress in [false, true] {
            let glb = export_glb(&imported.mesh, &ExportOptions { compress, ..ExportOptions::plain() }).expect("exports");
            // What we write, we read back.
            import_bytes(&glb, Format::Glb, None, &options).expect("re-imports");
        }
    }
});

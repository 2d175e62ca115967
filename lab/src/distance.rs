//! `horizon-lab distance`: the symmetric Metro-style Hausdorff distance between two models,
//! each expanded into world space (vertex, edge and face samples; exact point-to-triangle
//! distance), the yardstick simplification is measured with.

use std::path::Path;

use horizon_mesh::{import_file, ImportOptions};
use horizon_server::outln;

/// Prints the symmetric Metro-style Hausdorff distance between two model files, each expanded
/// into world space.
pub fn run(a: &Path, b: &Path, samples: usize, json: bool) -> anyhow::Result<()> {
    let ma = import_file(a, &ImportOptions::default())?.mesh.expand();
    let mb = import_file(b, &ImportOptions::default())?.mesh.expand();
    let options = horizon_simplify::distance::DistanceOptions {
        samples,
        ..Default::default()
    };
    let report = horizon_simplify::distance::hausdorff(&ma, &mb, &options)?;
    if json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        outln!(
            "hausdorff {:.6e} ({:.4e} of the diagonal {:.4}); mean {:.4e} / {:.4e}; {:.3} s",
            report.hausdorff,
            report.hausdorff_rel_diag,
            report.diagonal,
            report.forward.mean,
            report.backward.mean,
            report.seconds
        )?;
    }
    Ok(())
}

//! Nodes placing each submesh's mesh at its instances: one EXT_mesh_gpu_instancing node, or a
//! node with a matrix per instance.
//!
//! A submesh with two or more instances that are all TRS is one GPU-instanced node, with
//! translation, rotation (float, or 16-bit normalized with short rotations) and scale streams,
//! an identity rotation or scale stream being left out. Otherwise each instance is a node with
//! a matrix, or, when the transform has shear (which a glTF matrix may not), a parent and child
//! pair from [`crate::transform::decompose_svd`]. Mirrored instances keep their negative
//! determinant, which glTF renderers answer by flipping the winding, as
//! [`InstancedMesh::expand`](crate::model::InstancedMesh::expand) does.
//!
//! Each submesh's stored positions map back to model space by its run's dequantisation, an
//! offset and a uniform step (`quantize.rs`). A GPU-instanced node carries the step as its own
//! uniform scale and each instance's translation absorbs the offset, so the instances'
//! rotations and scales are written unchanged (and an identity stream stays left out); a node
//! with a matrix takes the whole dequantisation into its matrix. Compression instead folds the
//! whole dequantisation into every instance: its streams are meshopt-encoded, where a constant
//! scale stream costs next to nothing.

use glam::{Affine3A, Mat4, Quat, Vec3, Vec4};
use serde_json::{json, Map, Value};

use super::attributes::float_attribute;
use super::json::numbers;
use super::quantize::{norm16_attribute, snorm16, Dequantize};
use super::writer::GlbWriter;
use crate::error::ExportError;
use crate::transform::{decompose_svd, decompose_trs, Trs};

impl GlbWriter {
    /// The nodes placing submesh `s` by `placed[s]`, its stored positions mapped back by
    /// `dequantize[s]`: one GPU-instanced node scaled by the step, or matrix nodes.
    pub(super) fn write_nodes(
        &mut self,
        placed: &[Vec<Affine3A>],
        dequantize: &[Dequantize],
    ) -> Result<(), ExportError> {
        for (s, (placed, d)) in placed.iter().zip(dequantize).enumerate() {
            // Compression folds the whole dequantisation into every placement: its instance
            // streams are meshopt-encoded, where a constant scale stream costs next to nothing
            // and translations divided by the step would compress worse.
            let folded: Vec<Affine3A>;
            let instances = if self.compress {
                folded = placed.iter().map(|t| *t * d.affine()).collect();
                &folded
            } else {
                placed
            };
            // The positions are quantized only where every form here stays finite, so this
            // needs an instance transform that was not finite to begin with.
            if !instances.iter().all(Affine3A::is_finite) {
                return Err(ExportError::Encode(format!(
                    "submesh {s}: transform overflows f32"
                )));
            }
            let all_trs: Option<Vec<Trs>> = instances.iter().map(decompose_trs).collect();
            match all_trs {
                Some(trs) if trs.len() >= 2 && self.compress => {
                    self.write_gpu_instanced_node(s, &trs, 1.0)?;
                }
                Some(mut trs) if trs.len() >= 2 => {
                    for x in &mut trs {
                        let read = if self.short_rotations {
                            read_back_rotation(x.rotation)
                        } else {
                            x.rotation
                        };
                        x.translation = d.instance_translation(x, read);
                    }
                    self.write_gpu_instanced_node(s, &trs, d.step)?;
                }
                _ => {
                    for t in placed {
                        self.write_matrix_node(s, &(*t * d.affine()));
                    }
                }
            }
        }
        Ok(())
    }

    /// One node drawing `mesh` at every transform of `trs`, itself scaled by `scale` (the
    /// positions' dequantisation step; 1 for float positions).
    fn write_gpu_instanced_node(
        &mut self,
        mesh: usize,
        trs: &[Trs],
        scale: f32,
    ) -> Result<(), ExportError> {
        self.extensions_used.insert("EXT_mesh_gpu_instancing");
        // Every attribute is optional: a rotation or scale that is the identity for every
        // instance (to float precision) is left out.
        let mut attributes = Map::new();
        let t = float_attribute(trs.iter().map(|x| x.translation.to_array()), false);
        attributes.insert("TRANSLATION".into(), json!(self.write_attribute(&t, None)?));
        if !trs
            .iter()
            .all(|x| x.rotation.abs_diff_eq(Quat::IDENTITY, 1e-7))
        {
            let rotations = trs.iter().map(|x| x.rotation.to_array());
            let r = if self.short_rotations {
                norm16_attribute(rotations, true)
            } else {
                float_attribute(rotations, false)
            };
            attributes.insert("ROTATION".into(), json!(self.write_attribute(&r, None)?));
        }
        if !trs.iter().all(|x| x.scale.abs_diff_eq(Vec3::ONE, 1e-7)) {
            let s = float_attribute(trs.iter().map(|x| x.scale.to_array()), false);
            attributes.insert("SCALE".into(), json!(self.write_attribute(&s, None)?));
        }
        let mut node = Map::new();
        node.insert("mesh".into(), json!(mesh));
        if scale != 1.0 {
            node.insert("scale".into(), numbers(&[scale; 3]));
        }
        node.insert(
            "extensions".into(),
            json!({"EXT_mesh_gpu_instancing": {"attributes": attributes}}),
        );
        self.nodes.push(Value::Object(node));
        self.roots.push(self.nodes.len() - 1);
        Ok(())
    }

    /// One node with a matrix, or a parent and child pair when the transform has shear.
    fn write_matrix_node(&mut self, mesh: usize, world: &Affine3A) {
        let matrix = |a: &Affine3A| numbers(&Mat4::from(*a).to_cols_array());
        if decompose_trs(world).is_some() {
            self.nodes
                .push(json!({ "mesh": mesh, "matrix": matrix(world) }));
            self.roots.push(self.nodes.len() - 1);
        } else if let Some((parent, child)) = decompose_svd(world) {
            self.nodes.push(json!({
                "mesh": mesh,
                "matrix": matrix(&Affine3A::from_quat(child)),
            }));
            let child_index = self.nodes.len() - 1;
            self.nodes.push(json!({
                "matrix": matrix(&parent.to_affine()),
                "children": [child_index],
            }));
            self.roots.push(self.nodes.len() - 1);
        } else {
            // Shear with singular values past f32's range: no TRS pair can hold it, so keep the
            // matrix itself. The transform survives; a strict validator flags the node.
            self.nodes
                .push(json!({ "mesh": mesh, "matrix": matrix(world) }));
            self.roots.push(self.nodes.len() - 1);
        }
    }
}

/// A rotation as a reader decodes it from normalized 16-bit integers
/// ([`norm16_attribute`]): each component rounded to a multiple of 1/32767, the whole
/// normalised again.
fn read_back_rotation(q: Quat) -> Quat {
    let round = |x: f32| f32::from(snorm16(x)) / 32767.0;
    let back = Vec4::new(round(q.x), round(q.y), round(q.z), round(q.w));
    back.try_normalize().map_or(q, Quat::from_vec4)
}

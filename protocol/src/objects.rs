//! Objects: placing, moving, deleting, reading and paging them.

use serde::{Deserialize, Serialize};

/// `POST /v1/objects`: a model placed in the world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct NewObject {
    /// The model's id.
    pub model: String,
    /// Where its origin goes, world space.
    pub translation: [f32; 3],
    /// Its rotation, a unit quaternion `[x, y, z, w]`. Default: none.
    #[serde(default = "identity_rotation")]
    pub rotation: [f32; 4],
    /// Its scale: one positive number, or one per axis. Default 1.
    #[serde(default)]
    pub scale: Scale,
}

/// A move: the parts of the placement to change.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ObjectPatch {
    /// The new translation.
    #[serde(default)]
    pub translation: Option<[f32; 3]>,
    /// The new rotation, a unit quaternion `[x, y, z, w]`.
    #[serde(default)]
    pub rotation: Option<[f32; 4]>,
    /// The new scale.
    #[serde(default)]
    pub scale: Option<Scale>,
}

/// A scale: uniform, or per axis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(untagged)]
pub enum Scale {
    /// The same factor on every axis.
    Uniform(f32),
    /// A factor per axis.
    PerAxis([f32; 3]),
}

impl Default for Scale {
    fn default() -> Self {
        Self::Uniform(1.0)
    }
}

impl Scale {
    /// The factor per axis.
    pub fn per_axis(self) -> [f32; 3] {
        match self {
            Self::Uniform(s) => [s; 3],
            Self::PerAxis(s) => s,
        }
    }
}

fn identity_rotation() -> [f32; 4] {
    [0.0, 0.0, 0.0, 1.0]
}

/// An object as the world holds it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ObjectInfo {
    /// The object's id.
    pub id: u64,
    /// Its model's id.
    pub model: String,
    /// Who placed it (none for objects a generator or an import placed).
    pub owner: Option<String>,
    /// Its translation.
    pub translation: [f32; 3],
    /// Its rotation, `[x, y, z, w]`.
    pub rotation: [f32; 4],
    /// Its scale per axis.
    pub scale: [f32; 3],
    /// The generation that last placed or moved it.
    pub generation: u64,
}

/// What placing an object answers (201).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Created {
    /// The new object's id.
    pub id: u64,
    /// The generation that placed it.
    pub generation: u64,
}

/// What deleting an object answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Deleted {
    /// The deleted object's id.
    pub id: u64,
    /// The generation that deleted it.
    pub generation: u64,
}

/// One page of `GET /v1/objects`, in id order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ObjectPage {
    /// The objects of the page.
    pub objects: Vec<ObjectInfo>,
    /// The `after` of the next page; none on the last.
    pub next: Option<u64>,
}

/// `POST /v1/objects/batch`: operations applied all or nothing, in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct BatchRequest {
    /// The operations.
    pub ops: Vec<BatchOp>,
}

/// One operation of a batch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum BatchOp {
    /// Place a new object.
    Create(NewObject),
    /// Move one of the caller's objects: the parts of its placement named change.
    Move {
        /// The object.
        id: u64,
        /// The new translation.
        #[serde(default)]
        translation: Option<[f32; 3]>,
        /// The new rotation, a unit quaternion `[x, y, z, w]`.
        #[serde(default)]
        rotation: Option<[f32; 4]>,
        /// The new scale.
        #[serde(default)]
        scale: Option<Scale>,
    },
    /// Delete one of the caller's objects.
    Delete {
        /// The object.
        id: u64,
    },
}

/// What a batch answers: the generation that applied it, and per operation the object it
/// touched, in order.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct BatchResponse {
    /// The generation of the batch's last operation.
    pub generation: u64,
    /// The object of each operation.
    pub ids: Vec<u64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_object_takes_defaults_and_either_scale() {
        let o: NewObject =
            serde_json::from_str(r#"{"model": "m", "translation": [1, 2, 3]}"#).expect("parse");
        assert_eq!(o.rotation, [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(o.scale.per_axis(), [1.0; 3]);
        let o: NewObject =
            serde_json::from_str(r#"{"model": "m", "translation": [0, 0, 0], "scale": [1, 2, 3]}"#)
                .expect("parse");
        assert_eq!(o.scale.per_axis(), [1.0, 2.0, 3.0]);
        assert!(
            serde_json::from_str::<NewObject>(r#"{"model": "m", "translation": [0, 0]}"#).is_err()
        );
        assert!(serde_json::from_str::<NewObject>(
            r#"{"model": "m", "translation": [0, 0, 0], "colour": 1}"#
        )
        .is_err());
    }

    #[test]
    fn batch_operations_are_tagged() {
        let b: BatchRequest = serde_json::from_str(
            r#"{"ops": [
                {"op": "create", "model": "m", "translation": [0, 0, 0]},
                {"op": "move", "id": 4, "translation": [1, 1, 1]},
                {"op": "delete", "id": 5}
            ]}"#,
        )
        .expect("parse");
        assert_eq!(b.ops.len(), 3);
        assert!(matches!(b.ops[1], BatchOp::Move { id: 4, .. }));
        assert_eq!(b.ops[2], BatchOp::Delete { id: 5 });
        for typo in [
            r#"{"ops": [{"op": "move", "id": 1, "translate": [5, 5, 5]}]}"#,
            r#"{"ops": [{"op": "delete", "id": 1, "colour": 1}]}"#,
            r#"{"ops": [{"op": "create", "model": "m", "translation": [0, 0, 0], "x": 1}]}"#,
        ] {
            assert!(
                serde_json::from_str::<BatchRequest>(typo).is_err(),
                "{typo}"
            );
        }
    }
}

//! The BVH's input of a built world, held for benchmarks that build many trees from it.

use std::sync::Arc;

use anyhow::Context;
use glam::Affine3A;
use horizon_bvh::NewObject;
use horizon_world::{new_object, Describe, ModelDescriptors, World};

/// Every object of a world with its model's descriptors, in id order.
#[derive(Debug)]
pub struct BvhInput {
    objects: Vec<(u64, Affine3A)>,
    descriptors: Vec<Arc<ModelDescriptors>>,
}

impl BvhInput {
    /// The objects of `world`, whose models must be described (`horizon build`).
    pub fn of(world: &World) -> anyhow::Result<Self> {
        let objects: Vec<(u64, Affine3A)> = world
            .bulk_input()?
            .into_iter()
            .map(|(_, model, transform)| (model, transform))
            .collect();
        let descriptors = objects
            .iter()
            .map(|&(model, _)| world.models().descriptors_of(model))
            .collect::<Result<_, _>>()
            .with_context(|| {
                format!(
                    "{} is not built (run horizon build)",
                    world.root().display()
                )
            })?;
        Ok(Self {
            objects,
            descriptors,
        })
    }

    /// The objects as the BVH takes them.
    pub fn objects(&self) -> Vec<NewObject<'_>> {
        self.objects
            .iter()
            .zip(&self.descriptors)
            .map(|(&(model, transform), d)| new_object(model, transform, d))
            .collect()
    }
}

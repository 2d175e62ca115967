//! A CPU ray caster for Horizon's meshes, and the image measures that compare two renders.
//!
//! The ray caster draws what a glTF client draws, closely enough to compare two ways of
//! showing one world: a two-level BVH (obvhs compressed wide BVHs, one per submesh, and one
//! over every placed submesh), glTF's front faces and `doubleSided`, `MASK` alpha, base colour
//! factors, textures sampled trilinearly from a mip chain with the footprint of the pixel (as
//! a GPU picks its mip level), vertex colours, and one fixed sun with ambient light.
//! [`compare`] holds PSNR, SSIM (Wang et al. 2004) and the hole measure.
//!
//! [`orthoview`] renders the orthographic depth images of Chaudhuri et al. 2009 with it and
//! composites a parent's from its children's; `horizon-aggregate` builds every node's in the
//! rebuild and the server's cut sends them as the far field.

pub mod camera;
pub mod compare;
pub mod frame;
pub mod orthoview;
pub mod scene;
mod shade;

pub use camera::Camera;
pub use compare::{compare, Comparison};
pub use frame::Frame;
pub use orthoview::{
    canonical_directions, facing, node_resolution, resolution, Orthoview, MAX_Q, MIN_Q,
    VIEWS_SERVED, WORLD_DIRECTIONS, WORLD_THETA,
};
pub use scene::{PreparedMesh, Scene, SceneBuilder, Surface};
pub use shade::{from_srgb, to_srgb};

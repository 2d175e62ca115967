//! One module per benchmark model of the IAS paper's Table 2 (Azim et al. 2014).

pub mod maple_tree;
pub mod patio_chair;
pub mod stonehenge;
pub mod village_mesh;

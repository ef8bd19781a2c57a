//! The ProcNet dataset generator: seeded cell episodes rendered into occluded frame
//! sequences, written in the format of [`workcell_render::dataset`] (re-exported here).

mod config;
mod generate;

pub use config::{DatasetConfig, DistanceClass, OcclusionLevel, RoiConfig};
pub use generate::{
    CropFactory, CropPolicy, GeneratedFrame, GeneratedSequence, Generator, PolicyError, Report,
    Timing,
};
pub use workcell_render::dataset::*;

//! The ProcNet dataset: sequences of camera frames of seeded cell episodes, with ground truth
//! and controlled occlusion, as the paper made its data.
//!
//! Layout of a dataset folder:
//!
//! ```text
//! manifest.json          format, configuration, scenario, classes, every sequence (seed,
//!                        distance class, occlusion level, split); written last
//! config.toml            the configuration and scenario it was made with
//! seq_00000/             one folder per sequence, renamed into place when complete
//!   sequence.json        its manifest entry
//!   frame_000_rgb.png    the network input: RGB with the occluder's pixels black
//!   frame_000_class.png  class per pixel without the occluder (what the network must see)
//!   frame_000_visible.png  class per pixel seen through the occluder (0 under it)
//!   frame_000_occluder.png 255 where the occluder covers
//!   frame_000_amodal.png   255 where the forearm rendered alone covers
//!   frame_000.json       labels: part poses in the camera frame, occlusion per part, camera
//! ```

mod config;
mod generate;
mod labels;
mod load;
mod sheet;

pub use config::{DatasetConfig, DistanceClass, OcclusionLevel};
pub use generate::{
    GeneratedFrame, GeneratedSequence, Generator, Report, Timing, frame_files, sequence_dir,
};
pub use labels::{
    CameraLabel, FORMAT, FrameLabels, Manifest, PartLabel, PoseLabel, SequenceEntry, Split,
};
pub use load::{Dataset, Sequence};
pub use sheet::contact_sheet;

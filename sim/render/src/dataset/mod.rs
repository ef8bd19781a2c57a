//! The dataset format: sequences of camera frames with ground truth and controlled occlusion,
//! as the paper made its data. `workcell-sim` writes them (its `dataset::Generator`); the
//! trainer and the evaluations read them through [`Dataset`], without the simulator.
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

mod labels;
mod load;
mod sheet;
mod stats;
#[cfg(any(test, feature = "test-util"))]
pub mod test_util;

pub use labels::{
    CameraLabel, FORMAT, FrameLabels, HumanLabel, Manifest, PartLabel, PoseLabel, READS, RoiLabel,
    SEES_THROUGH_OCCLUDER, SequenceEntry, Split, View, ViewSource,
};
pub use load::{Dataset, MAX_SEQUENCE_FRAMES, MAX_SEQUENCES, Sequence};
pub use sheet::{PredictionPanel, contact_sheet, prediction_sheet};
pub use stats::{ForearmStats, forearm_stats};

/// The folder of sequence `index`.
#[must_use]
pub fn sequence_dir(index: usize) -> String {
    format!("seq_{index:05}")
}

/// The file names of frame `f`: rgb, class, visible, occluder, amodal PNGs, the labels and
/// the depth PNG (16-bit, mm; from format 2 on).
#[must_use]
pub fn frame_files(f: usize) -> [String; 7] {
    [
        "rgb.png",
        "class.png",
        "visible.png",
        "occluder.png",
        "amodal.png",
        "json",
        "depth.png",
    ]
    .map(|s| {
        if s == "json" {
            format!("frame_{f:03}.json")
        } else {
            format!("frame_{f:03}_{s}")
        }
    })
}

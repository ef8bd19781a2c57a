//! Fixtures for the unit tests of the crates that read datasets (feature `test-util`).

use super::{SequenceEntry, Split, ViewSource};

/// The catalogue entry of a one-frame test sequence of the paper's short camera.
#[must_use]
pub fn one_frame_entry(occlusion_level: &str, mean_forearm_occlusion: f64) -> SequenceEntry {
    SequenceEntry {
        index: 0,
        dir: "seq_00000".into(),
        seed: 1,
        attempts: 1,
        distance_class: "short".into(),
        occlusion_level: occlusion_level.into(),
        source: ViewSource::Paper,
        split: Split::Test,
        frames: 1,
        mean_forearm_occlusion: Some(mean_forearm_occlusion),
        frames_without_forearm: 0,
        clip: None,
    }
}

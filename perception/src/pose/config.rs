//! Settings of the pose search.

/// Settings of the pose search.
// Serialize: the docs' stated defaults are checked against it (tests/defaults.rs).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PoseConfig {
    /// A fit whose gain is below this is no pose (and ends a track). Default 0.3.
    pub min_gain: f64,
    /// A fit that leaves more than this fraction of the mask's support farther than a pixel
    /// from the render is no pose (several blobs, say). Default 0.7.
    pub min_explained: f64,
    /// Climb iterations at most, per level of the coarse-to-fine schedule. Default 12.
    pub max_iterations: usize,
    /// First central-difference step, in pixels of image motion. Default 2.
    pub initial_step_px: f64,
    /// The climb stops when its step falls below this. Default 0.25.
    pub min_step_px: f64,
    /// Axis directions on the hemisphere tried by the global search. Default 64.
    pub directions: usize,
    /// Global hypotheses climbed. Default 4.
    pub refine: usize,
    /// Random probes per climb iteration, besides the 12 of the central difference.
    /// Default 12.
    pub random_probes: usize,
    /// Render only a region of interest around the mask (the previous pose included):
    /// its bounding box grown by 60 % of its size and at least 6 px per side. Default true.
    pub roi: bool,
    /// Mask values above this are the forearm's support. Default 0.5.
    pub threshold: f32,
}

impl Default for PoseConfig {
    fn default() -> Self {
        Self {
            min_gain: 0.3,
            min_explained: 0.7,
            max_iterations: 12,
            initial_step_px: 2.0,
            min_step_px: 0.25,
            directions: 64,
            refine: 4,
            random_probes: 12,
            roi: true,
            threshold: 0.5,
        }
    }
}

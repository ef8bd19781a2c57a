//! The humans of datasets: the model and base pose a dataset's manifest records, and the
//! arm models built from them. The dataset format stops here: the pose search and the
//! tracker take a human model and a pose.

use workcell_render::dataset::{Dataset, HumanLabel};
use workcell_robots::math::Pose;
use workcell_robots::{PackageMap, RobotModel};

use crate::error::{PerceptionError, Result};
use crate::pose::{ArmModel, ArticulatedArm};

impl ArmModel {
    /// The arm of the human a dataset shows (the model and base pose its manifest records).
    ///
    /// # Errors
    /// The manifest records no human (a dataset from before it did: regenerate it), the
    /// model does not load, or [`ArmModel::new`] fails.
    pub fn of_dataset(dataset: &Dataset) -> Result<Self> {
        let (model, X_WH) = dataset_human(dataset)?;
        Self::new(&model, &X_WH)
    }
}

impl ArticulatedArm {
    /// The arm of the human a dataset shows.
    ///
    /// # Errors
    /// As [`dataset_human`] and [`ArticulatedArm::new`].
    pub fn of_dataset(dataset: &Dataset) -> Result<Self> {
        let (human, X_WH) = dataset_human(dataset)?;
        Self::new(&human, &X_WH)
    }
}

/// The human a dataset shows: its model in the dataset's look (the visuals it was rendered
/// with) and its base pose, as the manifest records them.
///
/// # Errors
/// The manifest records no human (a dataset from before it did: regenerate it), or the
/// model does not load.
pub fn dataset_human(dataset: &Dataset) -> Result<(RobotModel, Pose)> {
    let human = dataset
        .manifest
        .human
        .as_ref()
        .ok_or_else(|| PerceptionError::Input {
            message: format!(
                "{}: the manifest records no human model (written by an older \
                 workcell); regenerate the dataset",
                dataset.root.join("manifest.json").display()
            ),
        })?;
    human_of(human)
}

/// The human a manifest's label names: its model in the look it was rendered in, and its
/// base pose.
///
/// # Errors
/// The model does not load.
pub fn human_of(human: &HumanLabel) -> Result<(RobotModel, Pose)> {
    let mut model = RobotModel::load(&human.model, &PackageMap::from_env())?;
    let look = human.look;
    model.retain_visuals(|g| look.shows(g.name.as_deref()));
    Ok((model, Pose::from(&human.X_WH)))
}

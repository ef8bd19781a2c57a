//! The rigid object searched for, and the anchor that pins its depth.

use std::sync::Arc;

use workcell_render::RenderMesh;
use workcell_robots::math::{Pose, Rotation, Vector};

use crate::error::{PerceptionError, Result};

/// The rigid object searched for: its render mesh and its axis.
#[derive(Debug, Clone)]
pub struct RigidModel {
    pub mesh: Arc<RenderMesh>,
    /// Centre of the mesh's bounding box, object frame.
    pub centre_O: Vector,
    /// Unit direction of the bounding box's longest side, object frame.
    pub axis_O: Vector,
    /// Length of that side, m.
    pub length_m: f64,
    /// Half the longer of the other two sides, m.
    pub half_width_m: f64,
    pub(super) corners_O: [Vector; 8],
}

impl RigidModel {
    /// The model of `mesh`, its axis the longest side of its bounding box.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] for an empty mesh or one with non-finite vertices.
    pub fn new(mesh: Arc<RenderMesh>) -> Result<Self> {
        let mut lo = Vector::splat(f64::INFINITY);
        let mut hi = Vector::splat(f64::NEG_INFINITY);
        for p in &mesh.positions {
            let p = Vector::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            lo = lo.min(p);
            hi = hi.max(p);
        }
        if mesh.is_empty() || !(lo.is_finite() && hi.is_finite()) {
            return Err(PerceptionError::Input {
                message: "the pose model's mesh is empty or not finite".into(),
            });
        }
        let size = hi - lo;
        let k = (0..3)
            .max_by(|&a, &b| size[a].total_cmp(&size[b]))
            .unwrap_or(2);
        let mut axis_O = Vector::ZERO;
        axis_O[k] = 1.0;
        let corners_O = std::array::from_fn(|i| {
            Vector::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        });
        Ok(Self {
            mesh,
            centre_O: 0.5 * (lo + hi),
            axis_O,
            length_m: size[k],
            half_width_m: 0.5
                * (0..3)
                    .filter(|&i| i != k)
                    .map(|i| size[i])
                    .fold(0.0, f64::max),
            corners_O,
        })
    }

    /// The pose of the object whose centre is at `centre_C` with rotation `R_CO`.
    #[must_use]
    pub fn pose(&self, centre_C: Vector, R_CO: Rotation) -> Pose {
        Pose::from_parts(centre_C - R_CO * self.centre_O, R_CO)
    }

    /// The object's centre at `X_CO`.
    #[must_use]
    pub fn centre(&self, X_CO: &Pose) -> Vector {
        X_CO.transform_point(self.centre_O)
    }

    /// The symmetric twin of `X_CO`: turned half a revolution about the axis through the
    /// centre perpendicular to the forearm's (the first other box axis), so its ends swap.
    /// Its mask differs from `X_CO`'s only by the forearm's small end-to-end asymmetries.
    #[must_use]
    pub fn twin(&self, X_CO: &Pose) -> Pose {
        let k = (0..3).find(|&i| self.axis_O[i] == 0.0).unwrap_or(0);
        let mut across = Vector::ZERO;
        across[k] = 1.0;
        let R = X_CO.rotation * Rotation::from_axis_angle(across, std::f64::consts::PI);
        self.pose(self.centre(X_CO), R)
    }
}

/// Where one point of the object must be: at `radius_m` from `point_C`. The forearm's elbow
/// end hangs from the shoulder by the upper arm, and the shoulder of a fixed-base human arm
/// is at a known place in the cell: this pins down the depth that the silhouette of a thin
/// forearm leaves open (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anchor {
    /// The object point, object frame (the elbow: the forearm link's origin).
    pub end_O: Vector,
    /// The sphere's centre (the shoulder), camera frame.
    pub point_C: Vector,
    pub radius_m: f64,
    /// A violation of this many metres costs as much as one mispredicted mask pixel.
    pub sigma_m: f64,
}

//! Math types shared by the workspace: poses and vectors in `f64`, the types of parry3d-f64
//! (glam underneath), so that collision queries take our poses without conversion.
//!
//! Frames follow the monogram notation: `X_WB` is the pose of frame B in frame W,
//! `p_WC` the position of point C in W.

pub use parry3d_f64::math::{Pose, Rotation, Vector};

/// Pose from a URDF `<origin xyz=".." rpy="..">`.
///
/// URDF's roll-pitch-yaw are fixed-axis rotations about X, then Y, then Z, so the rotation
/// matrix is `Rz(yaw) * Ry(pitch) * Rx(roll)` (URDF XML specification, `<origin>`).
#[must_use]
pub fn pose_from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Pose {
    let rotation = Rotation::from_euler(parry3d_f64::glamx::EulerRot::ZYX, rpy[2], rpy[1], rpy[0]);
    Pose::from_parts(Vector::new(xyz[0], xyz[1], xyz[2]), rotation)
}

/// The inverse of [`pose_from_xyz_rpy`]: `(xyz, rpy)` with yaw and roll in (-pi, pi] and
/// pitch in [-pi/2, pi/2].
#[must_use]
pub fn pose_to_xyz_rpy(pose: &Pose) -> ([f64; 3], [f64; 3]) {
    let (yaw, pitch, roll) = pose.rotation.to_euler(parry3d_f64::glamx::EulerRot::ZYX);
    (pose.translation.to_array(), [roll, pitch, yaw])
}

/// `true` when every component is finite.
#[must_use]
pub fn all_finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn rpy_is_fixed_axis_xyz() {
        // A pure yaw of 90 degrees maps the x axis to the y axis.
        let yaw = pose_from_xyz_rpy([0.0; 3], [0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        let v = yaw.transform_vector(Vector::X);
        assert_relative_eq!(v.y, 1.0, epsilon = 1e-12);
        // roll then pitch (fixed axes): Ry(pi/2) * Rx(pi/2) maps y to x.
        let rp = pose_from_xyz_rpy(
            [0.0; 3],
            [
                std::f64::consts::FRAC_PI_2,
                std::f64::consts::FRAC_PI_2,
                0.0,
            ],
        );
        let v = rp.transform_vector(Vector::Y);
        assert_relative_eq!(v.x, 1.0, epsilon = 1e-12);
    }

    #[test]
    fn rpy_round_trip() {
        let rpy = [0.3, -0.7, 2.1];
        let pose = pose_from_xyz_rpy([1.0, 2.0, 3.0], rpy);
        let (xyz, back) = pose_to_xyz_rpy(&pose);
        assert_eq!(xyz, [1.0, 2.0, 3.0]);
        for (a, b) in rpy.iter().zip(back) {
            assert_relative_eq!(*a, b, epsilon = 1e-12);
        }
    }
}

//! The pinhole camera.

use parry3d_f64::glamx::DMat3;
use workcell_robots::math::{Pose, Rotation, Vector};

use crate::error::{RenderError, Result};
use crate::pose_is_finite;

/// Largest image side accepted, px.
pub const MAX_SIDE_PX: u32 = 4096;

/// A pinhole camera: intrinsics in pixels and its pose in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Pose of the camera frame C (x right, y down, z forward) in the world.
    pub X_WC: Pose,
}

impl Camera {
    /// A camera at `eye` looking at `target`, with `up` appearing up in the image, square
    /// pixels and the principal point at the image centre.
    ///
    /// # Errors
    /// [`RenderError::InvalidRender`] for a size of zero or above 4096 px, a field of view
    /// outside (0, 180) degrees, non-finite numbers, `eye == target`, or `up` parallel to
    /// the viewing direction.
    pub fn look_at(
        eye: [f64; 3],
        target: [f64; 3],
        up: [f64; 3],
        width: u32,
        height: u32,
        fov_y_deg: f64,
    ) -> Result<Self> {
        let invalid = |message: String| RenderError::InvalidRender { message };
        check_size(width, height)?;
        if !(fov_y_deg.is_finite() && fov_y_deg > 0.0 && fov_y_deg < 180.0) {
            return Err(invalid(format!(
                "field of view {fov_y_deg} deg is not in (0, 180)"
            )));
        }
        let [eye, target, up] = [eye, target, up].map(Vector::from_array);
        if !(eye.is_finite() && target.is_finite() && up.is_finite()) {
            return Err(invalid("camera eye, target or up is not finite".into()));
        }
        let z = target - eye;
        if z.length() < 1e-9 {
            return Err(invalid("camera eye and target coincide".into()));
        }
        let z = z.normalize();
        let x = z.cross(up);
        if x.length() < 1e-9 * up.length().max(1e-300) || up.length() < 1e-12 {
            return Err(invalid(
                "camera up direction is zero or parallel to the viewing direction".into(),
            ));
        }
        let x = x.normalize();
        let y = z.cross(x);
        let rotation = Rotation::from_mat3(&DMat3::from_cols(x, y, z)).normalize();
        let fy = 0.5 * f64::from(height) / (0.5 * fov_y_deg.to_radians()).tan();
        Ok(Self {
            width,
            height,
            fx: fy,
            fy,
            cx: 0.5 * f64::from(width),
            cy: 0.5 * f64::from(height),
            X_WC: Pose::from_parts(eye, rotation),
        })
    }

    /// Checks that the camera can be rendered from.
    ///
    /// # Errors
    /// [`RenderError::InvalidRender`] naming what is wrong.
    pub fn validate(&self) -> Result<()> {
        check_size(self.width, self.height)?;
        let finite = [self.fx, self.fy, self.cx, self.cy]
            .iter()
            .all(|v| v.is_finite());
        if !finite || self.fx <= 0.0 || self.fy <= 0.0 || !pose_is_finite(&self.X_WC) {
            return Err(RenderError::InvalidRender {
                message: format!(
                    "camera intrinsics ({}, {}, {}, {}) or pose not finite and positive",
                    self.fx, self.fy, self.cx, self.cy
                ),
            });
        }
        Ok(())
    }

    /// Pixel coordinates `(u, v)` of a point in the camera frame (pixel centres at
    /// half-integers), or `None` behind the near plane.
    #[must_use]
    pub fn project(&self, p_C: Vector) -> Option<[f64; 2]> {
        (p_C.z >= super::NEAR_M).then(|| {
            [
                self.fx * p_C.x / p_C.z + self.cx,
                self.fy * p_C.y / p_C.z + self.cy,
            ]
        })
    }

    /// The point in the camera frame that pixel coordinates `(u, v)` (pixel centres at
    /// half-integers) show at depth `depth_m` along the optical axis: [`Camera::project`]'s
    /// inverse.
    #[must_use]
    pub fn point_at(&self, u: f64, v: f64, depth_m: f64) -> Vector {
        Vector::new(
            (u - self.cx) / self.fx * depth_m,
            (v - self.cy) / self.fy * depth_m,
            depth_m,
        )
    }

    /// The same camera with its image scaled to `width x height` (intrinsics scaled).
    ///
    /// # Errors
    /// As [`Camera::look_at`] for the size.
    pub fn resized(&self, width: u32, height: u32) -> Result<Self> {
        check_size(width, height)?;
        let (sx, sy) = (
            f64::from(width) / f64::from(self.width),
            f64::from(height) / f64::from(self.height),
        );
        Ok(Self {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            X_WC: self.X_WC,
        })
    }
}

fn check_size(width: u32, height: u32) -> Result<()> {
    if width == 0 || height == 0 || width > MAX_SIDE_PX || height > MAX_SIDE_PX {
        return Err(RenderError::InvalidRender {
            message: format!("image size {width}x{height} is not within 1..={MAX_SIDE_PX} px"),
        });
    }
    Ok(())
}

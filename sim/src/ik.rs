//! Inverse kinematics by damped least squares (Levenberg-Marquardt on the 6-D pose error).
//!
//! `dq = J^T (J J^T + lambda^2 I)^-1 e`, with `e` the translation error and the rotation
//! error as a rotation vector, both in the world frame (Buss, "Introduction to inverse
//! kinematics with Jacobian transpose, pseudoinverse and damped least squares methods", 2004).

use workcell_robots::math::{Pose, Vector};
use workcell_robots::{Jacobian, KinematicState, LinkId, RobotModel};

/// Options of [`solve_ik`]; defaults in [`IkOptions::default`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct IkOptions {
    /// Iterations per attempt. Default 200.
    pub max_iterations: usize,
    /// Damping lambda. Default 0.05.
    pub damping: f64,
    /// Accepted translation error, m. Default 1e-4.
    pub tolerance_m: f64,
    /// Accepted rotation error, rad. Default 1e-3.
    pub tolerance_rad: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            max_iterations: 200,
            damping: 0.05,
            tolerance_m: 1e-4,
            tolerance_rad: 1e-3,
        }
    }
}

/// Outcome of [`solve_ik`]: the configuration reached and its remaining errors.
#[derive(Debug, Clone, PartialEq)]
pub struct IkSolution {
    pub q: Vec<f64>,
    pub error_m: f64,
    pub error_rad: f64,
    pub converged: bool,
}

/// Moves `link` of `robot` (base at `X_WB`) to `X_WT`, starting from `q_seed` and staying in
/// the position limits. Returns the best configuration found, `converged` saying whether it
/// is within tolerance.
#[must_use]
pub fn solve_ik(
    robot: &RobotModel,
    X_WB: Pose,
    link: LinkId,
    X_WT: Pose,
    q_seed: &[f64],
    options: &IkOptions,
) -> IkSolution {
    let n = robot.dof();
    let limits = robot.position_limits();
    let mut q: Vec<f64> = q_seed
        .iter()
        .zip(&limits)
        .map(|(v, [lo, hi])| v.clamp(*lo, *hi))
        .collect();
    let mut state = KinematicState::new(robot);
    state.X_WB = X_WB;
    let mut jacobian = Jacobian::zeros(n);
    let mut best = IkSolution {
        q: q.clone(),
        error_m: f64::INFINITY,
        error_rad: f64::INFINITY,
        converged: false,
    };
    for _ in 0..options.max_iterations {
        if robot.forward_kinematics(&q, &mut state).is_err() {
            break;
        }
        let X_WL = *state.link_pose(link);
        let e_p = X_WT.translation - X_WL.translation;
        // Shortest rotation from the link to the target, as a rotation vector.
        let mut dr = X_WT.rotation * X_WL.rotation.inverse();
        if dr.w < 0.0 {
            dr = -dr;
        }
        let e_r = dr.to_scaled_axis();
        let (error_m, error_rad) = (e_p.length(), e_r.length());
        if error_m + 0.1 * error_rad < best.error_m + 0.1 * best.error_rad {
            best = IkSolution {
                q: q.clone(),
                error_m,
                error_rad,
                converged: false,
            };
        }
        if error_m < options.tolerance_m && error_rad < options.tolerance_rad {
            best.converged = true;
            return best;
        }
        robot.point_jacobian(&state, link, X_WL.translation, &mut jacobian);
        let e = [e_p.x, e_p.y, e_p.z, e_r.x, e_r.y, e_r.z];
        // A = J J^T + lambda^2 I (6 x 6, symmetric positive definite); solve A y = e.
        let mut a = [[0.0; 6]; 6];
        for col in jacobian.columns() {
            for r in 0..6 {
                for c in 0..6 {
                    a[r][c] += col[r] * col[c];
                }
            }
        }
        for (r, row) in a.iter_mut().enumerate() {
            row[r] += options.damping * options.damping;
        }
        let Some(y) = solve_spd6(a, e) else { break };
        for (i, col) in jacobian.columns().iter().enumerate() {
            let dq: f64 = (0..6).map(|r| col[r] * y[r]).sum();
            q[i] = (q[i] + dq.clamp(-0.5, 0.5)).clamp(limits[i][0], limits[i][1]);
        }
    }
    best
}

/// Solves `A x = b` for a symmetric positive definite 6 x 6 `A` by Cholesky factorisation.
fn solve_spd6(mut a: [[f64; 6]; 6], b: [f64; 6]) -> Option<[f64; 6]> {
    for j in 0..6 {
        let d = a[j][j] - (0..j).map(|k| a[j][k] * a[j][k]).sum::<f64>();
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        a[j][j] = d.sqrt();
        for i in j + 1..6 {
            a[i][j] = (a[i][j] - (0..j).map(|k| a[i][k] * a[j][k]).sum::<f64>()) / a[j][j];
        }
    }
    let mut y = [0.0; 6];
    for i in 0..6 {
        y[i] = (b[i] - (0..i).map(|k| a[i][k] * y[k]).sum::<f64>()) / a[i][i];
    }
    let mut x = [0.0; 6];
    for i in (0..6).rev() {
        x[i] = (y[i] - (i + 1..6).map(|k| a[k][i] * x[k]).sum::<f64>()) / a[i][i];
    }
    Some(x)
}

/// The tool orientation of pick-and-place: the tool's z axis pointing down (-z of the world),
/// its x axis along world x.
#[must_use]
pub fn tool_down(p_W: Vector) -> Pose {
    Pose::from_parts(
        p_W,
        workcell_robots::math::Rotation::from_rotation_x(std::f64::consts::PI),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_known_system() {
        let mut a = [[0.0; 6]; 6];
        for i in 0..6 {
            a[i][i] = 4.0;
            if i > 0 {
                a[i][i - 1] = 1.0;
                a[i - 1][i] = 1.0;
            }
        }
        let x_true = [1.0, -2.0, 3.0, 0.5, -1.0, 2.0];
        let mut b = [0.0; 6];
        for i in 0..6 {
            b[i] = (0..6).map(|k| a[i][k] * x_true[k]).sum();
        }
        let x = solve_spd6(a, b).expect("spd");
        for i in 0..6 {
            assert!((x[i] - x_true[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn reaches_a_pose_that_forward_kinematics_produced() {
        let robot = RobotModel::from_catalogue("iiwa14_kinematics").expect("catalogue");
        let tool = robot.link_id("tool0").expect("tool0");
        let q_goal = [0.4, 0.6, -0.3, -1.2, 0.2, 0.9, 0.1];
        let X_WT = *robot
            .fk(Pose::IDENTITY, &q_goal)
            .expect("fk")
            .link_pose(tool);
        let sol = solve_ik(
            &robot,
            Pose::IDENTITY,
            tool,
            X_WT,
            &[0.0, 0.3, 0.0, -0.8, 0.0, 0.5, 0.0],
            &IkOptions::default(),
        );
        assert!(sol.converged, "{sol:?}");
        let X = *robot
            .fk(Pose::IDENTITY, &sol.q)
            .expect("fk")
            .link_pose(tool);
        assert!((X.translation - X_WT.translation).length() < 1e-4);
    }
}

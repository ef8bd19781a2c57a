//! Static clutter: tables, boxes and shelves, as boxes in the world.

use workcell_robots::math::{Pose, Vector};

use crate::scenario::{ClutterConfig, ClutterKind};

/// A static box of the clutter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClutterBox {
    /// Pose of the box centre in the world.
    pub X_WC: Pose,
    /// Half extents, m.
    pub half_extents_m: [f64; 3],
}

/// The boxes of one clutter item: a solid box, or a shelf's posts and boards.
pub fn clutter_boxes(c: &ClutterConfig) -> Vec<ClutterBox> {
    let X_WS = c.pose.to_pose();
    let [sx, sy, sz] = c.size_m;
    match c.kind {
        ClutterKind::Box => vec![ClutterBox {
            X_WC: X_WS,
            half_extents_m: [sx / 2.0, sy / 2.0, sz / 2.0],
        }],
        ClutterKind::Shelf => {
            let post = 0.03_f64.min(sx / 4.0).min(sy / 4.0);
            let board = 0.02_f64.min(sz / (2.0 * c.boards as f64));
            let mut boxes = Vec::new();
            for (x, y) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                let p = Vector::new(x * (sx - post) / 2.0, y * (sy - post) / 2.0, 0.0);
                boxes.push(ClutterBox {
                    X_WC: X_WS * Pose::from_translation(p),
                    half_extents_m: [post / 2.0, post / 2.0, sz / 2.0],
                });
            }
            for k in 0..c.boards {
                let z = -sz / 2.0 + board / 2.0 + (sz - board) * k as f64 / (c.boards - 1) as f64;
                boxes.push(ClutterBox {
                    X_WC: X_WS * Pose::from_translation(Vector::new(0.0, 0.0, z)),
                    half_extents_m: [sx / 2.0, sy / 2.0, board / 2.0],
                });
            }
            boxes
        }
    }
}

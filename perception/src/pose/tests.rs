use std::sync::Arc;

use workcell_render::{Camera, CpuRenderer, MaskBatch, RenderMesh, Renderer};
use workcell_robots::math::{Pose, Rotation, Vector, pose_from_xyz_rpy};
use workcell_robots::{HumanLook, RobotModel};

use super::image::blobs;
use super::*;
use crate::error::PerceptionError;

/// The forearm of the built-in human arm in its skeletal look (two bones, 25 cm).
fn forearm() -> RigidModel {
    let mut human = RobotModel::from_catalogue("human_arm").expect("catalogue human");
    human.retain_visuals(|g| HumanLook::Skeletal.shows(g.name.as_deref()));
    let forearm = human
        .link_id("forearm")
        .expect("the human arm has a forearm");
    let mut mesh = RenderMesh::default();
    for g in &human.links()[forearm].visuals {
        mesh.append(
            &RenderMesh::from_geometry(g, [0.85, 0.72, 0.62]),
            &Pose::IDENTITY,
        );
    }
    RigidModel::new(Arc::new(mesh)).expect("mesh")
}

/// A 128x128 camera with the field of view the dataset uses at `distance_m`.
fn camera(fov_y_deg: f64) -> Camera {
    Camera::look_at(
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, -1.0, 0.0],
        128,
        128,
        fov_y_deg,
    )
    .expect("camera")
}

fn render(model: &RigidModel, camera: &Camera, X: &[Pose]) -> Vec<Vec<f32>> {
    let mut batch = MaskBatch::new();
    CpuRenderer::new()
        .render_masks(&model.mesh, camera, X, &mut batch)
        .expect("render");
    (0..X.len())
        .map(|k| batch.mask(k).iter().map(|&v| f32::from(v)).collect())
        .collect()
}

fn estimator(model: &RigidModel) -> PoseEstimator<CpuRenderer> {
    PoseEstimator::new(CpuRenderer::new(), model.clone(), PoseConfig::default())
}

#[test]
fn f_m_is_one_minus_twice_the_disagreement_for_binary_masks() {
    let m: Vec<f32> = (0..100).map(|i| f32::from(u8::from(i % 3 == 0))).collect();
    let mut r: Vec<u8> = m.iter().map(|&v| v as u8).collect();
    assert_eq!(f_m(&m, &r), 1.0);
    // 7 pixels flipped out of 100.
    for v in r.iter_mut().take(7) {
        *v = 1 - *v;
    }
    assert!((f_m(&m, &r) - (1.0 - 2.0 * 0.07)).abs() < 1e-12);
    let complement: Vec<u8> = m.iter().map(|&v| 1 - v as u8).collect();
    assert_eq!(f_m(&m, &complement), -1.0);
    // An undecided mask agrees with nothing and contradicts nothing.
    assert_eq!(f_m(&[0.5; 100], &r), 0.0);
}

#[test]
fn the_forearm_model_is_its_bones_bounding_box() {
    let model = forearm();
    // Elbow sphere top at z = -0.01 + 0.009, wrist sphere bottom at -0.2455 - 0.009
    // (robots/urdf/human_arm/human_arm.urdf), tessellated within f32.
    assert_eq!(model.axis_O, Vector::Z);
    assert!((model.length_m - 0.2535).abs() < 1e-4, "{}", model.length_m);
    assert!(
        (model.centre_O.z - (-0.12775)).abs() < 1e-4,
        "{}",
        model.centre_O
    );
    // The twin keeps the centre and reverses the axis.
    let X = pose_from_xyz_rpy([0.1, -0.2, 2.0], [0.3, -0.4, 1.1]);
    let T = model.twin(&X);
    assert!((model.centre(&T) - model.centre(&X)).length() < 1e-12);
    let (a, b) = (X.rotation * model.axis_O, T.rotation * model.axis_O);
    assert!((a + b).length() < 1e-12);
}

/// Asserts what a maximiser of the search's score must give on `mask`: a fit at least as
/// good as the truth's, to two pixels' worth; the centre within two pixels across the view; and the forearm's
/// direction in the image within `axis_deg`. Depth and the tilt out of the image plane trade
/// off against each other on a 20-pixel forearm (the projected length is `f L cos(tilt) / z`),
/// so they are bounded through the fit, not asserted.
fn check_fit(
    model: &RigidModel,
    cam: &Camera,
    mask: &[f32],
    found: &PoseEstimate,
    truth: &Pose,
    axis_deg: f64,
) {
    let renders = render(model, cam, &[found.X_CO]);
    let as_u8 = |m: &[f32]| m.iter().map(|&v| v as u8).collect::<Vec<u8>>();
    assert!(
        (f_m(mask, &as_u8(&renders[0])) - found.f_m).abs() < 1e-12,
        "f_m is reported over the whole image"
    );
    let truth_gain = estimator(model).gain_at(cam, mask, truth).expect("score");
    let pixels = mask.iter().filter(|&&v| v > 0.5).count() as f64;
    assert!(
        found.gain >= truth_gain - 2.0 / pixels,
        "found gain {} below the truth's {truth_gain}",
        found.gain
    );
    check_placement(model, cam, found, truth, axis_deg);
}

/// The centre within two pixels across the view, the forearm's direction in the image within
/// `axis_deg`, and nearly all of the mask explained.
fn check_placement(
    model: &RigidModel,
    cam: &Camera,
    found: &PoseEstimate,
    truth: &Pose,
    axis_deg: f64,
) {
    assert!(found.explained >= 0.9, "explained {}", found.explained);
    let (c, t) = (model.centre(&found.X_CO), model.centre(truth));
    let ([u0, v0], [u1, v1]) = (
        cam.project(c).expect("in view"),
        cam.project(t).expect("in view"),
    );
    assert!(
        (u0 - u1).hypot(v0 - v1) < 2.0,
        "centre {u0},{v0} vs {u1},{v1}"
    );
    let end = |X: &Pose| {
        let a = X.transform_point(model.centre_O + 0.5 * model.length_m * model.axis_O);
        let b = X.transform_point(model.centre_O - 0.5 * model.length_m * model.axis_O);
        let (pa, pb) = (
            cam.project(a).expect("in view"),
            cam.project(b).expect("in view"),
        );
        (pa[1] - pb[1]).atan2(pa[0] - pb[0])
    };
    let d = end(&found.X_CO) - end(truth);
    // Directions, not senses: the forearm is symmetric end for end.
    let d = (2.0 * d).sin().atan2((2.0 * d).cos()).abs().to_degrees() / 2.0;
    assert!(d < axis_deg, "image direction off by {d} deg");
    assert!(found.uncertainty_m > 0.0 && found.uncertainty_m.is_finite());
}

#[test]
fn a_rendered_forearm_is_found_without_a_prior() {
    let model = forearm();
    // (centre, rpy, field of view): the dataset's short, medium and large classes.
    let cases = [
        ([0.05, -0.02, 2.0], [0.4, 1.2, 0.3], 45.0),
        ([-0.1, 0.08, 2.5], [1.3, 0.2, -0.7], 45.0),
        ([0.2, 0.1, 4.5], [-0.6, 0.5, 2.0], 24.0),
        ([-0.3, 0.2, 8.0], [1.0, -0.3, 0.9], 14.0),
    ];
    for (centre, rpy, fov) in cases {
        let cam = camera(fov);
        let R = pose_from_xyz_rpy([0.0; 3], rpy).rotation;
        let truth = model.pose(Vector::from_array(centre), R);
        let mask = &render(&model, &cam, &[truth])[0];
        let mut e = estimator(&model);
        let found = e.estimate(&cam, mask).expect("estimate").expect("a pose");
        assert!(found.reacquired);
        check_fit(&model, &cam, mask, &found, &truth, 10.0);
        // Depth to within the length's pixel resolution, twice over: a length of n pixels
        // gives z to about z / n.
        let z = centre[2];
        let length_px = model.length_m * cam.fy / z;
        let err = model.centre(&found.X_CO) - model.centre(&truth);
        assert!(err.z.abs() < 4.0 * z / length_px, "{centre:?}: depth {err}");
    }
}

#[test]
fn tracking_climbs_back_from_a_displaced_prior() {
    let model = forearm();
    let cam = camera(45.0);
    let R = pose_from_xyz_rpy([0.0; 3], [0.2, 1.0, -0.4]).rotation;
    let truth = model.pose(Vector::new(0.1, 0.05, 2.2), R);
    let mask = &render(&model, &cam, &[truth])[0];
    let mut e = estimator(&model);
    // The previous frame's pose: 3.7 cm and 6 degrees away.
    let displaced = model.pose(
        model.centre(&truth) + Vector::new(0.03, -0.015, 0.02),
        Rotation::from_axis_angle(Vector::new(0.0, 1.0, 1.0).normalize(), 0.1) * R,
    );
    e.set_prior(&displaced);
    let found = e.estimate(&cam, mask).expect("estimate").expect("a pose");
    assert!(!found.reacquired, "the climb should not lose the track");
    check_fit(&model, &cam, mask, &found, &truth, 10.0);
    // Tracking renders far fewer masks than a global search.
    let mut cold = estimator(&model);
    let global = cold
        .estimate(&cam, mask)
        .expect("estimate")
        .expect("a pose");
    assert!(
        found.renders < global.renders,
        "{} vs {}",
        found.renders,
        global.renders
    );
}

#[test]
fn masks_without_a_forearm_give_no_pose_and_no_panic() {
    let model = forearm();
    let cam = camera(45.0);
    let mut e = estimator(&model);
    let n = 128 * 128;
    assert_eq!(
        e.estimate(&cam, &vec![0.0; n]).expect("estimate"),
        Err(NoPose::Empty)
    );
    let mut nan = vec![0.0; n];
    nan[4000] = f32::NAN;
    assert_eq!(
        e.estimate(&cam, &nan).expect("estimate"),
        Err(NoPose::NotAProbability)
    );
    assert_eq!(
        e.estimate(&cam, &vec![1.5; n]).expect("estimate"),
        Err(NoPose::NotAProbability)
    );
    assert!(matches!(
        e.estimate(&cam, &vec![0.0; 100]),
        Err(PerceptionError::Input { .. })
    ));
    // Two forearms far apart in one mask: no single pose explains both.
    let R = pose_from_xyz_rpy([0.0; 3], [0.0, 1.5, 0.3]).rotation;
    let a = model.pose(Vector::new(-0.45, -0.3, 2.0), R);
    let b = model.pose(Vector::new(0.45, 0.35, 2.0), R);
    let masks = render(&model, &cam, &[a, b]);
    let both: Vec<f32> = masks[0]
        .iter()
        .zip(&masks[1])
        .map(|(x, y)| x.max(*y))
        .collect();
    assert_eq!(
        e.estimate(&cam, &both).expect("estimate"),
        Err(NoPose::SeveralBlobs { blobs: 2 })
    );
}

#[test]
fn a_forearm_cut_in_two_by_an_occluder_is_still_one_pose() {
    let model = forearm();
    let cam = camera(45.0);
    let R = pose_from_xyz_rpy([0.0; 3], [0.0, 1.5, 0.3]).rotation;
    let truth = model.pose(Vector::new(0.0, 0.0, 1.8), R);
    let mut mask = render(&model, &cam, &[truth]).remove(0);
    // A 3-pixel vertical bar through the forearm's centre.
    let [u, _] = cam.project(model.centre(&truth)).expect("in view");
    let u = u as usize;
    for y in 0..128 {
        for x in u - 1..=u + 1 {
            mask[y * 128 + x] = 0.0;
        }
    }
    assert_eq!(blobs(&mask, 128, 0.5), 2);
    let found = estimator(&model)
        .estimate(&cam, &mask)
        .expect("estimate")
        .expect("a pose");
    // Placement only: on a cut mask the climb may end a few pixels' worth below the truth.
    check_placement(&model, &cam, &found, &truth, 10.0);
}

#[test]
fn the_search_over_the_whole_image_fits_as_well() {
    let model = forearm();
    let cam = camera(24.0);
    let R = pose_from_xyz_rpy([0.0; 3], [0.7, 0.9, -1.2]).rotation;
    let truth = model.pose(Vector::new(0.15, -0.1, 4.0), R);
    let mask = &render(&model, &cam, &[truth])[0];
    let config = PoseConfig {
        roi: false,
        ..PoseConfig::default()
    };
    let mut full = PoseEstimator::new(CpuRenderer::new(), model.clone(), config);
    let found = full.estimate(&cam, mask).expect("estimate").expect("pose");
    check_fit(&model, &cam, mask, &found, &truth, 10.0);
}

/// A forearm whose ends lie on the same two camera rays as `X`'s, its elbow end `delta_m`
/// farther along its ray and its wrist end at the other of the two points of its ray a
/// forearm's length away: the family a thin rod's silhouette cannot tell apart. At
/// `delta_m = 0` it is `X`'s mirror about the elbow's ray.
fn same_rays(model: &RigidModel, X: &Pose, delta_m: f64) -> Pose {
    let half = 0.5 * model.length_m * model.axis_O;
    let (p1, p2) = (
        X.transform_point(model.centre_O + half),
        X.transform_point(model.centre_O - half),
    );
    let (r1, r2) = (p1.normalize(), p2.normalize());
    let a = p1.length() + delta_m;
    let c = r1.dot(r2);
    let b = a * c + (model.length_m.powi(2) - a * a * (1.0 - c * c)).sqrt();
    let (q1, q2) = (a * r1, b * r2);
    let axis = (q1 - q2).normalize();
    let R = Rotation::from_rotation_arc(X.rotation * model.axis_O, axis) * X.rotation;
    model.pose(0.5 * (q1 + q2), R)
}

#[test]
fn a_thin_forearm_s_mask_leaves_its_depth_open() {
    // Why the estimator takes an anchor: at the dataset's scale (a 25 cm forearm 20-odd
    // pixels long, its bones under two pixels thick) poses 20 cm apart in depth render masks
    // that differ in a handful of pixels.
    let model = forearm();
    let cam = camera(45.0);
    let X = model.pose(
        Vector::new(0.05, 0.0, 2.3),
        pose_from_xyz_rpy([0.0; 3], [0.3, 0.9, 0.2]).rotation,
    );
    let Y = same_rays(&model, &X, 0.2);
    let moved = (model.centre(&Y) - model.centre(&X)).length();
    assert!(moved > 0.15, "{moved}");
    let masks = render(&model, &cam, &[X, Y]);
    let pixels = masks[0].iter().filter(|&&v| v > 0.5).count();
    let differ = masks[0]
        .iter()
        .zip(&masks[1])
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        pixels > 15 && differ * 4 < pixels,
        "{differ} of {pixels} pixels differ"
    );
}

#[test]
fn an_anchored_elbow_recovers_the_depth_up_to_the_wrist_s_mirror() {
    let model = forearm();
    let cam = camera(45.0);
    let R = pose_from_xyz_rpy([0.0; 3], [0.3, 0.9, 0.2]).rotation;
    let truth = model.pose(Vector::new(0.05, 0.0, 2.3), R);
    let mask = &render(&model, &cam, &[truth])[0];
    // A shoulder 0.3255 m from the elbow (the human arm's upper arm), off to one side.
    let elbow = truth.transform_point(Vector::ZERO);
    let shoulder = elbow + 0.3255 * Vector::new(0.6, -0.48, 0.64).normalize();
    let mut e = estimator(&model);
    e.set_anchor(Some(Anchor {
        end_O: Vector::ZERO,
        point_C: shoulder,
        radius_m: 0.3255,
        sigma_m: 0.02,
    }));
    let found = e.estimate(&cam, mask).expect("estimate").expect("a pose");
    check_placement(&model, &cam, &found, &truth, 10.0);
    let elbow_err = (found.X_CO.transform_point(Vector::ZERO) - elbow).length();
    assert!(elbow_err < 0.05, "elbow {elbow_err} m off (not the twin)");
    // With the elbow pinned, the wrist may still sit at either of the two points of its ray
    // a forearm's length away: the same mask, the same anchor. Either is a right answer.
    let mirror = same_rays(&model, &truth, 0.0);
    // (The box's end is the elbow sphere's top, 1 mm from the joint: the mirror keeps the
    // box's end, so its joint moves by at most twice that.)
    assert!((mirror.transform_point(Vector::ZERO) - elbow).length() < 2e-3);
    let err = [truth, mirror]
        .iter()
        .map(|X| (model.centre(&found.X_CO) - model.centre(X)).length())
        .fold(f64::INFINITY, f64::min);
    assert!(err < 0.05, "centre {err} m from both solutions");
    // ... and the reported uncertainty covers the other one: the wrist ends differ by this.
    let wrist = |X: &Pose| X.transform_point(2.0 * model.centre_O);
    let apart = (wrist(&truth) - wrist(&mirror)).length();
    assert!(apart > 0.2, "{apart}");
    assert!(
        found.uncertainty_m > apart - 0.05,
        "uncertainty {} for wrists {apart} m apart",
        found.uncertainty_m
    );
}

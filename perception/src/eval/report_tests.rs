//! The pose report's tables, comparisons and CSV on hand-made frames.

use crate::pose::NoPose;

/// An evaluated frame of sequence 0 at short distance, for the report tests.
fn frame_result(
    frame: usize,
    level: &str,
    outcome: std::result::Result<super::PoseError, NoPose>,
) -> super::FrameResult {
    super::FrameResult {
        sequence: 0,
        frame,
        recorded: false,
        distance_class: "short".into(),
        occlusion_level: level.into(),
        distance_m: 1.0,
        occlusion: 0.8,
        outcome,
        reacquired: false,
        confirmed: false,
        f_m: 0.0,
        gain: 0.0,
        uncertainty_m: 0.0,
        sigma_m: f64::NAN,
        spread_m: f64::NAN,
        hidden_share: f64::NAN,
        pose_ms: 0.0,
        mask_ms: 0.0,
        renders: 0,
        truth_gain: [f64::NAN; 4],
        trunk_error: [f64::NAN; 2],
    }
}

/// A pose `position_cm` off at the centre and `ends_cm` at the farther end, right in angle.
fn pose_error(position_cm: f64, ends_cm: f64) -> super::PoseError {
    super::PoseError {
        position_cm,
        yaw_deg: 0.0,
        pitch_deg: 0.0,
        roll_deg: 0.0,
        axis_deg: 0.0,
        spin_deg: 0.0,
        flipped: false,
        ends_cm,
    }
}

/// An evaluation of one test sequence's `frames`, no contact sheet.
fn evaluation(frames: Vec<super::FrameResult>) -> super::PoseEvaluation {
    super::PoseEvaluation {
        masks: String::new(),
        split: "test".into(),
        sequences: 1,
        method: String::new(),
        frames,
        no_pose: Vec::new(),
    }
}

#[test]
fn the_comparison_scores_every_source_on_the_frames_all_of_them_have() {
    use super::compare_markdown;
    let frame = |i: usize, cm: Option<f64>| {
        let outcome = cm.map(|cm| pose_error(cm, cm)).ok_or(NoPose::Empty);
        frame_result(i, "heavy", outcome)
    };
    let eval = evaluation;
    let a = eval(vec![
        frame(0, Some(1.0)),
        frame(1, Some(2.0)),
        frame(2, Some(6.0)),
    ]);
    let b = eval(vec![
        frame(0, Some(5.0)),
        frame(1, Some(7.0)),
        frame(2, None),
    ]);
    let md = compare_markdown(&[("a", &a), ("b", &b)]).unwrap();
    // short / heavy: a 3.00 over its 3 frames, b 6.00 over its 2 (one without a pose); over
    // the 2 common frames a 1.50, b 6.00; the paper's 5.84 and 6.29 beside.
    assert!(
        md.contains("| short | heavy | 3 | 3.00 | 0 | 6.00 | 1 | 2 | 1.50 | 6.00 | 5.84 | 6.29 |"),
        "{md}"
    );
    // A cell without frames has no error to show.
    assert!(
        md.contains("| short | light | 0 | - | 0 | - | 0 | 0 | - | - | 1.73 | 1.62 |"),
        "{md}"
    );
    // Evaluations of other frames are refused.
    let c = eval(vec![frame(0, Some(1.0))]);
    assert!(compare_markdown(&[("a", &a), ("c", &c)]).is_err());
}

/// A group whose frames all lack a pose has no angles to average: the table shows `-`,
/// not 0.0 degrees, in every angle column (the position column says so too).
#[test]
fn a_group_without_a_pose_shows_no_angles() {
    use super::PoseEvaluation;
    let frame = |i: usize, level: &str| frame_result(i, level, Err(NoPose::PoorFit));
    let eval = PoseEvaluation {
        masks: String::new(),
        split: "test".into(),
        sequences: 1,
        method: String::new(),
        frames: vec![frame(1, "medium"), frame(2, "medium")],
        no_pose: Vec::new(),
    };
    let s = eval.summary(Some("short"), Some("medium"));
    assert_eq!((s.frames, s.no_pose), (2, 2));
    for v in [
        s.position_cm,
        s.yaw_deg,
        s.pitch_deg,
        s.roll_deg,
        s.axis_deg,
        s.spin_deg,
    ] {
        assert!(v.is_nan(), "{s:?}");
    }
    let md = eval.to_markdown();
    assert!(
        md.contains("| short | medium | - | - | - | - | - | 0 |"),
        "{md}"
    );
}

/// The contact sheet's sample of frames without a pose takes each sequence's first before
/// any sequence's second, and keeps the split's order.
#[test]
fn the_no_pose_sample_spreads_over_the_sequences() {
    use super::{NoPoseFrame, PoseEvaluation};
    // Sequence 7 has four frames without a pose, sequences 8 and 9 one each.
    let sequences = [7, 7, 7, 7, 8, 9];
    let frames = sequences
        .iter()
        .enumerate()
        .map(|(i, &sequence)| super::FrameResult {
            sequence,
            ..frame_result(i + 1, "heavy", Err(NoPose::PoorFit))
        })
        .collect();
    let no_pose = (0..sequences.len())
        .map(|index| NoPoseFrame {
            index,
            images: workcell_procnet::eval::SheetImages {
                rgb: vec![0; 3],
                truth: vec![0],
                predicted: vec![0],
                width: 1,
                height: 1,
            },
        })
        .collect();
    let eval = PoseEvaluation {
        masks: String::new(),
        split: "test".into(),
        sequences: 3,
        method: String::new(),
        frames,
        no_pose,
    };
    let sample = |n| -> Vec<usize> { eval.no_pose_sample(n).iter().map(|f| f.index).collect() };
    assert_eq!(sample(3), [0, 4, 5]);
    assert_eq!(sample(4), [0, 1, 4, 5]);
    assert_eq!(sample(24), [0, 1, 2, 3, 4, 5]);
    assert!(sample(0).is_empty());
}

/// Every reason for no pose stays one field of the per-frame CSV, commas and all.
#[test]
fn the_csv_quotes_reasons_with_commas() {
    use super::PoseEvaluation;
    let reasons = [
        NoPose::Empty,
        NoPose::NotAProbability,
        NoPose::SeveralBlobs { blobs: 3 },
        NoPose::PoorFit,
    ];
    let eval = PoseEvaluation {
        masks: String::new(),
        split: "test".into(),
        sequences: 1,
        method: String::new(),
        frames: reasons
            .iter()
            .enumerate()
            .map(|(i, why)| frame_result(i + 1, "heavy", Err(*why)))
            .collect(),
        no_pose: Vec::new(),
    };
    let csv = eval.to_csv();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let why = header
        .iter()
        .position(|h| *h == "no_pose")
        .expect("no_pose column");
    for (line, reason) in lines.zip(reasons) {
        // Split on the commas outside quotes; a quoted field loses its quotes.
        let (mut fields, mut field, mut quoted) = (Vec::new(), String::new(), false);
        for c in line.chars() {
            match c {
                '"' => quoted = !quoted,
                ',' if !quoted => fields.push(std::mem::take(&mut field)),
                c => field.push(c),
            }
        }
        fields.push(field);
        assert_eq!(fields.len(), header.len(), "{line}");
        assert_eq!(fields[why], reason.to_string(), "{line}");
    }
}

/// A split that mixes recorded people with the generator's motion is reported per motion;
/// one of a single kind is not.
#[test]
fn recorded_people_and_the_generators_motion_get_a_row_each() {
    use super::FrameResult;
    let posed = |ends_cm: f64| Ok(pose_error(ends_cm / 2.0, ends_cm));
    let frame = |i: usize, recorded: bool, outcome| FrameResult {
        recorded,
        uncertainty_m: 0.5,
        ..frame_result(i, "light", outcome)
    };
    // Recorded: ends 10 and 40 cm off (one far, within a 50 cm bound both) and a frame
    // without a pose; generated: 4 cm off.
    let frames = vec![
        frame(0, true, posed(10.0)),
        frame(1, true, posed(40.0)),
        frame(2, true, Err(NoPose::PoorFit)),
        frame(3, false, posed(4.0)),
    ];
    let eval = evaluation;
    let md = eval(frames.clone()).by_motion_markdown();
    assert!(
        md.contains("| recorded people | 3 | 1 | 12.50 | 1 (50.0 %) | 100.0 % |"),
        "{md}"
    );
    assert!(
        md.contains("| generated motion | 1 | 0 | 2.00 | 0 (0.0 %) | 100.0 % |"),
        "{md}"
    );
    assert!(eval(frames.clone()).to_markdown().contains(&md));
    let generated: Vec<FrameResult> = frames.into_iter().filter(|f| !f.recorded).collect();
    assert!(eval(generated).by_motion_markdown().is_empty());
}

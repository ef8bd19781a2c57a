//! Tables, CSV and the side-by-side comparison of pose evaluations.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::{FrameResult, PoseError, PoseEvaluation, Summary};
use crate::error::{PerceptionError, Result};

/// The paper's Table 2 (position error, cm): ProcNet and PoseCNN; `None` where it failed.
pub const PAPER_TABLE2: [(&str, &str, Option<f64>, Option<f64>); 9] = [
    ("short", "light", Some(1.73), Some(1.62)),
    ("short", "medium", Some(2.48), Some(4.83)),
    ("short", "heavy", Some(5.84), Some(6.29)),
    ("medium", "light", Some(1.81), Some(1.57)),
    ("medium", "medium", Some(2.59), Some(5.02)),
    ("medium", "heavy", Some(6.04), Some(6.54)),
    ("large", "light", Some(4.07), Some(2.65)),
    ("large", "medium", Some(5.39), Some(2.86)),
    ("large", "heavy", None, None),
];
/// The paper's averages (ProcNet, PoseCNN), cm.
pub const PAPER_AVERAGE: (f64, f64) = (3.74, 3.92);

fn fmt_cm(v: Option<f64>) -> String {
    v.map_or_else(|| "failed".to_string(), |v| format!("{v:.2}"))
}

/// Several mask sources on the same split side by side (`eval pose --masks procnet,baseline`):
/// per cell of Table 2 and per occlusion level, each source's mean position error and frames
/// without a pose, then the same means over only the frames where every source has a pose
/// (a source that gives up on hard frames is not rewarded for it), with the paper's numbers.
///
/// # Errors
/// The evaluations are not of the same frames.
pub fn compare_markdown(evals: &[(&str, &PoseEvaluation)]) -> Result<String> {
    let Some((_, first)) = evals.first() else {
        return Err(PerceptionError::Input {
            message: "nothing to compare".into(),
        });
    };
    let key = |f: &FrameResult| (f.sequence, f.frame);
    for (name, ev) in evals {
        if ev.frames.len() != first.frames.len()
            || ev
                .frames
                .iter()
                .zip(&first.frames)
                .any(|(a, b)| key(a) != key(b))
        {
            return Err(PerceptionError::Input {
                message: format!("{name} was evaluated on other frames than {}", evals[0].0),
            });
        }
    }
    let every_has_pose: Vec<bool> = (0..first.frames.len())
        .map(|i| evals.iter().all(|(_, ev)| ev.frames[i].outcome.is_ok()))
        .collect();
    // (distance, occlusion, paper ProcNet, paper PoseCNN); `None` matches every value.
    type Row<'a> = (Option<&'a str>, Option<&'a str>, Option<f64>, Option<f64>);
    let mut rows: Vec<Row> = PAPER_TABLE2
        .iter()
        .map(|&(d, l, a, b)| (Some(d), Some(l), a, b))
        .collect();
    for level in ["light", "medium", "heavy"] {
        rows.push((None, Some(level), None, None));
    }
    rows.push((None, None, Some(PAPER_AVERAGE.0), Some(PAPER_AVERAGE.1)));
    let mut md = String::new();
    let names: Vec<&str> = evals.iter().map(|(n, _)| *n).collect();
    let _ = writeln!(
        md,
        "Position error (cm) and frames without a pose; then the error over the frames where all of {} have a pose. The paper's PoseCNN column is PoseCNN itself; `baseline` is this project's feed-forward stand-in for it.\n",
        names.join(", ")
    );
    let mut header = "| distance | occlusion | frames |".to_string();
    let mut rule = "|---|---|---|".to_string();
    for n in &names {
        let _ = write!(header, " {n} (cm) | {n} no pose |");
        rule.push_str("---|---|");
    }
    header.push_str(" common frames |");
    rule.push_str("---|");
    for n in &names {
        let _ = write!(header, " {n}, common (cm) |");
        rule.push_str("---|");
    }
    header.push_str(" paper ProcNet (cm) | paper PoseCNN (cm) |");
    rule.push_str("---|---|");
    let _ = writeln!(md, "{header}\n{rule}");
    for (d, l, paper_procnet, paper_posecnn) in rows {
        let average = d.is_none() && l.is_none();
        let mut line = format!(
            "| {} | {} | {} |",
            d.unwrap_or(if average { "average" } else { "all" }),
            l.unwrap_or(""),
            first.summary(d, l).frames
        );
        for (_, ev) in evals {
            let s = ev.summary(d, l);
            let cm = if s.frames == 0 {
                "-".into()
            } else {
                fmt_cm(finite(s.position_cm))
            };
            let _ = write!(line, " {cm} | {} |", s.no_pose);
        }
        let common: Vec<usize> = (0..first.frames.len())
            .filter(|&i| every_has_pose[i] && first.frames[i].is_in(d, l))
            .collect();
        let _ = write!(line, " {} |", common.len());
        for (_, ev) in evals {
            let sum: f64 = common
                .iter()
                .filter_map(|&i| ev.frames[i].outcome.as_ref().ok())
                .map(|e| e.position_cm)
                .sum();
            let mean = if common.is_empty() {
                "-".into()
            } else {
                format!("{:.2}", sum / common.len() as f64)
            };
            let _ = write!(line, " {mean} |");
        }
        let paper = |v: Option<f64>| {
            if d.is_none() && !average {
                String::new()
            } else {
                fmt_cm(v)
            }
        };
        let _ = writeln!(
            line,
            " {} | {} |",
            paper(paper_procnet),
            paper(paper_posecnn)
        );
        md.push_str(&line);
    }
    Ok(md)
}

/// An angle with one decimal, `-` where there is none (a group without a pose).
fn fmt_deg(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1}")
    } else {
        "-".into()
    }
}

/// An end of the forearm this far off, cm, is a pose that would mislead the safety filter:
/// the share of such poses is what a bound's tail is made of.
pub const FAR_OFF_CM: f64 = 30.0;

/// The share of a group's posed frames within their uncertainty, as a percentage.
fn within(s: &Summary) -> String {
    let posed = s.frames - s.no_pose;
    if posed == 0 {
        "-".into()
    } else {
        format!("{:.1} %", 100.0 * s.within_bound as f64 / posed as f64)
    }
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl PoseEvaluation {
    /// Statistics of the frames of a (distance class, occlusion level) pair; `None` matches
    /// every value.
    #[must_use]
    pub fn summary(&self, distance: Option<&str>, level: Option<&str>) -> Summary {
        Summary::of(self.frames.iter().filter(|f| f.is_in(distance, level)))
    }

    /// Per distance bin of `bin_m`: (bin centre, mean position error in cm (NaN without a
    /// pose), frames with a pose, frames without), for the error-against-distance plot.
    #[must_use]
    pub fn by_distance(&self, bin_m: f64) -> Vec<(f64, f64, usize, usize)> {
        let mut bins: BTreeMap<i64, (f64, usize, usize)> = BTreeMap::new();
        for f in &self.frames {
            let b = bins
                .entry((f.distance_m / bin_m).floor() as i64)
                .or_default();
            match &f.outcome {
                Ok(e) => {
                    b.0 += e.position_cm;
                    b.1 += 1;
                }
                Err(_) => b.2 += 1,
            }
        }
        bins.into_iter()
            .map(|(k, (sum, n, none))| {
                let mean = if n > 0 { sum / n as f64 } else { f64::NAN };
                ((k as f64 + 0.5) * bin_m, mean, n, none)
            })
            .collect()
    }

    /// Where the split mixes recorded people with the motion generator's: a row for each,
    /// since a figure on the generator's motion says little of people (frames, frames
    /// without a pose, mean position error, poses with an end of the forearm over
    /// [`FAR_OFF_CM`] off, poses within the bound). Empty where the frames are all of one.
    #[must_use]
    pub fn by_motion_markdown(&self) -> String {
        let recorded = self.frames.iter().filter(|f| f.recorded).count();
        if recorded == 0 || recorded == self.frames.len() {
            return String::new();
        }
        let mut md = format!(
            "| motion | frames | no pose | position (cm) | an end over {FAR_OFF_CM} cm off | within the bound |\n|---|---|---|---|---|---|\n",
        );
        for (name, of_recorded) in [("recorded people", true), ("generated motion", false)] {
            let frames = || {
                self.frames
                    .iter()
                    .filter(move |f| f.recorded == of_recorded)
            };
            let s = Summary::of(frames());
            let far = frames()
                .filter(|f| f.outcome.as_ref().is_ok_and(|e| e.ends_cm > FAR_OFF_CM))
                .count();
            let posed = s.frames - s.no_pose;
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {} | {} |",
                s.frames,
                s.no_pose,
                if posed > 0 {
                    format!("{:.2}", s.position_cm)
                } else {
                    "failed".into()
                },
                if posed > 0 {
                    format!("{far} ({:.1} %)", 100.0 * far as f64 / posed as f64)
                } else {
                    "-".into()
                },
                within(&s)
            );
        }
        md.push('\n');
        md
    }

    /// The evaluation as Markdown: Table 2's layout with the paper's numbers beside ours,
    /// then the angles, then timing.
    #[must_use]
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(
            md,
            "Pose error on the {} split ({} sequences, {} frames), masks: {}; {}.\n",
            self.split,
            self.sequences,
            self.frames.len(),
            self.masks,
            self.method
        );
        let _ = writeln!(
            md,
            "| distance | occlusion | frames | no pose | position (cm) | paper ProcNet (cm) | paper PoseCNN (cm) | re-acquired | within the bound |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|");
        for (d, l, ours, theirs) in PAPER_TABLE2 {
            let s = self.summary(Some(d), Some(l));
            let _ = writeln!(
                md,
                "| {d} | {l} | {} | {} | {} | {} | {} | {} | {} |",
                s.frames,
                s.no_pose,
                if s.frames > s.no_pose {
                    format!("{:.2}", s.position_cm)
                } else {
                    "failed".into()
                },
                fmt_cm(ours),
                fmt_cm(theirs),
                s.reacquired,
                within(&s)
            );
        }
        let s = self.summary(None, None);
        let _ = writeln!(
            md,
            "| average | | {} | {} | {:.2} | {:.2} | {:.2} | {} | {} |\n",
            s.frames,
            s.no_pose,
            s.position_cm,
            PAPER_AVERAGE.0,
            PAPER_AVERAGE.1,
            s.reacquired,
            within(&s)
        );
        let _ = writeln!(
            md,
            "Within the bound: of the frames with a pose, those whose reported uncertainty covers both ends of the true forearm (the radius the safety filter inflates the forearm by).\n"
        );
        md.push_str(&self.by_motion_markdown());
        let confirmed: Vec<&FrameResult> = self.frames.iter().filter(|f| f.confirmed).collect();
        if !confirmed.is_empty() {
            let covered = confirmed
                .iter()
                .filter(|f| {
                    f.outcome
                        .as_ref()
                        .is_ok_and(|e| e.ends_cm <= 100.0 * f.uncertainty_m)
                })
                .count();
            let _ = writeln!(
                md,
                "{} poses had a gain below the fit's threshold and were confirmed by the frame before (`ArmFitConfig::confirm_min_gain`); {covered} of them within the bound.\n",
                confirmed.len()
            );
        }
        let _ = writeln!(
            md,
            "The paper's PoseCNN column is PoseCNN itself; this project's stand-in for it is the feed-forward baseline (`--masks baseline`; `--masks procnet,baseline` compares the two).\n"
        );
        let _ = writeln!(
            md,
            "| distance | occlusion | yaw (deg) | pitch (deg) | roll (deg) | axis (deg) | spin about the axis (deg) | end-for-end flips |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
        let mut rows: Vec<(Option<&str>, Option<&str>)> = PAPER_TABLE2
            .iter()
            .map(|(d, l, _, _)| (Some(*d), Some(*l)))
            .collect();
        rows.push((None, None));
        for (d, l) in rows {
            let s = self.summary(d, l);
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} | {} |",
                d.unwrap_or("average"),
                l.unwrap_or(""),
                fmt_deg(s.yaw_deg),
                fmt_deg(s.pitch_deg),
                fmt_deg(s.roll_deg),
                fmt_deg(s.axis_deg),
                fmt_deg(s.spin_deg),
                s.flipped
            );
        }
        md.push_str(&self.timing_markdown());
        md
    }

    /// Time per frame: the mask source (the network) and the pose search, split by tracked
    /// and re-acquired frames, as mean, median and 95th percentile.
    #[must_use]
    pub fn timing_markdown(&self) -> String {
        let stats = |mut v: Vec<f64>| -> String {
            if v.is_empty() {
                return "| - | - | - | 0 |".into();
            }
            v.sort_by(f64::total_cmp);
            let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            format!(
                "| {mean:.1} | {:.1} | {:.1} | {} |",
                q(0.5),
                q(0.95),
                v.len()
            )
        };
        let tracked: Vec<&FrameResult> = self
            .frames
            .iter()
            .filter(|f| f.outcome.is_ok() && !f.reacquired)
            .collect();
        let mut md = String::from(
            "\n| per frame (ms) | mean | median | 95th percentile | frames |\n|---|---|---|---|---|\n",
        );
        let rows: [(&str, Vec<f64>); 5] = [
            (
                "masks (network)",
                self.frames.iter().map(|f| f.mask_ms).collect(),
            ),
            ("pose, tracked", tracked.iter().map(|f| f.pose_ms).collect()),
            (
                "pose with the global search (no track, or a poor one)",
                self.frames
                    .iter()
                    .filter(|f| f.reacquired)
                    .map(|f| f.pose_ms)
                    .collect(),
            ),
            (
                "pose, all frames",
                self.frames.iter().map(|f| f.pose_ms).collect(),
            ),
            (
                "masks + pose",
                self.frames.iter().map(|f| f.mask_ms + f.pose_ms).collect(),
            ),
        ];
        for (name, v) in rows {
            let _ = writeln!(md, "| {name} {}", stats(v));
        }
        let n = self.frames.len().max(1) as f64;
        let renders = self.frames.iter().map(|f| f.renders as f64).sum::<f64>() / n;
        let _ = writeln!(md, "\n{renders:.0} renders per frame on average.");
        md
    }

    /// One line per frame, CSV.
    #[must_use]
    pub fn to_csv(&self) -> String {
        let mut csv = String::from(
            "sequence,frame,distance_class,occlusion_level,distance_m,occlusion,no_pose,position_cm,yaw_deg,pitch_deg,roll_deg,axis_deg,spin_deg,flipped,reacquired,f_m,gain,uncertainty_m,mask_ms,pose_ms,renders,ends_cm,truth_gain,sigma_m,spread_m,truth_gain_upper_arm,truth_gain_forearm,truth_gain_hand,hidden_share,confirmed,recorded,trunk_error_deg,pelvis_error_cm\n",
        );
        for f in &self.frames {
            let (no_pose, e) = match &f.outcome {
                Ok(e) => (String::new(), Some(e)),
                Err(why) => (why.to_string(), None),
            };
            let v = |g: fn(&PoseError) -> f64| e.map_or(String::new(), |e| format!("{:.4}", g(e)));
            let _ = writeln!(
                csv,
                "{},{},{},{},{:.4},{:.4},{},{},{},{},{},{},{},{},{},{:.6},{:.4},{:.4},{:.3},{:.3},{},{},{:.4},{:.5},{:.5},{:.4},{:.4},{:.4},{:.4},{},{},{:.2},{:.2}",
                f.sequence,
                f.frame,
                workcell_procnet::eval::csv_field(&f.distance_class),
                workcell_procnet::eval::csv_field(&f.occlusion_level),
                f.distance_m,
                f.occlusion,
                workcell_procnet::eval::csv_field(&no_pose),
                v(|e| e.position_cm),
                v(|e| e.yaw_deg),
                v(|e| e.pitch_deg),
                v(|e| e.roll_deg),
                v(|e| e.axis_deg),
                v(|e| e.spin_deg),
                e.is_some_and(|e| e.flipped),
                f.reacquired,
                f.f_m,
                f.gain,
                f.uncertainty_m,
                f.mask_ms,
                f.pose_ms,
                f.renders,
                v(|e| e.ends_cm),
                f.truth_gain[0],
                f.sigma_m,
                f.spread_m,
                f.truth_gain[1],
                f.truth_gain[2],
                f.truth_gain[3],
                f.hidden_share,
                f.confirmed,
                f.recorded,
                f.trunk_error[0].to_degrees(),
                100.0 * f.trunk_error[1]
            );
        }
        csv
    }
}

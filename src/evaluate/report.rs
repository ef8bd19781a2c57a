//! The evaluation report: `summary.md`, `metrics.csv`, and plots of separation and speed
//! scaling over time.

use std::fmt::Write as _;
use std::path::Path;

use workcell_safety::HumanPart;

use super::{EpisodeMetrics, EpisodeTrace};
use crate::plot::{Panel, svg_panels, svg_to_png};

/// Aggregates over episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Aggregate {
    pub episodes: usize,
    pub min_separation_m: f64,
    pub episodes_with_violation: usize,
    pub violations: usize,
    pub violation_s: f64,
    pub violation_moving_s: f64,
    pub finished: usize,
    /// Mean of task time / nominal task time over finished episodes.
    pub mean_task_ratio: f64,
    pub peak_speed_near_human_m_s: f64,
    pub peak_approach_speed_m_s: f64,
    pub peak_human_speed_m_s: f64,
    pub peak_human_acceleration_m_s2: f64,
    /// Per part ([`crate::evaluate::PFL_PARTS`]): the robot's fastest approach within the PFL
    /// distance, m/s.
    pub peak_approach_by_part_m_s: [f64; crate::evaluate::PFL_PARTS.len()],
    pub contacts_moving: usize,
    pub contacts_standing: usize,
    pub ticks_pass: usize,
    pub ticks_modified: usize,
    pub ticks_relaxed: usize,
    pub ticks_braking: usize,
    /// Simulated time over the loop's wall time (each episode's less its setup), summed
    /// over episodes (each episode runs on one core).
    pub real_time_factor: f64,
    /// Simulated time over the episodes' whole wall time, setup included.
    pub real_time_with_setup: f64,
}

impl Aggregate {
    /// Sums and extremes of `episodes`.
    #[must_use]
    pub fn of(episodes: &[EpisodeMetrics]) -> Self {
        let finished: Vec<f64> = episodes
            .iter()
            .filter_map(|e| e.task_time_s.map(|t| t / e.nominal_task_s))
            .collect();
        Self {
            episodes: episodes.len(),
            min_separation_m: episodes
                .iter()
                .map(|e| e.min_separation_m)
                .fold(f64::INFINITY, f64::min),
            episodes_with_violation: episodes.iter().filter(|e| e.violations > 0).count(),
            violations: episodes.iter().map(|e| e.violations).sum(),
            violation_s: episodes.iter().map(|e| e.violation_s).sum(),
            violation_moving_s: episodes.iter().map(|e| e.violation_moving_s).sum(),
            finished: finished.len(),
            mean_task_ratio: if finished.is_empty() {
                f64::NAN
            } else {
                finished.iter().sum::<f64>() / finished.len() as f64
            },
            peak_speed_near_human_m_s: episodes
                .iter()
                .map(|e| e.peak_speed_near_human_m_s)
                .fold(0.0, f64::max),
            peak_approach_speed_m_s: episodes
                .iter()
                .map(|e| e.peak_approach_speed_m_s)
                .fold(0.0, f64::max),
            peak_human_speed_m_s: episodes
                .iter()
                .map(|e| e.peak_human_speed_m_s)
                .fold(0.0, f64::max),
            peak_human_acceleration_m_s2: episodes
                .iter()
                .map(|e| e.peak_human_acceleration_m_s2)
                .fold(0.0, f64::max),
            peak_approach_by_part_m_s: std::array::from_fn(|i| {
                episodes
                    .iter()
                    .map(|e| e.peak_approach_by_part_m_s[i])
                    .fold(0.0, f64::max)
            }),
            contacts_moving: episodes.iter().map(|e| e.contacts_moving).sum(),
            contacts_standing: episodes.iter().map(|e| e.contacts_standing).sum(),
            ticks_pass: episodes.iter().map(|e| e.ticks_pass).sum(),
            ticks_modified: episodes.iter().map(|e| e.ticks_modified).sum(),
            ticks_relaxed: episodes.iter().map(|e| e.ticks_relaxed).sum(),
            ticks_braking: episodes.iter().map(|e| e.ticks_braking).sum(),
            real_time_factor: episodes.iter().map(|e| e.simulated_s).sum::<f64>()
                / episodes
                    .iter()
                    .map(|e| (e.wall_s - e.setup_s).max(0.0))
                    .sum::<f64>(),
            real_time_with_setup: episodes.iter().map(|e| e.simulated_s).sum::<f64>()
                / episodes.iter().map(|e| e.wall_s).sum::<f64>(),
        }
    }
}

/// The mean task-time ratio, or `-` when no episode finished (it is NaN then).
#[must_use]
pub fn task_ratio(ratio: f64, prefix: &str) -> String {
    if ratio.is_finite() {
        format!("{prefix}{ratio:.3}")
    } else {
        "- (none finished)".into()
    }
}

impl Aggregate {
    /// One line for the terminal.
    #[must_use]
    pub fn headline(&self, d_min_m: f64) -> String {
        format!(
            "min separation {:.4} m (d_min {d_min_m:.3}), {} violations in {} episodes ({:.3} s below d_min, {:.3} s of it moving), contacts: {} with the robot moving, {} at standstill, {}/{} finished, task time {} of unfiltered, peak speed near the human {:.3} m/s (approach {:.3} m/s)",
            self.min_separation_m,
            self.violations,
            self.episodes_with_violation,
            self.violation_s,
            self.violation_moving_s,
            self.contacts_moving,
            self.contacts_standing,
            self.finished,
            self.episodes,
            task_ratio(self.mean_task_ratio, "x"),
            self.peak_speed_near_human_m_s,
            self.peak_approach_speed_m_s
        )
    }
}

/// Header of `metrics.csv`.
pub const CSV_HEADER: &str = "episode,seed,filter,min_separation_m,closest,violations,violation_s,violation_moving_s,task_time_s,nominal_task_s,task_ratio,peak_speed_near_human_m_s,peak_approach_speed_m_s,peak_human_speed_m_s,peak_human_acceleration_m_s2,peak_approach_upper_arm_m_s,peak_approach_forearm_m_s,peak_approach_hand_m_s,peak_approach_head_m_s,contacts_moving,contacts_standing,ticks_pass,ticks_modified,ticks_relaxed,ticks_braking,braking_reasons,perception_error_m,perception_error_torso_m,perception_error_upper_arm_m,perception_error_forearm_m,perception_error_hand_m,perception_error_head_m,perception_error_left_upper_arm_m,perception_error_left_forearm_m,perception_error_left_hand_m,fit_error_m,other_arm_min_separation_m,other_arm_violation_s,simulated_s,wall_s,setup_s";

/// `metrics.csv`: one row per episode.
#[must_use]
pub fn metrics_csv(episodes: &[EpisodeMetrics]) -> String {
    let mut csv = String::from(CSV_HEADER);
    csv.push('\n');
    for e in episodes {
        let reasons: Vec<String> = e
            .braking_reasons
            .iter()
            .map(|(r, n)| format!("{r}: {n}"))
            .collect();
        let _ = writeln!(
            csv,
            "{},{},{},{:.6},\"{}\",{},{:.3},{:.3},{},{:.3},{},{:.4},{:.4},{:.4},{:.2},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{},{},\"{}\",{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.3},{:.3},{:.3},{:.3}",
            e.episode,
            e.seed,
            e.filter,
            e.min_separation_m,
            e.closest,
            e.violations,
            e.violation_s,
            e.violation_moving_s,
            e.task_time_s.map_or(String::new(), |t| format!("{t:.3}")),
            e.nominal_task_s,
            e.task_time_s
                .map_or(String::new(), |t| format!("{:.4}", t / e.nominal_task_s)),
            e.peak_speed_near_human_m_s,
            e.peak_approach_speed_m_s,
            e.peak_human_speed_m_s,
            e.peak_human_acceleration_m_s2,
            e.peak_approach_by_part_m_s[0],
            e.peak_approach_by_part_m_s[1],
            e.peak_approach_by_part_m_s[2],
            e.peak_approach_by_part_m_s[3],
            e.contacts_moving,
            e.contacts_standing,
            e.ticks_pass,
            e.ticks_modified,
            e.ticks_relaxed,
            e.ticks_braking,
            reasons.join("; "),
            e.perception_error_m,
            part_error(e, HumanPart::Torso),
            part_error(e, HumanPart::UpperArm),
            part_error(e, HumanPart::Forearm),
            part_error(e, HumanPart::Hand),
            part_error(e, HumanPart::Head),
            part_error(e, HumanPart::LeftUpperArm),
            part_error(e, HumanPart::LeftForearm),
            part_error(e, HumanPart::LeftHand),
            e.fit_error_m,
            e.other_arm_min_separation_m,
            e.other_arm_violation_s,
            e.simulated_s,
            e.wall_s,
            e.setup_s
        );
    }
    csv
}

/// An episode's mean perception error of `part`, m (NaN: the model lacks it, or no estimate).
fn part_error(e: &EpisodeMetrics, part: HumanPart) -> f64 {
    HumanPart::ALL
        .iter()
        .position(|&p| p == part)
        .and_then(|i| e.perception_error_by_part_m.get(i))
        .copied()
        .unwrap_or(f64::NAN)
}

/// The median of the finite values of `values`; `None` without one.
fn finite_median(values: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = values.filter(|e| e.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// Where the perception error goes: each part's error in the median episode (of those that
/// estimated it), and where perception fits frames the fits' own error at their exposure
/// (the rest is the estimate's ageing), or `None` when no episode had an estimate.
fn part_error_line(episodes: &[EpisodeMetrics]) -> Option<String> {
    let parts: Vec<String> = HumanPart::ALL
        .iter()
        .filter_map(|&part| {
            let median = finite_median(episodes.iter().map(|e| part_error(e, part)))?;
            Some(format!("{part} {:.1}", median * 1e3))
        })
        .collect();
    let at_exposure = finite_median(episodes.iter().map(|e| e.fit_error_m)).map(|m| {
        format!(
            " The fits' own error at their exposure, before the estimate ages (the latency and the frames since): {:.1} mm in the median episode.",
            m * 1e3
        )
    });
    (!parts.is_empty()).then(|| {
        format!(
            "Perception error per part, median episode (mm; the mean of its two end points' distances from the truth): {}.{}",
            parts.join(", "),
            at_exposure.unwrap_or_default()
        )
    })
}

/// The left arm (`EpisodeMetrics::other_arm_min_separation_m`): how near
/// the robot it came and for how long within `d_min_m`, over the episodes that had one;
/// `None` when none had.
#[must_use]
pub fn other_arm_line(episodes: &[EpisodeMetrics], d_min_m: f64, seen: bool) -> Option<String> {
    let with: Vec<&EpisodeMetrics> = episodes
        .iter()
        .filter(|e| !e.other_arm_min_separation_m.is_nan())
        .collect();
    let closest = with
        .iter()
        .map(|e| e.other_arm_min_separation_m)
        .fold(f64::INFINITY, f64::min);
    let below: Vec<&&EpisodeMetrics> = with
        .iter()
        .filter(|e| e.other_arm_min_separation_m < d_min_m)
        .collect();
    let touched = with
        .iter()
        .filter(|e| e.other_arm_min_separation_m <= 0.0)
        .count();
    (!with.is_empty()).then(|| {
        format!(
            "The left arm (the two-armed human's own, or a recorded person's other arm placed beside a one-armed model; {}; {} of {} episodes had one): closest {closest:.4} m, below d_min in {} episodes ({:.3} s), touching the robot in {touched}.",
            if seen {
                "perception reports it with the other parts"
            } else {
                "not reported to the filter"
            },
            with.len(),
            episodes.len(),
            below.len(),
            // From +0: an empty sum of f64 is -0, printed "-0.000".
            below.iter().fold(0.0, |s, e| s + e.other_arm_violation_s)
        )
    })
}

/// What the summary needs besides the episodes.
#[derive(Debug, Clone)]
pub struct SummaryContext<'a> {
    pub evaluation_file: &'a str,
    pub robot: &'a str,
    pub filter: &'a str,
    pub perception: &'a str,
    pub d_min_m: f64,
    pub near_m: f64,
    /// Distance within which the peaks per body region are taken, m.
    pub pfl_distance_m: f64,
    /// ISO/TS 15066 transient contact speed limits of the human model's guarded parts, by
    /// part name ([`crate::evaluate::PFL_PARTS`]), m/s, for the robot; 0 where contact is
    /// not permitted.
    pub contact_speed_limits: &'a [(String, f64)],
    pub command: &'a str,
    /// Perception saw the left arm (`RunSettings::other_arm_seen`): the filter, where one
    /// runs, guards it as the other parts.
    pub other_arm_seen: bool,
}

/// `summary.md`.
#[must_use]
pub fn summary_markdown(context: &SummaryContext<'_>, episodes: &[EpisodeMetrics]) -> String {
    let a = Aggregate::of(episodes);
    let mut md = String::new();
    let _ = writeln!(md, "# Closed-loop safety evaluation\n");
    let _ = writeln!(md, "- evaluation: `{}`", context.evaluation_file);
    let _ = writeln!(md, "- command: `{}`", context.command);
    let _ = writeln!(
        md,
        "- robot: {}; filter: **{}**; perception: {}",
        context.robot, context.filter, context.perception
    );
    let _ = writeln!(
        md,
        "- d_min: {:.3} m (true separation: exact robot shapes against the true human)\n",
        context.d_min_m
    );
    // Either arm below d_min is a violation; the left arm has a line of its own (a recorded
    // other arm beside a one-armed model is not in the table below).
    let other_arm_below = episodes
        .iter()
        .filter(|e| e.other_arm_min_separation_m < context.d_min_m)
        .count();
    let verdict = if episodes.iter().any(EpisodeMetrics::violated) {
        "VIOLATIONS"
    } else {
        "no violation"
    };
    let other_arm = if other_arm_below > 0 {
        format!(
            " (the left arm, {}, came below d_min in {other_arm_below} episodes)",
            if context.other_arm_seen {
                "reported by perception"
            } else {
                "not reported to the filter"
            }
        )
    } else {
        String::new()
    };
    let _ = writeln!(md, "## Verdict: {verdict}{other_arm}\n");
    let _ = writeln!(
        md,
        "| episodes | min separation (m) | episodes with violation | violations | time below d_min (s) | of it with the robot moving (s) | finished | task time / unfiltered | peak speed near human (m/s) | peak approach speed (m/s) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|");
    let _ = writeln!(
        md,
        "| {} | {:.4} | {} | {} | {:.3} | {:.3} | {}/{} | {} | {:.3} | {:.3} |\n",
        a.episodes,
        a.min_separation_m,
        a.episodes_with_violation,
        a.violations,
        a.violation_s,
        a.violation_moving_s,
        a.finished,
        a.episodes,
        task_ratio(a.mean_task_ratio, ""),
        a.peak_speed_near_human_m_s,
        a.peak_approach_speed_m_s
    );
    let ticks = (a.ticks_pass + a.ticks_modified + a.ticks_relaxed + a.ticks_braking).max(1) as f64;
    let _ = writeln!(
        md,
        "Fastest human part point: {:.2} m/s (ISO 13855 assumes 1.6 to 2.0 m/s); largest acceleration: {:.1} m/s^2 (a camera's bound on a stale estimate holds only up to the acceleration it assumes).\n",
        a.peak_human_speed_m_s, a.peak_human_acceleration_m_s2
    );
    let _ = writeln!(
        md,
        "Filter status over all ticks: pass {:.1} %, modified {:.1} %, relaxed (evading a human faster than the arm can retreat) {:.1} %, braking {:.1} %.\n",
        100.0 * a.ticks_pass as f64 / ticks,
        100.0 * a.ticks_modified as f64 / ticks,
        100.0 * a.ticks_relaxed as f64 / ticks,
        100.0 * a.ticks_braking as f64 / ticks
    );
    let _ = writeln!(
        md,
        "Contact (true separation down to 0): {} with the robot moving, {} with the robot at standstill (speed and separation monitoring permits only the second).\n",
        a.contacts_moving, a.contacts_standing
    );
    if let Some(line) = other_arm_line(episodes, context.d_min_m, context.other_arm_seen) {
        let _ = writeln!(md, "{line}\n");
    }
    let _ = writeln!(
        md,
        "Peak speeds near the human count the robot's closest surface point while the true separation is below {:.2} m (approach: its speed toward the human).\n",
        context.near_m
    );
    if !context.contact_speed_limits.is_empty() {
        let _ = writeln!(
            md,
            "### Power and force limiting\n\nThe robot's fastest approach toward each part at its closest point while that part was within {:.2} m, against ISO/TS 15066's transient contact speed of its body region for this robot:\n",
            context.pfl_distance_m
        );
        let _ = writeln!(
            md,
            "| body region | peak approach (m/s) | limit (m/s) | within |"
        );
        let _ = writeln!(md, "|---|---|---|---|");
        for (region, limit) in context.contact_speed_limits {
            let Some(i) = crate::evaluate::PFL_PARTS
                .iter()
                .position(|p| p.name() == region)
            else {
                continue;
            };
            let peak = a.peak_approach_by_part_m_s[i];
            let limit_text = if *limit > 0.0 {
                format!("{limit:.3}")
            } else {
                "0 (no contact)".to_string()
            };
            let _ = writeln!(
                md,
                "| {region} | {peak:.3} | {limit_text} | {} |",
                if peak <= *limit { "yes" } else { "NO" }
            );
        }
        let _ = writeln!(md);
    }
    let _ = writeln!(
        md,
        "Closed-loop speed: {:.2}x real time per core (physics, perception model, filter and metrics; {:.2}x with each episode's setup: the cell, its recorded clip retargeted, the perception built).\n",
        a.real_time_factor, a.real_time_with_setup
    );
    if let Some(line) = part_error_line(episodes) {
        let _ = writeln!(md, "{line}\n");
    }
    let _ = writeln!(md, "## Episodes\n");
    let _ = writeln!(
        md,
        "| episode | seed | min separation (m) | closest (link / part) | violations | below d_min (s) | task time (s) | peak speed near human (m/s) | pass / modified / relaxed / braking ticks | braking reasons | perception error (mm) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|");
    for e in episodes {
        let reasons: Vec<String> = e
            .braking_reasons
            .iter()
            .map(|(r, n)| format!("{r} ({n})"))
            .collect();
        let _ = writeln!(
            md,
            "| {} | {} | {:.4} | {} | {} | {:.3} | {} | {:.3} | {} / {} / {} / {} | {} | {} |",
            e.episode,
            e.seed,
            e.min_separation_m,
            e.closest,
            e.violations,
            e.violation_s,
            e.task_time_s
                .map_or("unfinished".to_string(), |t| format!("{t:.2}")),
            e.peak_speed_near_human_m_s,
            e.ticks_pass,
            e.ticks_modified,
            e.ticks_relaxed,
            e.ticks_braking,
            if reasons.is_empty() {
                "-".into()
            } else {
                reasons.join(", ")
            },
            if e.perception_error_m.is_finite() {
                format!("{:.1}", e.perception_error_m * 1e3)
            } else {
                "- (no estimate)".into()
            }
        );
    }
    let _ = writeln!(
        md,
        "\n![separation](separation.png)\n\n![speed scaling](speed_scaling.png)\n\n![perception error](perception_error.png)"
    );
    md
}

/// Writes `separation.{svg,png}`, `speed_scaling.{svg,png}` and
/// `perception_error.{svg,png}` for the given episodes (the worst ones, closest first; see
/// [`super::record::worst_episodes`]), resampled onto one time axis.
///
/// # Errors
/// When a file cannot be written.
pub fn write_plots(
    out: &Path,
    worst: &[(&EpisodeMetrics, &EpisodeTrace)],
    d_min_m: f64,
) -> crate::Result<Vec<String>> {
    let t_end = worst
        .iter()
        .filter_map(|(_, trace)| trace.t_s.last().copied())
        .fold(0.0, f64::max);
    let n = 1000usize;
    let x: Vec<f64> = (0..=n).map(|k| t_end * k as f64 / n as f64).collect();
    let resample = |t: &[f64], v: &[f64]| -> Vec<f64> {
        x.iter()
            .map(|&xi| {
                if t.is_empty() || xi > t[t.len() - 1] + 1e-9 {
                    return f64::NAN;
                }
                let i = t.partition_point(|&ti| ti <= xi).saturating_sub(1);
                v.get(i).copied().unwrap_or(f64::NAN)
            })
            .collect()
    };
    let mut separation = Panel {
        title: "True minimum separation (worst episodes) and d_min".into(),
        y_label: "separation [m]".into(),
        series: Vec::new(),
    };
    let mut scaling = Panel {
        title: "Speed scaling |qdot| / |qdot_nom| (1 = nominal, 0 = stopped, above 1 = evading)"
            .into(),
        y_label: "scale".into(),
        series: Vec::new(),
    };
    let mut perception = Panel {
        title: "Perception error: mean distance of the estimated parts' end points from the true ones (gaps: no estimate)".into(),
        y_label: "error [m]".into(),
        series: Vec::new(),
    };
    for (episode, trace) in worst {
        perception.series.push((
            format!("ep {}", episode.episode),
            resample(
                &trace.t_s,
                &trace
                    .perception_error_m
                    .iter()
                    .map(|e| e.unwrap_or(f64::NAN))
                    .collect::<Vec<_>>(),
            ),
        ));
        let name = format!(
            "ep {}: min {:.3} m",
            episode.episode, episode.min_separation_m
        );
        separation
            .series
            .push((name, resample(&trace.t_s, &trace.separation_m)));
        scaling.series.push((
            format!("ep {}", episode.episode),
            resample(&trace.t_s, &trace.speed_scale),
        ));
    }
    separation
        .series
        .push(("d_min".into(), vec![d_min_m; x.len()]));
    // Contact, which also keeps d_min off the frame's bottom edge.
    separation
        .series
        .push(("contact".into(), vec![0.0; x.len()]));
    let mut written = Vec::new();
    for (name, panel) in [
        ("separation", separation),
        ("speed_scaling", scaling),
        ("perception_error", perception),
    ] {
        let svg = svg_panels(&x, "time [s]", &[panel]);
        let svg_path = out.join(format!("{name}.svg"));
        std::fs::write(&svg_path, &svg).map_err(|source| crate::Error::Write {
            path: svg_path.clone(),
            source,
        })?;
        let png_path = out.join(format!("{name}.png"));
        svg_to_png(&svg, &png_path)?;
        written.push(format!("{name}.svg"));
        written.push(format!("{name}.png"));
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_where_no_episode_finished_has_no_task_ratio() {
        let mut a = Aggregate {
            episodes: 2,
            min_separation_m: 0.2,
            episodes_with_violation: 0,
            violations: 0,
            violation_s: 0.0,
            violation_moving_s: 0.0,
            finished: 2,
            mean_task_ratio: 1.25,
            peak_speed_near_human_m_s: 0.1,
            peak_approach_speed_m_s: 0.1,
            peak_human_speed_m_s: 1.0,
            peak_human_acceleration_m_s2: 5.0,
            peak_approach_by_part_m_s: [0.0; crate::evaluate::PFL_PARTS.len()],
            contacts_moving: 1,
            contacts_standing: 2,
            ticks_pass: 10,
            ticks_modified: 0,
            ticks_relaxed: 0,
            ticks_braking: 0,
            real_time_factor: 1.0,
            real_time_with_setup: 1.0,
        };
        let line = a.headline(0.1);
        assert!(
            line.contains("2/2 finished, task time x1.250 of unfiltered"),
            "{line}"
        );
        assert!(
            line.contains("contacts: 1 with the robot moving, 2 at standstill"),
            "{line}"
        );
        (a.finished, a.mean_task_ratio) = (0, f64::NAN);
        let line = a.headline(0.1);
        assert!(
            line.contains("0/2 finished, task time - (none finished) of unfiltered"),
            "{line}"
        );
        assert!(!line.contains("NaN"), "{line}");
    }

    /// `metrics.csv`'s row has a field per header column, and each part's error lands under
    /// its own name: a tick that saw the forearm 4 cm off and the hand 10 cm off, no head.
    /// The other arm's tally: its least separation over ticks and its time below d_min; the
    /// summary states both, beside a verdict that says it is the modelled human's.
    #[test]
    fn the_other_arm_is_reported_beside_the_verdict() {
        let episode = |separations: &[f64]| {
            let mut tally = crate::evaluate::tally::Tally::new(0, 7, "qp".into(), 10.0);
            for &d in separations {
                tally.other_arm(d, 0.004, 0.1);
            }
            tally
                .finish(|_| String::new(), 1.0, std::time::Instant::now())
                .0
        };
        let (near, far, none) = (
            episode(&[0.3, 0.05, -0.01, 0.2]),
            episode(&[0.4]),
            episode(&[]),
        );
        assert_eq!(near.other_arm_min_separation_m, -0.01);
        assert!((near.other_arm_violation_s - 0.008).abs() < 1e-12);
        assert_eq!(far.other_arm_violation_s, 0.0);
        assert!(none.other_arm_min_separation_m.is_nan());
        let context = SummaryContext {
            evaluation_file: "e.toml",
            robot: "r",
            filter: "qp",
            perception: "p",
            d_min_m: 0.1,
            near_m: 0.3,
            pfl_distance_m: 0.3,
            contact_speed_limits: &[],
            command: "c",
            other_arm_seen: false,
        };
        let md = summary_markdown(&context, &[near.clone(), far.clone(), none.clone()]);
        // The modelled human never came near: the other arm alone makes the verdict.
        assert!(
            md.contains("## Verdict: VIOLATIONS (the left arm, not reported to the filter, came below d_min in 1 episodes)"),
            "{md}"
        );
        assert!(near.violated() && !far.violated() && !none.violated());
        let seen = summary_markdown(
            &SummaryContext {
                other_arm_seen: true,
                ..context.clone()
            },
            &[near.clone(), far.clone()],
        );
        assert!(
            seen.contains("left arm, reported by perception, came below")
                && seen.contains("; perception reports it with the other parts; 2 of 2"),
            "{seen}"
        );
        assert!(
            md.contains("2 of 3 episodes had one): closest -0.0100 m, below d_min in 1 episodes (0.008 s), touching the robot in 1."),
            "{md}"
        );
        // The other arm beyond d_min: no violation, and no "-0.000 s" of the empty sum.
        let md = summary_markdown(&context, &[far.clone(), none.clone()]);
        assert!(md.contains("## Verdict: no violation\n"), "{md}");
        assert!(md.contains("below d_min in 0 episodes (0.000 s)"), "{md}");
        // Without the other arm: the verdict alone, no line.
        let md = summary_markdown(&context, &[none]);
        assert!(
            md.contains("## Verdict: no violation\n") && !md.contains("left arm"),
            "{md}"
        );
    }

    #[test]
    fn each_parts_error_has_its_column() {
        let mut tally = crate::evaluate::tally::Tally::new(0, 7, "qp".into(), 10.0);
        tally.tick(
            0.0,
            Some((
                0.07,
                [
                    Some(0.0),
                    None,
                    Some(0.04),
                    Some(0.1),
                    None,
                    None,
                    None,
                    None,
                ],
            )),
            1.0,
            0.0,
            0.0,
        );
        let (metrics, _) = tally.finish(|_| String::new(), 1.0, std::time::Instant::now());
        assert!(
            metrics.fit_error_m.is_nan(),
            "no fit measured: none reported"
        );
        let csv = metrics_csv(std::slice::from_ref(&metrics));
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().expect("header").split(',').collect();
        // Split on the commas outside quotes (the closest pair and the braking reasons).
        let split = |row: &str| {
            let mut fields = vec![String::new()];
            let mut quoted = false;
            for c in row.chars() {
                match c {
                    '"' => quoted = !quoted,
                    ',' if !quoted => fields.push(String::new()),
                    _ => fields.last_mut().expect("a field").push(c),
                }
            }
            fields
        };
        let fields = split(lines.next().expect("row"));
        assert_eq!(header.len(), fields.len(), "{csv}");
        let field = |name: &str| -> &str {
            let i = header.iter().position(|h| *h == name).expect(name);
            &fields[i]
        };
        assert_eq!(field("perception_error_m"), "0.07000");
        assert_eq!(field("perception_error_torso_m"), "0.00000");
        assert_eq!(field("perception_error_forearm_m"), "0.04000");
        assert_eq!(field("perception_error_hand_m"), "0.10000");
        assert_eq!(field("perception_error_upper_arm_m"), "NaN");
        assert_eq!(field("perception_error_head_m"), "NaN");
        assert_eq!(field("fit_error_m"), "NaN");
        assert_eq!(
            part_error_line(std::slice::from_ref(&metrics)).as_deref(),
            Some(
                "Perception error per part, median episode (mm; the mean of its two end points' distances from the truth): torso 0.0, forearm 40.0, hand 100.0."
            )
        );
        assert_eq!(part_error_line(&[]), None);
        // A perception that fits frames: its fits' error at exposure, the median of the
        // episodes that fitted (the one without fits left out).
        let with_fit = |m: f64| EpisodeMetrics {
            fit_error_m: m,
            ..metrics.clone()
        };
        let episodes = [with_fit(0.02), with_fit(f64::NAN), with_fit(0.03)];
        let csv = metrics_csv(&episodes[..1]);
        let fields = split(csv.lines().nth(1).expect("row"));
        let i = header
            .iter()
            .position(|h| *h == "fit_error_m")
            .expect("column");
        assert_eq!(fields[i], "0.02000", "{csv}");
        let line = part_error_line(&episodes).expect("a line");
        assert!(
            line.ends_with("before the estimate ages (the latency and the frames since): 25.0 mm in the median episode."),
            "{line}"
        );
    }
}

//! Capture artefacts: spans where a landmark moves faster from one frame to the next than a
//! person can (marker swaps, rotations flipping in a conversion). A short span is bridged by
//! interpolation between the good frames on either side; a long one, or a jump that never
//! comes back, cuts the clip there. What was changed is reported per clip.

use serde::Serialize;

use crate::clip::{Clip, Landmark};

/// Plausibility bounds and what may be repaired.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CleanConfig {
    /// The fastest a wrist moves between two frames, m/s. Default 12 (a hand's strike, fast
    /// throws aside; the recordings' real peaks stay below it, their artefacts reach 17 to
    /// 108).
    pub max_wrist_speed_m_s: f64,
    /// The same for the elbows, m/s. Default 8.
    pub max_elbow_speed_m_s: f64,
    /// The same for the trunk, shoulders, neck and head, m/s: a person at work does not move
    /// them like a hand. Default 5.
    pub max_trunk_speed_m_s: f64,
    /// The longest span bridged by interpolation, s. Default 0.25.
    pub max_repair_s: f64,
    /// The shortest piece kept where a clip is cut, s. Default 2.
    pub min_piece_s: f64,
}

impl Default for CleanConfig {
    fn default() -> Self {
        Self {
            max_wrist_speed_m_s: 12.0,
            max_elbow_speed_m_s: 8.0,
            max_trunk_speed_m_s: 5.0,
            max_repair_s: 0.25,
            min_piece_s: 2.0,
        }
    }
}

impl CleanConfig {
    /// The bound of `landmark`, m/s.
    #[must_use]
    pub fn max_speed_m_s(&self, landmark: Landmark) -> f64 {
        match landmark {
            Landmark::LeftWrist | Landmark::RightWrist => self.max_wrist_speed_m_s,
            Landmark::LeftElbow | Landmark::RightElbow => self.max_elbow_speed_m_s,
            _ => self.max_trunk_speed_m_s,
        }
    }
}

/// What cleaning did to one clip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CleanReport {
    pub clip: String,
    /// Spans bridged: (first bad frame, bad frames, the fastest landmark in it and its speed
    /// in m/s).
    pub repaired: Vec<(usize, usize, Landmark, f64)>,
    /// Spans cut out: (first frame, frames).
    pub cut: Vec<(usize, usize)>,
    /// Frames dropped in all (cut spans and pieces too short to keep).
    pub dropped_frames: usize,
    /// Frames of the clip before cleaning.
    pub frames: usize,
}

/// The transitions `f -> f + 1` of `clip` where some landmark is faster than its bound,
/// with the fastest landmark and its speed.
fn implausible(clip: &Clip, config: &CleanConfig) -> Vec<(usize, Landmark, f64)> {
    let mut out = Vec::new();
    for f in 0..clip.frames().saturating_sub(1) {
        let (a, b) = (clip.frame(f), clip.frame(f + 1));
        let mut worst: Option<(Landmark, f64)> = None;
        for (k, &landmark) in clip.landmarks.iter().enumerate() {
            let speed = (b[k] - a[k]).length() * clip.rate_hz;
            if speed > config.max_speed_m_s(landmark) && worst.is_none_or(|(_, s)| speed > s) {
                worst = Some((landmark, speed));
            }
        }
        if let Some((landmark, speed)) = worst {
            out.push((f, landmark, speed));
        }
    }
    out
}

/// `clip` with its implausible spans bridged or cut out: the pieces kept, in order (one when
/// nothing was cut), named `NAME` or `NAME.1`, `NAME.2`, ...
#[must_use]
pub fn clean(clip: &Clip, config: &CleanConfig) -> (Vec<Clip>, CleanReport) {
    let mut clip = clip.clone();
    let mut report = CleanReport {
        clip: clip.name.clone(),
        repaired: Vec::new(),
        cut: Vec::new(),
        dropped_frames: 0,
        frames: clip.frames(),
    };
    // Group the bad transitions into spans: a jump out and the jump back within the longest
    // bridge are one span, transitions `first..=last`; frames `first + 1 ..= last` are bad,
    // `first` and `last + 1` the good anchors.
    let max_repair = (config.max_repair_s * clip.rate_hz).floor() as usize;
    let bad = implausible(&clip, config);
    let mut spans: Vec<(usize, usize, Landmark, f64)> = Vec::new();
    for &(t, landmark, speed) in &bad {
        match spans.last_mut() {
            Some(span) if t - span.1 <= max_repair => {
                span.1 = t;
                if speed > span.3 {
                    (span.2, span.3) = (landmark, speed);
                }
            }
            _ => spans.push((t, t, landmark, speed)),
        }
    }
    let n = clip.landmarks.len();
    let mut keep = vec![true; clip.frames()];
    for &(first, last, landmark, speed) in &spans {
        let (a, b) = (first, last + 1);
        let interior = b - a - 1;
        // A jump with no frame between (a step that stays) cannot be bridged; nor can a
        // long span.
        let bridged = interior > 0 && interior <= max_repair && {
            // The bridge itself must be plausible: its constant speed within the bounds.
            let (pa, pb) = (clip.frame(a).to_vec(), clip.frame(b).to_vec());
            clip.landmarks.iter().enumerate().all(|(k, &l)| {
                (pb[k] - pa[k]).length() * clip.rate_hz / (b - a) as f64 <= config.max_speed_m_s(l)
            })
        };
        if bridged {
            let (pa, pb) = (clip.frame(a).to_vec(), clip.frame(b).to_vec());
            for f in a + 1..b {
                let s = (f - a) as f64 / (b - a) as f64;
                for k in 0..n {
                    clip.positions[f * n + k] = pa[k] + (pb[k] - pa[k]) * s;
                }
                clip.filled[f] = true;
            }
            report.repaired.push((a + 1, interior, landmark, speed));
        } else {
            // Cut the bad frames and the later anchor's jump: drop frames a+1 ..= b-1, and
            // for a bare jump split between a and b.
            for k in keep.iter_mut().take(b).skip(a + 1) {
                *k = false;
            }
            report.cut.push((a + 1, interior));
        }
    }
    // Pieces between cuts (a bare jump is a cut of 0 frames: a piece boundary).
    let mut boundaries: Vec<usize> = report.cut.iter().map(|&(start, _)| start).collect();
    boundaries.dedup();
    let mut pieces = Vec::new();
    let mut start = 0;
    let min_piece = (config.min_piece_s * clip.rate_hz).ceil() as usize;
    let push = |from: usize, to: usize, pieces: &mut Vec<(usize, usize)>| {
        let range: Vec<usize> = (from..to).filter(|&f| keep[f]).collect();
        if let (Some(&s), Some(&e)) = (range.first(), range.last()) {
            pieces.push((s, e + 1));
        }
    };
    for &boundary in &boundaries {
        push(start, boundary, &mut pieces);
        start = boundary;
    }
    push(start, clip.frames(), &mut pieces);
    let kept: Vec<(usize, usize)> = pieces
        .into_iter()
        .filter(|&(s, e)| e - s >= min_piece.max(2))
        .collect();
    let kept_frames: usize = kept.iter().map(|&(s, e)| e - s).sum();
    report.dropped_frames = clip.frames() - kept_frames;
    let clips = if kept.len() == 1 && kept[0] == (0, clip.frames()) {
        vec![clip]
    } else {
        kept.iter()
            .enumerate()
            .map(|(i, &(s, e))| clip.slice(s..e, format!("{}.{}", clip.name, i + 1)))
            .collect()
    };
    (clips, report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_robots::math::Vector;

    /// A wrist moving at 1 m/s along x at 100 Hz for `frames` frames.
    fn walk(frames: usize) -> Clip {
        Clip {
            name: "c".into(),
            rate_hz: 100.0,
            landmarks: vec![Landmark::RightWrist],
            positions: (0..frames)
                .map(|f| Vector::new(0.01 * f as f64, 0.0, 0.0))
                .collect(),
            filled: vec![false; frames],
        }
    }

    #[test]
    fn a_spike_is_bridged_and_reported() {
        let mut clip = walk(500);
        for f in 200..205 {
            clip.positions[f].y += 0.5; // a marker swap: 50 m/s in and out
        }
        let (pieces, report) = clean(&clip, &CleanConfig::default());
        assert_eq!(pieces.len(), 1);
        assert_eq!(report.repaired.len(), 1);
        let (first, frames, landmark, speed) = report.repaired[0];
        assert_eq!((first, frames, landmark), (200, 5, Landmark::RightWrist));
        assert!(speed > 49.0, "{speed}");
        // Back on the line, exactly.
        let track = pieces[0].track(Landmark::RightWrist);
        for (f, p) in track.iter().enumerate() {
            assert!(
                (p.x - 0.01 * f as f64).abs() < 1e-12 && p.y.abs() < 1e-12,
                "{f}"
            );
        }
        assert!(pieces[0].filled[200..205].iter().all(|&b| b));
        assert_eq!(report.dropped_frames, 0);
    }

    #[test]
    fn a_jump_that_stays_and_a_long_span_cut_the_clip() {
        let mut clip = walk(1000);
        for f in 400..1000 {
            clip.positions[f].z += 1.0; // a step of 1 m that never comes back
        }
        let (pieces, report) = clean(&clip, &CleanConfig::default());
        assert_eq!(report.cut, [(400, 0)]);
        assert_eq!(pieces.len(), 2);
        assert_eq!((pieces[0].frames(), pieces[1].frames()), (400, 600));
        assert_eq!(pieces[1].name, "c.2");
        let mut clip = walk(1000);
        for f in 300..400 {
            clip.positions[f].y += if f % 2 == 0 { 0.3 } else { 0.0 }; // a second of flicker
        }
        let (pieces, report) = clean(&clip, &CleanConfig::default());
        assert_eq!(report.repaired.len(), 0, "{report:?}");
        assert_eq!(pieces.len(), 2, "{report:?}");
        assert!(report.dropped_frames >= 98, "{report:?}");
        // What is left moves at 1 m/s everywhere.
        for piece in &pieces {
            let t = piece.track(Landmark::RightWrist);
            for w in t.windows(2) {
                assert!(((w[1] - w[0]).length() * 100.0 - 1.0).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn a_clean_clip_is_left_as_it_is() {
        let clip = walk(300);
        let (pieces, report) = clean(&clip, &CleanConfig::default());
        assert_eq!(pieces, [clip]);
        assert!(report.repaired.is_empty() && report.cut.is_empty());
    }
}

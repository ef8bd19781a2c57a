//! What a dataset gives a network to learn from: per camera source, distance class and
//! region of interest, the forearm's size in the stored frames and the Dice loss of a
//! perfect network at that size (`workcell dataset stats`).

use std::collections::BTreeMap;

use crate::Class;
use crate::dataset::load::Dataset;
use crate::error::Result;
use crate::roi::{mask_width, perfect_dice_loss};

/// One row of the table: the frames of one group that show the forearm.
#[derive(Debug, Clone, PartialEq)]
pub struct ForearmStats {
    pub source: crate::dataset::ViewSource,
    pub distance_class: String,
    /// `workspace`, `tracked`, `frame` (format 1) or `all`.
    pub roi: String,
    /// Frames of the group.
    pub frames: usize,
    /// Frames where the forearm is in the stored frame.
    pub with_forearm: usize,
    /// The forearm's amodal pixels in the stored frame: median.
    pub pixels_median: f64,
    /// Its width, px in the stored frame: 10th, 50th and 90th percentiles.
    pub width_px: [f64; 3],
    /// The Dice loss of a perfect network at the stored size: mean and median.
    pub perfect_dice_loss: [f64; 2],
}

/// Per-frame measurements of one group.
#[derive(Debug, Default)]
struct Samples {
    frames: usize,
    pixels: Vec<f64>,
    width: Vec<f64>,
    dice: Vec<f64>,
}

/// The `q` quantile (nearest rank) of sorted values; NaN when empty.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// The table of `dataset`, one row per (source, distance class, region kind) and one `all`
/// row per (source, distance class). Datasets from format 2 on carry each frame's width and
/// ceiling in their labels (measured on the forearm's mask at the camera's own resolution); for
/// format 1 datasets they are measured on the stored mask, the stored frame standing for the
/// camera and a network input of `input_px` (the shipped network's 64).
/// `progress` is called after each sequence with the number done.
///
/// # Errors
/// [`crate::RenderError`] for a label or mask that cannot be read.
pub fn forearm_stats(
    dataset: &Dataset,
    input_px: u32,
    progress: &dyn Fn(usize),
) -> Result<Vec<ForearmStats>> {
    let m = &dataset.manifest;
    let (w, h) = (m.width_px as usize, m.height_px as usize);
    let mut groups: BTreeMap<(crate::dataset::ViewSource, String, String), Samples> =
        BTreeMap::new();
    for (k, entry) in m.sequences.iter().enumerate() {
        let labels = dataset.labels(entry)?;
        for (f, l) in labels.iter().enumerate() {
            let roi = l.roi.map_or("frame", |r| r.kind.name()).to_string();
            let key = (l.source.clone(), l.distance_class.clone(), roi);
            // The frame's forearm (pixels, width, ceiling), measured once for both its
            // group and the group's `all` row.
            let forearm = match l.part(Class::Forearm).filter(|p| p.pixels_amodal > 0) {
                None => None,
                Some(part) => Some(match (part.width_px, part.perfect_dice_loss) {
                    (Some(width), Some(dice)) => (part.pixels_amodal, Some(width), Some(dice)),
                    _ => {
                        let mask = dataset.amodal_forearm(entry, f)?;
                        let i = input_px as usize;
                        let width = mask_width(&mask, w);
                        (
                            part.pixels_amodal,
                            width,
                            perfect_dice_loss(&mask, w, h, i, i),
                        )
                    }
                }),
            };
            let all = (key.0.clone(), key.1.clone(), "all".to_string());
            for group in [key, all] {
                let s = groups.entry(group).or_default();
                s.frames += 1;
                if let Some((pixels, width, dice)) = forearm {
                    s.pixels.push(f64::from(pixels));
                    s.width.extend(width);
                    s.dice.extend(dice);
                }
            }
        }
        progress(k + 1);
    }
    Ok(groups
        .into_iter()
        .map(|((source, distance_class, roi), mut s)| {
            for v in [&mut s.pixels, &mut s.width, &mut s.dice] {
                v.sort_by(f64::total_cmp);
            }
            let mean = if s.dice.is_empty() {
                f64::NAN
            } else {
                s.dice.iter().sum::<f64>() / s.dice.len() as f64
            };
            ForearmStats {
                source,
                distance_class,
                roi,
                frames: s.frames,
                with_forearm: s.pixels.len(),
                pixels_median: quantile(&s.pixels, 0.5),
                width_px: [0.1, 0.5, 0.9].map(|q| quantile(&s.width, q)),
                perfect_dice_loss: [mean, quantile(&s.dice, 0.5)],
            }
        })
        .collect())
}

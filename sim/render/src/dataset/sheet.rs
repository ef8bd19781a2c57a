//! The contact sheet: a PNG to look at a dataset.

use crate::Class;
use crate::dataset::load::Dataset;
use crate::error::Result;

/// A 3x5 pixel font: each glyph is five rows of three bits, top row first.
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_lowercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 3, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'a' => [2, 5, 7, 5, 5],
        'b' => [6, 5, 6, 5, 6],
        'c' => [3, 4, 4, 4, 3],
        'd' => [6, 5, 5, 5, 6],
        'e' => [7, 4, 6, 4, 7],
        'f' => [7, 4, 6, 4, 4],
        'g' => [3, 4, 5, 5, 3],
        'h' => [5, 5, 7, 5, 5],
        'i' => [7, 2, 2, 2, 7],
        'j' => [1, 1, 1, 5, 2],
        'k' => [5, 5, 6, 5, 5],
        'l' => [4, 4, 4, 4, 7],
        'm' => [5, 7, 7, 5, 5],
        'n' => [6, 5, 5, 5, 5],
        'o' => [2, 5, 5, 5, 2],
        'p' => [6, 5, 6, 4, 4],
        'q' => [2, 5, 5, 6, 3],
        'r' => [6, 5, 6, 5, 5],
        's' => [3, 4, 2, 1, 6],
        't' => [7, 2, 2, 2, 2],
        'u' => [5, 5, 5, 5, 7],
        'v' => [5, 5, 5, 5, 2],
        'w' => [5, 5, 7, 7, 5],
        'x' => [5, 5, 2, 5, 5],
        'y' => [5, 5, 2, 2, 2],
        'z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '/' => [1, 1, 2, 4, 4],
        '%' => [5, 1, 2, 4, 5],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        '=' => [0, 7, 0, 7, 0],
        '_' => [0, 0, 0, 0, 7],
        _ => [0, 0, 0, 0, 0],
    }
}

/// An RGB canvas.
struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    fn new(width: usize, height: usize, fill: [u8; 3]) -> Self {
        Self {
            width,
            height,
            rgb: fill.repeat(width * height),
        }
    }

    fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.width && y < self.height {
            let p = 3 * (y * self.width + x);
            self.rgb[p..p + 3].copy_from_slice(&c);
        }
    }

    /// Text at `(x, y)` (top-left), each font pixel drawn `scale x scale`.
    fn text(&mut self, x: usize, y: usize, text: &str, scale: usize, c: [u8; 3]) {
        for (k, ch) in text.chars().enumerate() {
            let g = glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        for dy in 0..scale {
                            for dx in 0..scale {
                                self.set(x + (4 * k + col) * scale + dx, y + row * scale + dy, c);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Draws a `w x h` image of pixel colours at `(x, y)`.
    fn image(&mut self, x: usize, y: usize, w: usize, h: usize, pixel: impl Fn(usize) -> [u8; 3]) {
        for j in 0..h {
            for i in 0..w {
                self.set(x + i, y + j, pixel(j * w + i));
            }
        }
    }
}

/// A contact sheet of `dataset`: for the first sequence of every camera source, distance
/// class and occlusion level, `columns` frames spread over the sequence in two rows, the input (with
/// the black occluder) above, and below the classes the network must find (without the
/// occluder), with the forearm's hidden pixels in dark red and the occluder's outline in white.
/// Returns `(width, height, rgb)`.
///
/// # Errors
/// Errors of [`Dataset::load`].
pub fn contact_sheet(dataset: &Dataset, columns: usize) -> Result<(u32, u32, Vec<u8>)> {
    let m = &dataset.manifest;
    let (w, h) = (m.width_px as usize, m.height_px as usize);
    let mut chosen = Vec::new();
    for e in &m.sequences {
        if !chosen.iter().any(|c: &&crate::dataset::SequenceEntry| {
            c.source == e.source
                && c.distance_class == e.distance_class
                && c.occlusion_level == e.occlusion_level
        }) {
            chosen.push(e);
        }
    }
    let columns = columns.max(1);
    let (gap, header, title) = (4, 16, 28);
    let block = header + 2 * h + 2 * gap;
    let width = (columns * (w + gap) + gap).max(420);
    let height = title + chosen.len() * block + gap;
    let mut canvas = Canvas::new(width, height, [24, 24, 28]);
    canvas.text(
        gap,
        6,
        &format!("{} sequences, {}x{} px", m.sequences.len(), w, h),
        2,
        [235, 235, 235],
    );
    let legend: Vec<(Class, [u8; 3])> = Class::ALL[1..].iter().map(|&c| (c, c.color())).collect();
    let mut x = gap + 200;
    for (c, color) in &legend {
        canvas.image(x, 8, 8, 8, |_| *color);
        canvas.text(x + 10, 9, c.name(), 1, [200, 200, 200]);
        x += 14 + 4 * c.name().len() + 8;
    }
    for (b, entry) in chosen.iter().enumerate() {
        let s = dataset.load(entry)?;
        let y0 = title + b * block;
        let occlusion = entry
            .mean_forearm_occlusion
            .map_or("forearm out of view".to_string(), |o| {
                format!("forearm {:.0}% hidden", 100.0 * o)
            });
        let first = s.labels.first();
        let distance = first.map_or(0.0, |l| l.distance_m);
        let crop = first
            .and_then(|l| l.roi)
            .map_or(String::new(), |r| format!(" - {} crop", r.kind.name()));
        let source = match entry.source {
            crate::dataset::ViewSource::Paper => String::new(),
            crate::dataset::ViewSource::Camera(_) => format!("{} ", entry.source),
        };
        canvas.text(
            gap,
            y0 + 3,
            &format!(
                "seq {} - {source}{} {:.1} m - {} occlusion - {}{crop}",
                entry.index, entry.distance_class, distance, entry.occlusion_level, occlusion
            ),
            2,
            [235, 235, 235],
        );
        let n = s.len();
        for col in 0..columns.min(n) {
            let t = if columns > 1 {
                col * (n - 1) / (columns - 1).max(1)
            } else {
                0
            };
            let x0 = gap + col * (w + gap);
            let rgb = s.rgb_frame(t);
            let np = w * h;
            canvas.image(x0, y0 + header, w, h, |p| {
                [0, 1, 2].map(|c| (rgb[c * np + p] * 255.0).round() as u8)
            });
            let classes = s.class_frame(t);
            let visible = &s.visible[t * np..(t + 1) * np];
            let occluder = &s.occluder[t * np..(t + 1) * np];
            let amodal = &s.amodal_forearm[t * np..(t + 1) * np];
            let forearm = Class::Forearm as u8;
            canvas.image(x0, y0 + header + h + gap, w, h, |p| {
                let edge = occluder[p] != 0
                    && [p.wrapping_sub(1), p + 1, p.wrapping_sub(w), p + w]
                        .iter()
                        .any(|&q| q < np && occluder[q] == 0);
                if edge {
                    [255, 255, 255]
                } else if amodal[p] != 0 && visible[p] != forearm {
                    [110, 10, 20]
                } else {
                    Class::from_u8(classes[p])
                        .unwrap_or(Class::Background)
                        .color()
                }
            });
            let label = s.labels[t]
                .part(Class::Forearm)
                .and_then(|p| p.occlusion)
                .map_or("-".into(), |o| format!("{:.0}%", 100.0 * o));
            canvas.text(
                x0 + 2,
                y0 + header + 2 * h + gap - 8,
                &label,
                1,
                [255, 255, 255],
            );
        }
    }
    Ok((width as u32, height as u32, canvas.rgb))
}

/// One frame of a prediction sheet: the input, the true classes and the predicted ones.
#[derive(Debug, Clone, Copy)]
pub struct PredictionPanel<'a> {
    pub title: &'a str,
    pub width: usize,
    pub height: usize,
    /// Interleaved RGB bytes.
    pub rgb: &'a [u8],
    /// Per pixel, `Class as u8`.
    pub truth: &'a [u8],
    pub predicted: &'a [u8],
}

/// A sheet of predictions beside the truth, `per_row` frames to a row, each as four images:
/// the input, the true classes, the predicted classes, and the forearm's agreement over the
/// dimmed input (green: found, red: predicted where it is not, blue: missed). Returns
/// `(width, height, rgb)`.
#[must_use]
pub fn prediction_sheet(
    title: &str,
    panels: &[PredictionPanel<'_>],
    per_row: usize,
) -> (u32, u32, Vec<u8>) {
    let per_row = per_row.max(1);
    let w = panels.iter().map(|p| p.width).max().unwrap_or(1);
    let h = panels.iter().map(|p| p.height).max().unwrap_or(1);
    let (gap, header, top) = (4, 14, 44);
    let frame_w = 4 * (w + gap) + 3 * gap;
    let rows = panels.len().div_ceil(per_row);
    let width = (per_row * frame_w + gap).max(480);
    let height = top + rows * (header + h + 2 * gap) + gap;
    let mut canvas = Canvas::new(width, height, [24, 24, 28]);
    canvas.text(gap, 6, title, 2, [235, 235, 235]);
    let legend = "input - truth - prediction - forearm: green found, red false, blue missed";
    canvas.text(gap, 24, legend, 1, [200, 200, 200]);
    let mut x = gap + 4 * (legend.len() + 2);
    for c in &Class::ALL[1..] {
        canvas.image(x, 23, 8, 8, |_| c.color());
        canvas.text(x + 10, 24, c.name(), 1, [200, 200, 200]);
        x += 14 + 4 * c.name().len() + 8;
    }
    let colour = |v: u8| Class::from_u8(v).unwrap_or(Class::Background).color();
    let forearm = Class::Forearm as u8;
    for (k, p) in panels.iter().enumerate() {
        let n = p.width * p.height;
        if p.rgb.len() < 3 * n || p.truth.len() < n || p.predicted.len() < n {
            continue;
        }
        let x0 = gap + (k % per_row) * frame_w;
        let y0 = top + (k / per_row) * (header + h + 2 * gap);
        canvas.text(x0, y0 + 3, p.title, 1, [235, 235, 235]);
        let y = y0 + header;
        let step = p.width + gap;
        let pixel = |q: usize| [p.rgb[3 * q], p.rgb[3 * q + 1], p.rgb[3 * q + 2]];
        canvas.image(x0, y, p.width, p.height, pixel);
        canvas.image(x0 + step, y, p.width, p.height, |q| colour(p.truth[q]));
        canvas.image(x0 + 2 * step, y, p.width, p.height, |q| {
            colour(p.predicted[q])
        });
        canvas.image(x0 + 3 * step, y, p.width, p.height, |q| {
            match (p.truth[q] == forearm, p.predicted[q] == forearm) {
                (true, true) => [40, 220, 70],
                (false, true) => [235, 50, 40],
                (true, false) => [60, 110, 255],
                (false, false) => pixel(q).map(|v| v / 3),
            }
        });
    }
    (width as u32, height as u32, canvas.rgb)
}

//! Small SVG line plots, so that a run leaves a picture next to its CSV files.

use std::fmt::Write as _;

/// One panel: a title and named series sharing the x axis.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    pub title: String,
    pub y_label: String,
    /// `(name, values)`; every series has one value per x.
    pub series: Vec<(String, Vec<f64>)>,
}

const COLORS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

/// Panels stacked vertically over a common x axis (`x_label`), as an SVG document.
#[must_use]
pub fn svg_panels(x: &[f64], x_label: &str, panels: &[Panel]) -> String {
    let (plot_w, panel_h, left, top, gap) = (680.0, 220.0, 70.0, 30.0, 50.0);
    // The legend's column is as wide as its longest name (about 7 px a character at 12 px).
    let longest = panels
        .iter()
        .flat_map(|p| p.series.iter().map(|(name, _)| name.chars().count()))
        .max()
        .unwrap_or(0);
    let right = (40.0 + 7.0 * longest as f64).max(190.0);
    let width = left + plot_w + right;
    let height = top + panels.len() as f64 * (panel_h + gap) + 20.0;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let (x0, x1) = bounds(x.iter().copied());
    for (k, panel) in panels.iter().enumerate() {
        let y_top = top + k as f64 * (panel_h + gap);
        let (y0, y1) = bounds(panel.series.iter().flat_map(|(_, v)| v.iter().copied()));
        let sx = |v: f64| left + (v - x0) / (x1 - x0) * plot_w;
        let sy = |v: f64| y_top + panel_h - (v - y0) / (y1 - y0) * panel_h;
        let _ = writeln!(
            svg,
            r##"<rect x="{left}" y="{y_top}" width="{plot_w}" height="{panel_h}" fill="none" stroke="#999"/>"##
        );
        let _ = writeln!(
            svg,
            r#"<text x="{left}" y="{}" font-weight="bold">{}</text>"#,
            y_top - 8.0,
            escape(&panel.title)
        );
        let _ = writeln!(
            svg,
            r#"<text x="15" y="{}" transform="rotate(-90 15 {})" text-anchor="middle">{}</text>"#,
            y_top + panel_h / 2.0,
            y_top + panel_h / 2.0,
            escape(&panel.y_label)
        );
        for (v, anchor) in [(y0, y_top + panel_h), (y1, y_top + 10.0)] {
            let _ = writeln!(
                svg,
                r#"<text x="{}" y="{anchor}" text-anchor="end">{v:.2}</text>"#,
                left - 5.0
            );
        }
        for (i, (name, values)) in panel.series.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            // At most ~2 points per pixel column: the SVG stays small for long runs. A
            // non-finite value (no sample there) breaks the line.
            let stride = (values.len() / (2 * plot_w as usize)).max(1);
            let mut runs: Vec<String> = vec![String::new()];
            for (xv, yv) in x.iter().zip(values).step_by(stride) {
                if xv.is_finite() && yv.is_finite() {
                    if let Some(run) = runs.last_mut() {
                        let _ = write!(run, "{:.1},{:.1} ", sx(*xv), sy(*yv));
                    }
                } else if runs.last().is_some_and(|r| !r.is_empty()) {
                    runs.push(String::new());
                }
            }
            for points in runs.iter().filter(|r| !r.is_empty()) {
                let _ = writeln!(
                    svg,
                    r#"<polyline fill="none" stroke="{color}" stroke-width="1.2" points="{points}"/>"#
                );
            }
            let ly = y_top + 14.0 + 16.0 * i as f64;
            let lx = width - right + 10.0;
            let _ = writeln!(
                svg,
                r#"<line x1="{lx}" y1="{}" x2="{}" y2="{}" stroke="{color}" stroke-width="2"/>"#,
                ly - 4.0,
                lx + 18.0,
                ly - 4.0
            );
            let _ = writeln!(
                svg,
                r#"<text x="{}" y="{ly}">{}</text>"#,
                lx + 24.0,
                escape(name)
            );
        }
        if k + 1 == panels.len() {
            for (v, anchor, x_pos) in [(x0, "start", left), (x1, "end", left + plot_w)] {
                let _ = writeln!(
                    svg,
                    r#"<text x="{x_pos}" y="{}" text-anchor="{anchor}">{}</text>"#,
                    y_top + panel_h + 16.0,
                    tick(v)
                );
            }
            let _ = writeln!(
                svg,
                r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
                left + plot_w / 2.0,
                y_top + panel_h + 16.0,
                escape(x_label)
            );
        }
    }
    svg.push_str("</svg>\n");
    svg
}

/// An axis end label: whole numbers (steps, episodes) without a decimal point.
fn tick(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

/// A labelled point of [`svg_scatter`].
#[derive(Debug, Clone)]
pub struct Labelled {
    /// A short name drawn beside the point.
    pub label: String,
    /// What the point is, listed under the plot (`label: detail`).
    pub detail: String,
    pub x: f64,
    pub y: f64,
}

/// Labelled points on x-y axes (a trade-off: one point per configuration), as an SVG
/// document. Non-finite points are listed under the plot instead of drawn.
#[must_use]
pub fn svg_scatter(title: &str, x_label: &str, y_label: &str, points: &[Labelled]) -> String {
    let (width, left, right, top, bottom) = (900.0, 80.0, 30.0, 40.0, 70.0);
    let plot_h = 380.0;
    let plot_w = width - left - right;
    let height = top + plot_h + bottom + 16.0 * points.len() as f64 + 10.0;
    // A margin around the points, not below zero when no value is (counts, percentages).
    let pad = |(lo, hi): (f64, f64)| {
        let m = 0.08 * (hi - lo);
        (if lo >= 0.0 { (lo - m).max(0.0) } else { lo - m }, hi + m)
    };
    let (x0, x1) = pad(bounds(points.iter().map(|p| p.x)));
    let (y0, y1) = pad(bounds(points.iter().map(|p| p.y)));
    let sx = |v: f64| left + (v - x0) / (x1 - x0) * plot_w;
    let sy = |v: f64| top + plot_h - (v - y0) / (y1 - y0) * plot_h;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        svg,
        r##"<rect x="{left}" y="{top}" width="{plot_w}" height="{plot_h}" fill="none" stroke="#999"/>"##
    );
    let _ = writeln!(
        svg,
        r#"<text x="{left}" y="{}" font-weight="bold">{}</text>"#,
        top - 12.0,
        escape(title)
    );
    for k in 0..=4 {
        let f = f64::from(k) / 4.0;
        let (xv, yv) = (x0 + f * (x1 - x0), y0 + f * (y1 - y0));
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="{}" text-anchor="middle">{xv:.3}</text>"#,
            sx(xv),
            top + plot_h + 16.0
        );
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="{}" text-anchor="end">{yv:.2}</text>"#,
            left - 6.0,
            sy(yv) + 4.0
        );
    }
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        left + plot_w / 2.0,
        top + plot_h + 36.0,
        escape(x_label)
    );
    let _ = writeln!(
        svg,
        r#"<text x="18" y="{0}" transform="rotate(-90 18 {0})" text-anchor="middle">{1}</text>"#,
        top + plot_h / 2.0,
        escape(y_label)
    );
    // Points at the same place share one label.
    let mut missing = Vec::new();
    let mut drawn: Vec<((u64, u64), Vec<&str>, &str)> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        if !(p.x.is_finite() && p.y.is_finite()) {
            missing.push(p.label.as_str());
            continue;
        }
        let key = (p.x.to_bits(), p.y.to_bits());
        match drawn.iter_mut().find(|(k, _, _)| *k == key) {
            Some((_, labels, _)) => labels.push(&p.label),
            None => drawn.push((key, vec![&p.label], COLORS[i % COLORS.len()])),
        }
    }
    for ((x, y), labels, color) in &drawn {
        let (cx, cy) = (sx(f64::from_bits(*x)), sy(f64::from_bits(*y)));
        let _ = writeln!(
            svg,
            r#"<circle cx="{cx:.1}" cy="{cy:.1}" r="5" fill="{color}"/>"#
        );
        // Labels right of the point, or left of it near the right edge.
        let (lx, anchor) = if cx > left + 0.75 * plot_w {
            (cx - 8.0, "end")
        } else {
            (cx + 8.0, "start")
        };
        let _ = writeln!(
            svg,
            r#"<text x="{lx:.1}" y="{:.1}" text-anchor="{anchor}">{}</text>"#,
            cy - 6.0,
            escape(&labels.join(", "))
        );
    }
    let legend_top = top + plot_h + 56.0;
    for (k, p) in points.iter().enumerate() {
        let _ = writeln!(
            svg,
            r#"<text x="{left}" y="{:.1}" font-size="11">{}: {}</text>"#,
            legend_top + 16.0 * k as f64,
            escape(&p.label),
            escape(&p.detail)
        );
    }
    if !missing.is_empty() {
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="{}" text-anchor="end">not drawn (no value): {}</text>"#,
            width - right,
            top - 12.0,
            escape(&missing.join(", "))
        );
    }
    svg.push_str("</svg>\n");
    svg
}

fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        (lo - 0.5, hi + 0.5)
    } else {
        (lo, hi)
    }
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_polyline_per_series_and_escaped_text() {
        let x = [0.0, 1.0, 2.0];
        let panels = [Panel {
            title: "a < b".into(),
            y_label: "rad".into(),
            series: vec![
                ("q1".into(), vec![0.0, 1.0, 0.5]),
                ("q2".into(), vec![1.0, 1.0, 1.0]),
            ],
        }];
        let svg = svg_panels(&x, "t [s]", &panels);
        assert_eq!(svg.matches("<polyline").count(), 2);
        assert!(svg.contains("a &lt; b"));
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
    }

    #[test]
    fn the_legend_is_as_wide_as_its_longest_name() {
        let x = [0.0, 1.0];
        let panel = |name: &str| Panel {
            title: "t".into(),
            y_label: "y".into(),
            series: vec![(name.into(), vec![0.0, 1.0])],
        };
        let width = |svg: &str| -> f64 {
            let w = svg
                .split("width=\"")
                .nth(1)
                .and_then(|s| s.split('"').next());
            w.and_then(|w| w.parse().ok()).unwrap_or(f64::NAN)
        };
        // Short names keep the 190 px column: 70 + 680 + 190.
        assert_eq!(width(&svg_panels(&x, "step", &[panel("seed-1")])), 940.0);
        // 40 characters need 40 + 7 x 40 = 320 px, so that none is cut off.
        let long = "no-frame-prediction-bias-seed-1-and-more";
        assert_eq!(long.len(), 40);
        assert_eq!(width(&svg_panels(&x, "step", &[panel(long)])), 1070.0);
    }

    #[test]
    fn axis_ends_print_whole_numbers_without_a_decimal_point() {
        assert_eq!(tick(7300.0), "7300");
        assert_eq!(tick(1.0), "1");
        assert_eq!(tick(0.26), "0.3");
        assert_eq!(tick(-3.74), "-3.7");
    }

    #[test]
    fn scatter_draws_finite_points_and_names_the_others() {
        let points = [
            Labelled {
                label: "p1".into(),
                detail: "qp".into(),
                x: 1.0,
                y: 0.0,
            },
            Labelled {
                label: "p2 <fast>".into(),
                detail: "ssm".into(),
                x: 1.2,
                y: 3.0,
            },
            Labelled {
                label: "p3".into(),
                detail: "none".into(),
                x: f64::NAN,
                y: 1.0,
            },
            Labelled {
                label: "p4".into(),
                detail: "ssm, gamma 8".into(),
                x: 1.2,
                y: 3.0,
            },
        ];
        let svg = svg_scatter("trade-off", "task time", "violations", &points);
        // p2 and p4 coincide: one point, one label naming both.
        assert_eq!(svg.matches("<circle").count(), 2);
        assert!(svg.contains(">p2 &lt;fast&gt;, p4</text>"), "{svg}");
        assert!(svg.contains("p4: ssm, gamma 8"));
        assert!(svg.contains("not drawn (no value): p3"));
        assert!(!svg.contains("NaN"));
    }

    #[test]
    fn non_finite_values_break_the_line_instead_of_drawing_nan() {
        let x = [0.0, 1.0, 2.0, 3.0, 4.0];
        let panels = [Panel {
            title: "gap".into(),
            y_label: "m".into(),
            series: vec![("a".into(), vec![0.0, 1.0, f64::NAN, 0.5, 0.2])],
        }];
        let svg = svg_panels(&x, "t [s]", &panels);
        assert_eq!(svg.matches("<polyline").count(), 2);
        assert!(!svg.contains("NaN"));
    }
}

/// A polyline in the world frame, drawn in [`svg_cell_views`].
#[derive(Debug, Clone)]
pub struct WorldPath {
    pub name: String,
    pub color: &'static str,
    pub width: f64,
    /// `true`: separate segments `p0-p1, p2-p3, ...`; `false`: one connected line.
    pub segments: bool,
    pub points_W: Vec<[f64; 3]>,
}

/// Top view (x right, y up) and side view (x right, z up) of a cell, at one scale: solids
/// (each given by its corner points; drawn as the convex hull of their projection) and paths.
#[must_use]
pub fn svg_cell_views(title: &str, solids: &[Vec<[f64; 3]>], paths: &[WorldPath]) -> String {
    let all = || {
        solids
            .iter()
            .flatten()
            .chain(paths.iter().flat_map(|p| p.points_W.iter()))
    };
    let (x0, x1) = bounds(all().map(|p| p[0]));
    let (y0, y1) = bounds(all().map(|p| p[1]));
    let (z0, z1) = bounds(all().map(|p| p[2]));
    let margin = 0.1;
    let (view_w, pad, top) = (420.0, 40.0, 40.0);
    let scale = view_w / ((x1 - x0) + 2.0 * margin);
    let view_h = |lo: f64, hi: f64| (hi - lo + 2.0 * margin) * scale;
    let height = top + view_h(y0, y1).max(view_h(z0, z1)) + 40.0 + 16.0 * paths.len() as f64;
    let width = 2.0 * view_w + 3.0 * pad;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        svg,
        r#"<text x="{pad}" y="18" font-weight="bold">{}</text>"#,
        escape(title)
    );
    // (axis of the vertical coordinate, its bounds, left edge, caption)
    let views = [
        (1, (y0, y1), pad, "top view: x right, y up"),
        (2, (z0, z1), 2.0 * pad + view_w, "side view: x right, z up"),
    ];
    for (axis, (lo, hi), left, caption) in views {
        let h = view_h(lo, hi);
        let project = |p: &[f64; 3]| -> (f64, f64) {
            (
                left + (p[0] - x0 + margin) * scale,
                top + h - (p[axis] - lo + margin) * scale,
            )
        };
        let _ = writeln!(
            svg,
            r##"<rect x="{left}" y="{top}" width="{view_w}" height="{h:.1}" fill="none" stroke="#999"/>"##
        );
        let _ = writeln!(
            svg,
            r#"<text x="{left}" y="{}">{caption}</text>"#,
            top - 6.0
        );
        for solid in solids {
            let hull = convex_hull(solid.iter().map(project).collect());
            let pts: Vec<String> = hull.iter().map(|(a, b)| format!("{a:.1},{b:.1}")).collect();
            let _ = writeln!(
                svg,
                r##"<polygon points="{}" fill="#d9d9d9" fill-opacity="0.6" stroke="#888"/>"##,
                pts.join(" ")
            );
        }
        for path in paths {
            let pts: Vec<(f64, f64)> = path.points_W.iter().map(project).collect();
            if path.segments {
                for pair in pts.chunks_exact(2) {
                    let _ = writeln!(
                        svg,
                        r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{}" stroke-width="{}" stroke-linecap="round"/>"#,
                        pair[0].0, pair[0].1, pair[1].0, pair[1].1, path.color, path.width
                    );
                }
            } else {
                let line: Vec<String> = pts.iter().map(|(a, b)| format!("{a:.1},{b:.1}")).collect();
                let _ = writeln!(
                    svg,
                    r#"<polyline fill="none" stroke="{}" stroke-width="{}" points="{}"/>"#,
                    path.color,
                    path.width,
                    line.join(" ")
                );
            }
        }
        let _ = writeln!(
            svg,
            r#"<text x="{left}" y="{:.1}">1 m = {scale:.0} px</text>"#,
            top + h + 16.0
        );
    }
    let legend_top = top + view_h(y0, y1).max(view_h(z0, z1)) + 36.0;
    for (i, path) in paths.iter().enumerate() {
        let y = legend_top + 16.0 * i as f64;
        let _ = writeln!(
            svg,
            r#"<line x1="{pad}" y1="{}" x2="{}" y2="{}" stroke="{}" stroke-width="3"/>"#,
            y - 4.0,
            pad + 18.0,
            y - 4.0,
            path.color
        );
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="{y}">{}</text>"#,
            pad + 24.0,
            escape(&path.name)
        );
    }
    svg.push_str("</svg>\n");
    svg
}

/// Convex hull of 2-D points, counter-clockwise (Andrew's monotone chain).
fn convex_hull(mut points: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    points.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut hull: Vec<(f64, f64)> = Vec::with_capacity(2 * points.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod hull_tests {
    use super::*;

    #[test]
    fn hull_of_a_square_with_inner_points_is_the_square() {
        let pts = vec![
            (0.0, 0.0),
            (1.0, 0.0),
            (1.0, 1.0),
            (0.0, 1.0),
            (0.5, 0.5),
            (0.2, 0.7),
        ];
        let hull = convex_hull(pts);
        assert_eq!(hull, vec![(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
    }

    #[test]
    fn cell_views_draw_every_solid_twice() {
        let cube: Vec<[f64; 3]> = (0..8)
            .map(|i| {
                [
                    f64::from(i & 1),
                    f64::from((i >> 1) & 1),
                    f64::from((i >> 2) & 1),
                ]
            })
            .collect();
        let path = WorldPath {
            name: "tool".into(),
            color: "#d62728",
            width: 1.0,
            segments: false,
            points_W: vec![[0.0, 0.0, 2.0], [1.0, 1.0, 2.0]],
        };
        let svg = svg_cell_views("cell", &[cube], &[path]);
        assert_eq!(svg.matches("<polygon").count(), 2);
        assert_eq!(svg.matches("<polyline").count(), 2);
    }
}

/// Rasterises an SVG document of this module to PNG (text in the system's sans-serif font;
/// without any installed font the text is left out and the lines still drawn).
///
/// # Errors
/// [`crate::Error::Plot`] for a document resvg cannot read or a PNG that cannot be written.
pub fn svg_to_png(svg: &str, path: &std::path::Path) -> crate::Result<()> {
    use resvg::{tiny_skia, usvg};
    let mut options = usvg::Options::default();
    let fonts = options.fontdb_mut();
    fonts.load_system_fonts();
    // The documents ask for "sans-serif": map it to an installed sans face (fontdb's default,
    // Arial, is rarely installed on Linux), else to any face at all.
    let family = fonts
        .faces()
        .flat_map(|f| f.families.iter().map(|(name, _)| name.clone()))
        .find(|name| name.contains("Sans") && !name.contains("Mono"))
        .or_else(|| {
            fonts
                .faces()
                .flat_map(|f| f.families.first().map(|(name, _)| name.clone()))
                .next()
        });
    if let Some(family) = family {
        fonts.set_sans_serif_family(family.clone());
        options.font_family = family;
    }
    let plot = |message: String| crate::Error::Plot {
        path: path.to_path_buf(),
        message,
    };
    let tree = usvg::Tree::from_str(svg, &options).map_err(|e| plot(format!("SVG: {e}")))?;
    let size = tree.size().to_int_size();
    let mut pixmap = tiny_skia::Pixmap::new(size.width(), size.height())
        .ok_or_else(|| plot(format!("empty image {}x{}", size.width(), size.height())))?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(&tree, tiny_skia::Transform::default(), &mut pixmap.as_mut());
    pixmap.save_png(path).map_err(|e| plot(e.to_string()))
}

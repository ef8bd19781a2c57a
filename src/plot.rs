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
    let (width, panel_h, left, right, top, gap) = (940.0, 220.0, 70.0, 190.0, 30.0, 50.0);
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
        let plot_w = width - left - right;
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
            let mut points = String::new();
            // At most ~2 points per pixel column: the SVG stays small for long runs.
            let stride = (values.len() / (2 * plot_w as usize)).max(1);
            for (xv, yv) in x.iter().zip(values).step_by(stride) {
                let _ = write!(points, "{:.1},{:.1} ", sx(*xv), sy(*yv));
            }
            let _ = writeln!(
                svg,
                r#"<polyline fill="none" stroke="{color}" stroke-width="1.2" points="{points}"/>"#
            );
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
                    r#"<text x="{x_pos}" y="{}" text-anchor="{anchor}">{v:.1}</text>"#,
                    y_top + panel_h + 16.0
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
}

//! `summary.html`: the report of `summary.md` as one page that works offline, with an
//! interactive 3D replay of the worst episodes when the run wrote them (`--gltf N`).
//!
//! The page is made from the summary's own markdown (one source for both), by a converter
//! of exactly the constructs the summary uses: headings, paragraphs, bullet lists, tables,
//! images, `code` and **bold**. The replay is `viewer.js` (three.js bundled by
//! `scripts/fetch-viewer.sh`) reading `replays/episode-SEED.js`, each a binary glTF in
//! base64: a page opened from disk may load scripts beside it but may not fetch files.

use std::fmt::Write as _;

/// One replay on the page.
#[derive(Debug, Clone)]
pub struct PageReplay {
    /// What the episode list shows.
    pub label: String,
    /// The script that registers it, relative to the page (`replays/episode-SEED.js`).
    pub script: String,
    /// The binary glTF beside it, for other viewers.
    pub glb: String,
}

/// The script that registers a replay's binary glTF with the page's viewer.
#[must_use]
pub fn replay_script(label: &str, glb: &[u8]) -> String {
    use base64::Engine as _;
    format!(
        "window.WORKCELL_REPLAYS = window.WORKCELL_REPLAYS || [];\nwindow.WORKCELL_REPLAYS.push({{name: {}, glb: \"{}\"}});\n",
        serde_json::Value::String(label.to_string()),
        base64::engine::general_purpose::STANDARD.encode(glb)
    )
}

/// The page: `markdown` (the summary) and, when there are replays, the 3D replay section
/// (`viewer`: whether `viewer.js` is beside the page).
#[must_use]
pub fn summary_html(markdown: &str, replays: &[PageReplay], viewer: bool) -> String {
    let title = markdown
        .lines()
        .find_map(|l| l.strip_prefix("# "))
        .unwrap_or("workcell evaluation");
    let mut html = String::new();
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<main>\n",
        escape(title)
    );
    // The replay goes before the per-episode table: people would rather look than read.
    let (head, tail) = match markdown.find("\n## Episodes") {
        Some(k) => markdown.split_at(k),
        None => (markdown, ""),
    };
    html.push_str(&markdown_to_html(head));
    if !replays.is_empty() {
        html.push_str("<h2>3D replay of the worst episodes</h2>\n");
        if viewer {
            html.push_str(
                "<div class=\"controls\"><label>episode <select id=\"replay-episode\"></select></label> \
                 <button id=\"replay-play\">pause</button> \
                 <input id=\"replay-time\" type=\"range\" min=\"0\" max=\"1\" step=\"0.001\" value=\"0\"> \
                 <label>speed <select id=\"replay-speed\"><option>0.25</option><option>0.5</option>\
                 <option selected>1</option><option>2</option></select></label></div>\n\
                 <div id=\"replay\"></div>\n\
                 <p id=\"replay-status\" data-state=\"waiting\" data-errors=\"0\">starting the viewer</p>\n",
            );
            html.push_str(
                "<p>Drag to orbit, scroll to zoom. The closest robot-human pair is a line: red below d_min, amber within 0.1 m of it, green beyond.</p>\n",
            );
        } else {
            html.push_str(
                "<p id=\"replay-status\" data-state=\"no-viewer\">The interactive replay needs the viewer: run <code>scripts/fetch-viewer.sh</code> once, then evaluate again. The episodes below open in any glTF viewer.</p>\n",
            );
        }
        html.push_str("<ul>\n");
        for r in replays {
            let _ = writeln!(
                html,
                "<li><a href=\"{}\">{}</a></li>",
                escape(&r.glb),
                escape(&r.label)
            );
        }
        html.push_str("</ul>\n");
        if viewer {
            for r in replays {
                let _ = writeln!(html, "<script src=\"{}\"></script>", escape(&r.script));
            }
        }
    }
    html.push_str(&markdown_to_html(tail));
    if !replays.is_empty() && viewer {
        html.push_str("<script src=\"viewer.js\"></script>\n");
    }
    html.push_str("</main>\n</body>\n</html>\n");
    html
}

const STYLE: &str = "body{font-family:system-ui,sans-serif;margin:0;background:#f6f7f9;color:#1d2330}\
main{max-width:1100px;margin:0 auto;padding:1.5em}\
table{border-collapse:collapse;margin:0.8em 0;font-size:0.9em}\
th,td{border:1px solid #c9ced6;padding:0.3em 0.6em;text-align:left}\
th{background:#e8ebf0}img{max-width:100%}code{background:#e8ebf0;padding:0 0.2em}\
#replay{width:100%;background:#dfe4ea}.controls{margin:0.5em 0}";

/// HTML of the markdown subset the summary uses.
#[must_use]
pub fn markdown_to_html(markdown: &str) -> String {
    let mut html = String::new();
    let lines: Vec<&str> = markdown.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim_end();
        if line.trim().is_empty() {
            i += 1;
            continue;
        }
        if let Some((level, text)) = heading(line) {
            let _ = writeln!(html, "<h{level}>{}</h{level}>", inline(text));
            i += 1;
        } else if line.starts_with('|') {
            let mut rows = Vec::new();
            while i < lines.len() && lines[i].starts_with('|') {
                rows.push(cells(lines[i]));
                i += 1;
            }
            html.push_str("<table>\n");
            for (k, row) in rows.iter().enumerate() {
                // The second row is the separator.
                if k == 1
                    && row
                        .iter()
                        .all(|c| c.chars().all(|ch| ch == '-' || ch == ':'))
                {
                    continue;
                }
                let tag = if k == 0 { "th" } else { "td" };
                html.push_str("<tr>");
                for c in row {
                    let _ = write!(html, "<{tag}>{}</{tag}>", inline(c));
                }
                html.push_str("</tr>\n");
            }
            html.push_str("</table>\n");
        } else if line.starts_with("- ") {
            html.push_str("<ul>\n");
            while i < lines.len() && lines[i].starts_with("- ") {
                let _ = writeln!(html, "<li>{}</li>", inline(&lines[i][2..]));
                i += 1;
            }
            html.push_str("</ul>\n");
        } else {
            let mut paragraph = Vec::new();
            while i < lines.len()
                && !lines[i].trim().is_empty()
                && heading(lines[i]).is_none()
                && !lines[i].starts_with('|')
                && !lines[i].starts_with("- ")
            {
                paragraph.push(inline(lines[i].trim()));
                i += 1;
            }
            let _ = writeln!(html, "<p>{}</p>", paragraph.join("\n"));
        }
    }
    html
}

fn heading(line: &str) -> Option<(usize, &str)> {
    let level = line.chars().take_while(|&c| c == '#').count();
    (1..=6)
        .contains(&level)
        .then(|| line[level..].strip_prefix(' '))
        .flatten()
        .map(|text| (level, text))
}

fn cells(row: &str) -> Vec<String> {
    let inner = row.trim().trim_start_matches('|').trim_end_matches('|');
    inner.split('|').map(|c| c.trim().to_string()).collect()
}

/// Inline markdown: images, `code` and **bold**, everything else escaped.
fn inline(text: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix("![")
            && let Some((alt, tail)) = after.split_once("](")
            && let Some((src, tail)) = tail.split_once(')')
        {
            let _ = write!(out, "<img src=\"{}\" alt=\"{}\">", escape(src), escape(alt));
            rest = tail;
            continue;
        }
        if let Some(after) = rest.strip_prefix('`')
            && let Some((code, tail)) = after.split_once('`')
        {
            let _ = write!(out, "<code>{}</code>", escape(code));
            rest = tail;
            continue;
        }
        if let Some(after) = rest.strip_prefix("**")
            && let Some((bold, tail)) = after.split_once("**")
        {
            let _ = write!(out, "<strong>{}</strong>", escape(bold));
            rest = tail;
            continue;
        }
        let next = rest
            .char_indices()
            .skip(1)
            .find(|&(_, c)| c == '!' || c == '`' || c == '*')
            .map_or(rest.len(), |(k, _)| k);
        out.push_str(&escape(&rest[..next]));
        rest = &rest[next..];
    }
    out
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_subset_becomes_html() {
        let md = "# Title <1>\n\n- a `x<y`\n- **b**\n\n| h1 | h2 |\n|---|---|\n| 1 | **2** |\n\nText with ![plot](p.png) and 3 * 4.\nmore\n\n## Next\n";
        let html = markdown_to_html(md);
        assert_eq!(
            html,
            "<h1>Title &lt;1&gt;</h1>\n<ul>\n<li>a <code>x&lt;y</code></li>\n<li><strong>b</strong></li>\n</ul>\n\
             <table>\n<tr><th>h1</th><th>h2</th></tr>\n<tr><td>1</td><td><strong>2</strong></td></tr>\n</table>\n\
             <p>Text with <img src=\"p.png\" alt=\"plot\"> and 3 * 4.\nmore</p>\n<h2>Next</h2>\n"
        );
    }

    #[test]
    fn a_page_without_the_viewer_still_lists_its_replays() {
        let replay = PageReplay {
            label: "episode 3 \"worst\"".into(),
            script: "replays/episode-3.js".into(),
            glb: "replays/episode-3.glb".into(),
        };
        let page = summary_html("# R\n", std::slice::from_ref(&replay), false);
        assert!(page.contains("data-state=\"no-viewer\""));
        assert!(page.contains("<a href=\"replays/episode-3.glb\">episode 3 &quot;worst&quot;</a>"));
        assert!(!page.contains("<script"));
        let page = summary_html("# R\n", &[replay], true);
        assert!(page.contains("<script src=\"replays/episode-3.js\"></script>"));
        assert!(page.contains("<script src=\"viewer.js\"></script>"));
        let script = replay_script("a \"b\"", b"glTF");
        assert!(
            script.contains("name: \"a \\\"b\\\"\", glb: \"Z2xURg==\""),
            "{script}"
        );
    }
}

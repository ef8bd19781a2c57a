//! Limits on what a robot file may ask for, and the checks that enforce them before anything
//! is allocated or parsed recursively.
//!
//! Files come from users and vendors: a one-kilobyte file must not be able to make the loader
//! allocate gigabytes, recurse until the stack overflows, read a device or a FIFO, or build a
//! multibody that takes minutes per simulated second. Each limit is far above any real robot's
//! need; exceeding one is an error that names the limit.

use std::io::Read;
use std::path::Path;

/// The largest URDF file read, in bytes (the biggest vendor URDFs are a few hundred kB).
pub const MAX_URDF_BYTES: u64 = 64 << 20;
/// The largest mesh file read, in bytes.
pub const MAX_MESH_BYTES: u64 = 256 << 20;
/// The deepest element nesting accepted in URDF and COLLADA (URDF needs 5 levels, COLLADA
/// scene graphs a few dozen).
pub const MAX_XML_DEPTH: usize = 256;
/// The most links a robot may have.
pub const MAX_LINKS: usize = 1024;
/// The most actuated coordinates a robot may have. rapier's multibody solver costs O(n^3)
/// per step in the number of degrees of freedom (the mass matrix is assembled link by link
/// and factored every step): `robot check`'s one simulated second takes 4 s for a 50-dof
/// chain and 20 s for 100 dofs. Arms have 6 or 7; the largest robot of example-robot-data
/// 6.0.0 (TIAGo with two arms, `tiago_dual`) has 101.
pub const MAX_DOF: usize = 128;
/// The largest mimic multiplier or offset magnitude (gripper mimics use 1, -1 or ratios).
pub const MAX_MIMIC_FACTOR: f64 = 1e3;
/// The largest configuration or record file read, in bytes: scenarios, evaluations, training
/// recipes, dataset manifests and labels, run records (`run.json`). The biggest the project
/// writes are run records of a few MB (a million episodes' metrics would be about 1 GB: a
/// sweep that large is merged from shards, each read on its own).
pub const MAX_CONFIG_BYTES: u64 = 256 << 20;
/// Joint limits beyond this magnitude (rad) mean "unlimited": a revolute joint with them is
/// taken as continuous (vendors write +-1e16 for rotors). A prismatic joint must stay within
/// it (m).
pub const MAX_JOINT_LIMIT: f64 = 1e4;

/// Reads a regular file of at most `max_bytes` bytes. Devices, FIFOs and folders are refused
/// before they are opened; a file that grows while it is read is cut at the limit and refused.
///
/// # Errors
/// The I/O error, or one of kind `InvalidInput` saying why the file is refused (the caller
/// names the file).
pub fn read_regular_file(path: &Path, max_bytes: u64) -> std::io::Result<Vec<u8>> {
    let meta = check_regular_file(path, max_bytes)?;
    let file = std::fs::File::open(path)?;
    // The path may have been replaced between the check and the open: check what was opened.
    if !file.metadata()?.is_file() {
        return Err(refuse("not a regular file".into()));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(max_bytes + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(refuse(format!(
            "grew past the limit of {max_bytes} bytes while it was read"
        )));
    }
    Ok(bytes)
}

/// Checks, without opening it, that `path` is a regular file of at most `max_bytes` bytes:
/// for files a library opens itself (burn's optimizer records and safetensors stores).
///
/// # Errors
/// The I/O error of its metadata, or one of kind `InvalidInput` saying why it is refused.
pub fn check_regular_file(path: &Path, max_bytes: u64) -> std::io::Result<std::fs::Metadata> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(refuse("not a regular file".into()));
    }
    if meta.len() > max_bytes {
        return Err(refuse(format!(
            "{} bytes, more than the limit of {max_bytes}",
            meta.len()
        )));
    }
    Ok(meta)
}

fn refuse(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// Reads a text file as [`read_regular_file`] does: a regular file of at most `max_bytes`
/// bytes, in UTF-8. Every configuration, manifest and record the project reads comes through
/// here (or through [`read_regular_file`] for binary files).
///
/// # Errors
/// As [`read_regular_file`], and one of kind `InvalidData` for text that is not UTF-8 (the
/// message gives the byte offset, never the bytes).
pub fn read_text_file(path: &Path, max_bytes: u64) -> std::io::Result<String> {
    let bytes = read_regular_file(path, max_bytes)?;
    String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (invalid byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

/// Reads a URDF file: a regular file of at most [`MAX_URDF_BYTES`], in UTF-8.
///
/// # Errors
/// [`RobotError::Io`] for what cannot be read, [`RobotError::Parse`] for what is not text.
pub fn read_urdf_text(path: &Path) -> crate::Result<String> {
    let bytes = read_regular_file(path, MAX_URDF_BYTES).map_err(|error| crate::RobotError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    String::from_utf8(bytes).map_err(|e| crate::RobotError::Parse {
        path: path.to_path_buf(),
        message: format!("not UTF-8 text ({e})"),
    })
}

/// Parses `text` as one well-formed XML document (one root element, no NUL or other
/// character XML forbids) whose elements nest at most [`MAX_XML_DEPTH`] deep.
///
/// Every XML parser at hand recurses per element (roxmltree, urdf-rs's, the COLLADA
/// decoder's): the depth is measured first by a flat scan of the markup, and only text that
/// passes reaches a parser.
///
/// # Errors
/// The parser's message (with line and column), or the depth found.
pub fn parse_xml(text: &str) -> Result<roxmltree::Document<'_>, String> {
    check_nesting(text.as_bytes())?;
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        // Each node costs about 100 bytes: a limit in proportion to the text bounds memory.
        nodes_limit: u32::try_from(text.len()).unwrap_or(u32::MAX).max(64),
    };
    let doc = roxmltree::Document::parse_with_options(text, options).map_err(|e| e.to_string())?;
    Ok(doc)
}

/// The deepest element nesting of `text` must not exceed [`MAX_XML_DEPTH`]. A flat scan of
/// the markup: comments, CDATA, processing instructions and declarations are skipped, quoted
/// attribute values may hold `>`, and `<a/>` opens nothing. Malformed markup is left to the
/// parser to report.
fn check_nesting(text: &[u8]) -> Result<(), String> {
    let find = |from: usize, needle: &[u8]| -> usize {
        text.get(from..)
            .and_then(|rest| rest.windows(needle.len()).position(|w| w == needle))
            .map_or(text.len(), |at| from + at + needle.len())
    };
    // The `>` that closes a tag begun before `from`: not one inside quotes, nor (for a
    // declaration) one inside brackets.
    let tag_end = |from: usize, brackets_nest: bool| -> usize {
        let (mut brackets, mut quote) = (0_usize, None);
        let mut j = from;
        while j < text.len() {
            match (quote, text[j]) {
                (Some(q), c) if c == q => quote = None,
                (Some(_), _) => {}
                (None, c @ (b'"' | b'\'')) => quote = Some(c),
                (None, b'[') if brackets_nest => brackets += 1,
                (None, b']') if brackets_nest => brackets = brackets.saturating_sub(1),
                (None, b'>') if brackets == 0 => break,
                _ => {}
            }
            j += 1;
        }
        j
    };
    let mut depth = 0_usize;
    let mut i = 0;
    while i < text.len() {
        if text[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &text[i..];
        if rest.starts_with(b"<!--") {
            i = find(i + 4, b"-->");
        } else if rest.starts_with(b"<![CDATA[") {
            i = find(i + 9, b"]]>");
        } else if rest.starts_with(b"<?") {
            i = find(i + 2, b"?>");
        } else if rest.starts_with(b"<!") {
            // A declaration, with an internal subset in brackets for a DOCTYPE.
            i = tag_end(i + 2, true) + 1;
        } else if rest.starts_with(b"</") {
            depth = depth.saturating_sub(1);
            i = find(i + 2, b">");
        } else {
            let j = tag_end(i + 1, false);
            if text.get(j.wrapping_sub(1)) != Some(&b'/') {
                depth += 1;
                if depth > MAX_XML_DEPTH {
                    let line = text[..i].iter().filter(|&&c| c == b'\n').count() + 1;
                    return Err(format!(
                        "elements nest deeper than {MAX_XML_DEPTH} levels (line {line})"
                    ));
                }
            }
            i = j + 1;
        }
    }
    Ok(())
}

/// Checks the `count` attributes of a COLLADA document against its size before the decoder
/// allocates for them: every counted value takes at least two bytes of text ("0 "), so a
/// `<float_array count>` (times an accessor's `stride`) or a primitive's count (times its
/// vertices and inputs) larger than the file is a lie.
///
/// # Errors
/// A message naming the element and its count.
pub(crate) fn check_collada_counts(
    doc: &roxmltree::Document<'_>,
    len: usize,
) -> Result<(), String> {
    let budget = (len / 2 + 1) as u128;
    for node in doc.descendants().filter(roxmltree::Node::is_element) {
        let Some(count) = node.attribute("count") else {
            continue;
        };
        let name = node.tag_name().name();
        let count: u128 = count
            .trim()
            .parse()
            .map_err(|_| format!("<{name} count=\"{count}\"> is not a non-negative integer"))?;
        let per_item: u128 = match name {
            "triangles" | "polylist" | "polygons" | "lines" | "linestrips" | "tristrips"
            | "trifans" => {
                let vertices = match name {
                    "triangles" => 3_u128,
                    "lines" => 2,
                    _ => 1,
                };
                // Each vertex of the index list `<p>` has as many indices as the largest
                // input `offset` plus one (the decoder reserves for that).
                let mut width = 1_u128;
                for input in node.children().filter(|c| c.has_tag_name("input")) {
                    let offset = input.attribute("offset").unwrap_or("0");
                    let offset: u128 = offset.trim().parse().map_err(|_| {
                        format!("<input offset=\"{offset}\"> is not a non-negative integer")
                    })?;
                    width = width.max(offset.saturating_add(1));
                }
                vertices.saturating_mul(width)
            }
            _ => {
                let stride = node.attribute("stride").unwrap_or("1");
                let stride: u128 = stride.trim().parse().map_err(|_| {
                    format!("<{name} stride=\"{stride}\"> is not a non-negative integer")
                })?;
                stride.max(1)
            }
        };
        if count.saturating_mul(per_item) > budget {
            return Err(format!(
                "<{name} count=\"{count}\"> claims more values than the {len}-byte file can hold"
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let deep = format!(
            "<robot>{}{}</robot>",
            "<a>".repeat(20_000),
            "</a>".repeat(20_000)
        );
        let err = parse_xml(&deep).expect_err("too deep");
        assert!(err.contains("deeper than 256"), "{err}");
        let ok = format!("<robot>{}{}</robot>", "<a>".repeat(200), "</a>".repeat(200));
        assert!(parse_xml(&ok).is_ok());
        // Markup that only looks like elements does not count; empty elements open nothing.
        let quiet = format!(
            "<?xml version=\"1.0\"?><!DOCTYPE robot [<!ENTITY e \"[x]>\">]><robot>\
             <!-- {open} --><![CDATA[{open}]]><b x=\"/>\" y='>'/>{empty}</robot>",
            open = "<a>".repeat(300),
            empty = "<c/>".repeat(300)
        );
        if let Err(e) = parse_xml(&quiet) {
            panic!("{e}");
        }
        let err = parse_xml(&format!("<r>\n{}", "<a x='>'>".repeat(300))).expect_err("deep");
        assert!(err.contains("line 2"), "{err}");
    }

    #[test]
    fn malformed_xml_is_refused() {
        for bad in [
            "<robot name=\"r\"/><robot name=\"s\"/>",
            "<robot name=\"r\">\0</robot>",
            "<robot name=\"r\"><!-- \0 --></robot>",
            "<robot name=\"r\">",
            "",
        ] {
            assert!(parse_xml(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn collada_counts_are_checked_against_the_file() {
        let dae = |count: &str| {
            format!(
                "<COLLADA><float_array id=\"a\" count=\"{count}\">0 0 0 1 0 0 0 1 0</float_array>\
                 <triangles count=\"1\"><input semantic=\"VERTEX\" offset=\"0\"/><p>0 1 2</p>\
                 </triangles></COLLADA>"
            )
        };
        let honest = dae("9");
        let doc = parse_xml(&honest).expect("xml");
        assert!(check_collada_counts(&doc, honest.len()).is_ok());
        for lie in ["4000000000", "18446744073709551615", "-1", "x"] {
            let text = dae(lie);
            let doc = parse_xml(&text).expect("xml");
            assert!(check_collada_counts(&doc, text.len()).is_err(), "{lie}");
        }
        let lie =
            "<COLLADA><triangles count=\"4294967295\"><input/><p>0 1 2</p></triangles></COLLADA>";
        let doc = parse_xml(lie).expect("xml");
        let err = check_collada_counts(&doc, lie.len()).expect_err("lie");
        // An input offset the file cannot back (the decoder reserved 576 GB for one; found by
        // the fuzz campaign).
        let offset = "<COLLADA><triangles count=\"12\"><input offset=\"4000000000\"/>\
                      <p>0 1 2</p></triangles></COLLADA>";
        let offset_doc = parse_xml(offset).expect("xml");
        assert!(check_collada_counts(&offset_doc, offset.len()).is_err());
        assert!(err.contains("<triangles count=\"4294967295\">"), "{err}");
    }

    #[cfg(unix)]
    #[test]
    fn only_regular_files_of_bounded_size_are_read() {
        let refused = |path: &Path, max| {
            read_regular_file(path, max)
                .expect_err("refused")
                .to_string()
        };
        let err = refused(Path::new("/dev/zero"), MAX_MESH_BYTES);
        assert!(err.contains("not a regular file"), "{err}");
        let dir = tempfile::tempdir().expect("tempdir");
        let err = refused(dir.path(), MAX_MESH_BYTES);
        assert!(err.contains("not a regular file"), "{err}");
        // A FIFO would block a reader forever: it is refused before it is opened.
        let fifo = dir.path().join("fifo.stl");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let err = refused(&fifo, MAX_MESH_BYTES);
            assert!(err.contains("not a regular file"), "{err}");
        }
        let file = dir.path().join("big.stl");
        std::fs::write(&file, vec![b'x'; 100]).expect("write");
        let err = refused(&file, 99);
        assert!(err.contains("more than the limit of 99"), "{err}");
        assert_eq!(read_regular_file(&file, 100).expect("fits").len(), 100);
    }
}

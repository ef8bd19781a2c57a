//! Triangle meshes from STL (binary and ASCII), OBJ and COLLADA/DAE files.
//!
//! Decoding uses mesh-loader. Its panics on malformed input are caught and turned into
//! errors; a program that wants them silent installs a panic hook that skips
//! [`DECODER_CRATE`] (the `workcell` binary does).

use std::path::Path;

use crate::math::Vector;

/// Name of the mesh decoding crate, as it appears in panic locations.
pub const DECODER_CRATE: &str = "mesh-loader";

/// An indexed triangle mesh in the mesh's own frame, in metres (scale applied).
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    pub vertices: Vec<Vector>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Reads a mesh file (format from the extension and content) and scales it per axis.
    ///
    /// All sub-meshes of a scene are merged. A file with no triangle, a non-finite vertex or a
    /// face that indexes past the vertices is an error.
    ///
    /// # Errors
    /// A message saying what is wrong with the file.
    pub fn load(path: &Path, scale: [f64; 3]) -> Result<Self, String> {
        let bytes = crate::input::read_regular_file(path, crate::input::MAX_MESH_BYTES)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        Self::from_bytes(&bytes, path, scale)
    }

    /// Like [`TriMesh::load`] on bytes already read; `path` only tells the format.
    ///
    /// # Errors
    /// A message saying what is wrong with the bytes.
    pub fn from_bytes(bytes: &[u8], path: &Path, scale: [f64; 3]) -> Result<Self, String> {
        check_binary_stl_length(bytes, path)?;
        check_collada(bytes, path)?;
        // A binary STL whose free-form header starts with "solid" is taken for ASCII by the
        // decoder; when the size fits the binary layout exactly, blank the header first.
        let patched;
        let bytes = if is_binary_stl_starting_with_solid(bytes, path) {
            let mut copy = bytes.to_vec();
            copy[..5].copy_from_slice(b"     ");
            patched = copy;
            &patched[..]
        } else if !bytes.is_ascii() && is_ascii_stl(bytes) {
            // The decoder wants ASCII throughout; only the solid's name may be anything else.
            patched = bytes
                .iter()
                .map(|&b| if b.is_ascii() { b } else { b'_' })
                .collect();
            &patched[..]
        } else {
            bytes
        };
        // Sub-meshes are merged below, not by the decoder: mesh-loader 0.1.13's
        // `merge_meshes(true)` does not offset the face indices of later sub-meshes, so their
        // triangles pointed at the first one's vertices (a UR5 upper arm lost its tube).
        let loader = mesh_loader::Loader::default();
        // OBJ files may name material libraries; those are not needed for geometry. The
        // decoder panics on some corrupted files (seen on COLLADA with dangling references,
        // and by the fuzz campaign in its iterators and instancing): a broken file must be an
        // error, so the panic is caught here. That needs unwinding panics, the default; a
        // build with `panic = "abort"` would turn such a file into a crash.
        let decoded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            loader.load_from_slice_with_reader(bytes, path, |_| Ok(Vec::new()))
        }));
        let scene = match decoded {
            Ok(result) => result.map_err(|e| format!("cannot decode {}: {e}", path.display()))?,
            Err(panic) => {
                let why = panic
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                return Err(format!(
                    "cannot decode {}: the decoder failed ({why})",
                    path.display()
                ));
            }
        };
        let mut mesh = TriMesh {
            vertices: Vec::new(),
            triangles: Vec::new(),
        };
        let s = Vector::from_array(scale);
        for part in &scene.meshes {
            let base =
                u32::try_from(mesh.vertices.len()).map_err(|_| "mesh too large".to_string())?;
            for v in &part.vertices {
                let p = Vector::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])) * s;
                if !p.is_finite() {
                    return Err(format!("{} has a non-finite vertex", path.display()));
                }
                mesh.vertices.push(p);
            }
            let count = part.vertices.len();
            for f in &part.faces {
                if f.iter().any(|&i| i as usize >= count) {
                    return Err(format!(
                        "{} has a face that indexes past its {count} vertices",
                        path.display()
                    ));
                }
                mesh.triangles.push([f[0] + base, f[1] + base, f[2] + base]);
            }
        }
        if mesh.triangles.is_empty() {
            return Err(format!("{} holds no triangle", path.display()));
        }
        let (lo, hi) = mesh.bounds();
        if (hi - lo).max_element() <= 0.0 {
            return Err(format!(
                "{} is degenerate: all its vertices coincide",
                path.display()
            ));
        }
        Ok(mesh)
    }

    /// Axis-aligned bounds `(min, max)` of the vertices.
    #[must_use]
    pub fn bounds(&self) -> (Vector, Vector) {
        self.vertices.iter().fold(
            (
                Vector::splat(f64::INFINITY),
                Vector::splat(f64::NEG_INFINITY),
            ),
            |(lo, hi), v| (lo.min(*v), hi.max(*v)),
        )
    }
}

/// A COLLADA file must be well-formed XML of bounded depth whose counts fit its size before
/// the decoder (recursive, and trusting every `count`) sees it.
fn check_collada(bytes: &[u8], path: &Path) -> Result<(), String> {
    let is_dae = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dae"));
    if !is_dae {
        return Ok(());
    }
    let text = std::str::from_utf8(bytes)
        .map_err(|e| format!("cannot decode {}: not UTF-8 XML ({e})", path.display()))?;
    let doc = crate::input::parse_xml(text)
        .map_err(|e| format!("cannot decode {}: {e}", path.display()))?;
    crate::input::check_collada_counts(&doc, bytes.len())
        .map_err(|e| format!("cannot decode {}: {e}", path.display()))
}

/// The triangle count in the header of a binary STL, `None` when the file is not an STL
/// long enough to have that header.
fn binary_stl_count(bytes: &[u8], path: &Path) -> Option<usize> {
    let is_stl = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("stl"));
    (is_stl && bytes.len() >= 84)
        .then(|| u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize)
}

/// A binary STL states its triangle count in its header: a file shorter than that is
/// truncated (decoders tend to read what is there and say nothing).
fn check_binary_stl_length(bytes: &[u8], path: &Path) -> Result<(), String> {
    let Some(count) = binary_stl_count(bytes, path) else {
        return Ok(());
    };
    if is_ascii_stl(bytes) {
        return Ok(());
    }
    let expected = 84 + 50 * count;
    if bytes.len() < expected {
        return Err(format!(
            "{} is a truncated binary STL: its header counts {count} triangles ({expected} bytes), the file has {} bytes",
            path.display(),
            bytes.len()
        ));
    }
    Ok(())
}

/// An ASCII STL: "solid", and then a first facet or the end (the name may be any UTF-8; a
/// binary STL whose header starts with "solid" has binary bytes right after its header).
fn is_ascii_stl(bytes: &[u8]) -> bool {
    if !bytes.starts_with(b"solid") {
        return false;
    }
    let line_end = bytes
        .iter()
        .position(|&b| b == b'\n')
        .unwrap_or(bytes.len());
    let rest = &bytes[line_end..];
    let first_word = rest
        .split(u8::is_ascii_whitespace)
        .find(|w| !w.is_empty())
        .unwrap_or_default();
    std::str::from_utf8(&bytes[..line_end]).is_ok()
        && (first_word == b"facet" || first_word == b"endsolid")
}

/// A binary STL whose header starts with "solid": the size fits the binary layout exactly.
fn is_binary_stl_starting_with_solid(bytes: &[u8], path: &Path) -> bool {
    bytes.starts_with(b"solid")
        && binary_stl_count(bytes, path).is_some_and(|n| n > 0 && bytes.len() == 84 + 50 * n)
}

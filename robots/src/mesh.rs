//! Triangle meshes from STL (binary and ASCII), OBJ, COLLADA/DAE and glTF 2.0 (`.gltf`,
//! `.glb`) files.
//!
//! Decoding uses mesh-loader, and the gltf crate for glTF. Its panics on malformed input are caught and turned into
//! errors; a program that wants them silent installs a panic hook that skips
//! [`DECODER_CRATES`] (the `workcell` binary does).

use std::path::Path;

use crate::math::Vector;

/// Names of the mesh decoding crates, as they appear in panic locations (the gltf crate's
/// validator lives in gltf-json).
pub const DECODER_CRATES: [&str; 3] = ["mesh-loader-", "gltf-json-", "gltf-1."];

/// Why a mesh, or a file it names, was not loaded; the message names the file and what is
/// wrong, never its bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The file cannot be read: missing, not a regular file, or larger than allowed.
    #[error("{0}")]
    Read(String),
    /// The bytes are not a mesh of the file's format (truncated, malformed, counts that lie,
    /// indices past the vertices), or the mesh is degenerate (no triangle, a non-finite
    /// vertex).
    #[error("{0}")]
    Decode(String),
    /// A file the mesh names (a glTF buffer) lies where the mesh may not reach.
    #[error("{0}")]
    Refused(String),
}

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
    /// [`MeshError::Read`] when the file cannot be read (missing, not a regular file, larger
    /// than [`crate::input::MAX_MESH_BYTES`]), else as [`TriMesh::from_bytes`].
    pub fn load(path: &Path, scale: [f64; 3]) -> Result<Self, MeshError> {
        let bytes = crate::input::read_regular_file(path, crate::input::MAX_MESH_BYTES)
            .map_err(|e| MeshError::Read(format!("cannot read {}: {e}", path.display())))?;
        Self::from_bytes(&bytes, path, scale)
    }

    /// Like [`TriMesh::load`] on bytes already read; `path` only tells the format.
    ///
    /// # Errors
    /// [`MeshError::Decode`], saying what is wrong with the bytes.
    pub fn from_bytes(bytes: &[u8], path: &Path, scale: [f64; 3]) -> Result<Self, MeshError> {
        Self::decode(bytes, path, scale).map_err(MeshError::Decode)
    }

    fn decode(bytes: &[u8], path: &Path, scale: [f64; 3]) -> Result<Self, String> {
        if is_gltf(path) {
            return gltf_mesh(bytes, path, scale);
        }
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
        mesh.checked(path)
    }

    /// The mesh when it holds a triangle and its vertices do not all coincide.
    fn checked(self, path: &Path) -> Result<Self, String> {
        if self.triangles.is_empty() {
            return Err(format!("{} holds no triangle", path.display()));
        }
        let (lo, hi) = self.bounds();
        if (hi - lo).max_element() <= 0.0 {
            return Err(format!(
                "{} is degenerate: all its vertices coincide",
                path.display()
            ));
        }
        Ok(self)
    }

    /// The mesh as a binary glTF file: one node, one grey material (f32 vertices).
    #[must_use]
    pub fn to_glb(&self, name: &str) -> Vec<u8> {
        let mut glb = crate::glb::GlbBuilder::new();
        let material = glb.material(name, [0.6, 0.6, 0.6, 1.0]);
        let positions: Vec<[f32; 3]> = self
            .vertices
            .iter()
            .map(|v| [v.x as f32, v.y as f32, v.z as f32])
            .collect();
        let indices: Vec<u32> = self.triangles.iter().flatten().copied().collect();
        let mesh = glb.mesh(
            name,
            &positions,
            &indices,
            crate::glb::Mode::Triangles,
            material,
        );
        glb.node(name, serde_json::json!({"mesh": mesh}), true);
        glb.finish("workcell", name)
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

/// `.gltf` or `.glb`.
fn is_gltf(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"))
}

/// The files a `.gltf` file's buffers name (relative URIs, not `data:`), which must travel
/// with it; empty for anything else.
#[must_use]
pub fn gltf_buffer_files(bytes: &[u8], path: &Path) -> Vec<String> {
    if !is_gltf(path) {
        return Vec::new();
    }
    std::panic::catch_unwind(|| {
        gltf::Gltf::from_slice(bytes).map(|g| {
            g.document
                .buffers()
                .filter_map(|b| match b.source() {
                    gltf::buffer::Source::Uri(uri) if !uri.starts_with("data:") => {
                        Some(uri.to_string())
                    }
                    _ => None,
                })
                .collect()
        })
    })
    .ok()
    .and_then(Result::ok)
    .unwrap_or_default()
}

/// The file a `.gltf` at `gltf_path` names by the buffer URI `uri` (not a `data:` URI): a
/// relative path inside the `.gltf`'s own folder, which lies inside the mesh's package root,
/// so that a buffer follows the rule of the meshes. Absolute paths, `..`, URI schemes and
/// symbolic links that lead out of the folder are refused.
///
/// # Errors
/// [`MeshError::Refused`], naming the URI and why (never the bytes of any file).
pub fn gltf_buffer_path(gltf_path: &Path, uri: &str) -> Result<std::path::PathBuf, MeshError> {
    let refused = |why: &str| MeshError::Refused(format!("buffer {uri:?} {why}"));
    if uri.contains("://") || uri.starts_with("data:") {
        return Err(refused("uses a URI scheme other than data:"));
    }
    let relative = Path::new(uri);
    let plain = !uri.is_empty()
        && relative
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)));
    if !plain {
        return Err(refused(
            "is not a relative path inside the .gltf's folder (no '..', not absolute)",
        ));
    }
    let folder = gltf_path.parent().unwrap_or(Path::new("."));
    let file = folder.join(relative);
    // A link inside the folder may point out of it.
    if let (Ok(real), Ok(real_folder)) = (file.canonicalize(), folder.canonicalize())
        && !real.starts_with(&real_folder)
    {
        return Err(refused("resolves outside the .gltf's folder"));
    }
    Ok(file)
}

/// The most nodes a glTF scene may have.
const MAX_GLTF_NODES: usize = 100_000;

/// The triangles of a glTF 2.0 file's default scene (else its first), every mesh placed by
/// its node's transform from the scene root. Vertices are taken as written, in metres, in
/// the link's frame, like the other formats: glTF's "+Y is up" is not turned into ROS's +Z.
/// Buffers come from the `.glb`'s binary chunk, from `data:` URIs, or from files in
/// `path`'s folder ([`gltf_buffer_path`]; read with the same limits as meshes). Nodes form
/// trees (glTF 2.0, 3.5.3: no node has two parents): a node reached twice is refused, so
/// that each node is visited once.
fn gltf_mesh(bytes: &[u8], path: &Path, scale: [f64; 3]) -> Result<TriMesh, String> {
    // The gltf crate indexes without checking in places (its own validator looks accessors
    // up by the index it is about to validate; accessor iterators slice the buffers): a
    // malformed file must be an error, not a crash, as with the other decoders.
    match std::panic::catch_unwind(|| gltf_mesh_unguarded(bytes, path, scale)) {
        Ok(result) => result,
        Err(_) => Err(format!(
            "cannot decode {}: the glTF decoder failed on a malformed file",
            path.display()
        )),
    }
}

fn gltf_mesh_unguarded(bytes: &[u8], path: &Path, scale: [f64; 3]) -> Result<TriMesh, String> {
    use base64::Engine as _;
    let bad = |why: String| format!("cannot decode {}: {why}", path.display());
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| bad(e.to_string()))?;
    let mut buffers: Vec<Vec<u8>> = Vec::new();
    for buffer in gltf.document.buffers() {
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| bad("a buffer refers to a binary chunk the file lacks".into()))?,
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let (_, data) = rest
                        .split_once(";base64,")
                        .ok_or_else(|| bad("a data URI that is not base64".into()))?;
                    base64::engine::general_purpose::STANDARD
                        .decode(data)
                        .map_err(|e| bad(format!("a data URI: {e}")))?
                } else {
                    let file = gltf_buffer_path(path, uri).map_err(|e| bad(e.to_string()))?;
                    crate::input::read_regular_file(&file, crate::input::MAX_MESH_BYTES)
                        .map_err(|e| bad(format!("buffer {}: {e}", file.display())))?
                }
            }
        };
        // Accessors index into the declared length: data shorter than that is truncated.
        if data.len() < buffer.length() {
            return Err(bad(format!(
                "buffer {} holds {} bytes, declares {}",
                buffer.index(),
                data.len(),
                buffer.length()
            )));
        }
        buffers.push(data);
    }
    let scene = gltf
        .document
        .default_scene()
        .or_else(|| gltf.document.scenes().next())
        .ok_or_else(|| bad("no scene".into()))?;
    let mut mesh = TriMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    let s = Vector::from_array(scale);
    let nodes = gltf.document.nodes().len();
    if nodes > MAX_GLTF_NODES {
        return Err(bad(format!(
            "{nodes} nodes, more than the limit of {MAX_GLTF_NODES}"
        )));
    }
    // A node shared by two parents (or a loop) would be walked once per path: 2.5 kB of
    // nodes each listing the next two as children made 2^64 paths.
    let mut reached = vec![false; nodes];
    let mut stack: Vec<(gltf::Node<'_>, [[f64; 4]; 4])> =
        scene.nodes().map(|n| (n, IDENTITY_4)).collect();
    while let Some((node, parent)) = stack.pop() {
        match reached.get_mut(node.index()) {
            Some(seen) if !*seen => *seen = true,
            _ => {
                return Err(bad(format!(
                    "node {} is reached twice: glTF nodes form trees (a node with two \
                     parents, or a loop)",
                    node.index()
                )));
            }
        }
        let local = node.transform().matrix().map(|c| c.map(f64::from));
        let world = mul4(&parent, &local);
        if let Some(m) = node.mesh() {
            for primitive in m.primitives() {
                add_primitive(&mut mesh, &primitive, &buffers, &world, s).map_err(bad)?;
            }
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    mesh.checked(path)
}

/// The identity, column-major as glTF stores matrices.
const IDENTITY_4: [[f64; 4]; 4] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// `a * b` of column-major 4x4 matrices.
fn mul4(a: &[[f64; 4]; 4], b: &[[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let mut m = [[0.0; 4]; 4];
    for (c, column) in m.iter_mut().enumerate() {
        for (r, v) in column.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

/// Appends one primitive's triangles (lists, strips and fans; points and lines have none),
/// its positions placed by `world` and scaled per axis.
fn add_primitive(
    mesh: &mut TriMesh,
    primitive: &gltf::Primitive<'_>,
    buffers: &[Vec<u8>],
    world: &[[f64; 4]; 4],
    scale: Vector,
) -> Result<(), String> {
    use gltf::mesh::Mode;
    let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let Some(positions) = reader.read_positions() else {
        return Ok(());
    };
    let base = u32::try_from(mesh.vertices.len()).map_err(|_| "mesh too large".to_string())?;
    let mut count = 0usize;
    for p in positions {
        let p = p.map(f64::from);
        let w = Vector::new(
            world[0][0] * p[0] + world[1][0] * p[1] + world[2][0] * p[2] + world[3][0],
            world[0][1] * p[0] + world[1][1] * p[1] + world[2][1] * p[2] + world[3][1],
            world[0][2] * p[0] + world[1][2] * p[1] + world[2][2] * p[2] + world[3][2],
        ) * scale;
        if !w.is_finite() {
            return Err("a non-finite vertex".into());
        }
        mesh.vertices.push(w);
        count += 1;
    }
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..u32::try_from(count).map_err(|_| "mesh too large".to_string())?).collect(),
    };
    // The position, not the value: an index is the file's bytes, and an error must not echo
    // what a buffer holds.
    if let Some(k) = indices.iter().position(|&i| i as usize >= count) {
        return Err(format!(
            "index number {k} points past the primitive's {count} vertices"
        ));
    }
    let triangles: Vec<[u32; 3]> = match primitive.mode() {
        Mode::Triangles => indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
        // Every other strip triangle is wound the other way round.
        Mode::TriangleStrip => indices
            .windows(3)
            .enumerate()
            .map(|(k, t)| {
                if k % 2 == 0 {
                    [t[0], t[1], t[2]]
                } else {
                    [t[1], t[0], t[2]]
                }
            })
            .collect(),
        Mode::TriangleFan => indices
            .iter()
            .skip(1)
            .zip(indices.iter().skip(2))
            .map(|(&b, &c)| [indices[0], b, c])
            .collect(),
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => Vec::new(),
    };
    mesh.triangles
        .extend(triangles.into_iter().map(|t| t.map(|i| i + base)));
    Ok(())
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

//! The files behind a URDF: the meshes it references, a copy of its text with those references
//! rewritten, and binary STL output.
//!
//! Two users: the MuJoCo cross-check, which hands MuJoCo the vendor's own URDF with every mesh
//! made an absolute path to a binary STL (MuJoCo resolves no `package://` URI and reads no
//! COLLADA), and `workcell robot add`, which copies a robot and its meshes into a folder of
//! its own with relative paths. The rewrite changes only the `filename` attribute values (and
//! inserts optional extra elements before `</robot>`), so the rest of the file stays byte for
//! byte what its vendor wrote.

use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::error::{Result, RobotError};
use crate::mesh::TriMesh;
use crate::package::PackageMap;

/// One `<mesh filename="...">` of a URDF.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MeshReference {
    /// The `filename` attribute as written (`package://...`, relative or absolute).
    pub uri: String,
    /// The file it resolves to.
    pub path: PathBuf,
    /// Byte range of the attribute value in the URDF text.
    value: Range<usize>,
}

/// A URDF's text and the meshes it references, resolved.
#[derive(Debug, Clone)]
pub struct UrdfAssets {
    /// Where the URDF was read from (anchors relative mesh paths).
    pub path: PathBuf,
    pub text: String,
    /// Every `<mesh>` element, in document order (a file referenced twice appears twice).
    pub meshes: Vec<MeshReference>,
    /// Byte offset of the root element's end tag `</robot>` (`None` for `<robot/>`).
    root_end: Option<usize>,
}

impl UrdfAssets {
    /// Reads `path` and resolves its meshes through `packages` (and the URDF's ancestors).
    ///
    /// # Errors
    /// [`RobotError::Io`], [`RobotError::Parse`] for text that is not XML with a `<robot>`
    /// root, [`RobotError::Mesh`] for a mesh that does not resolve to an existing file.
    pub fn read(path: impl AsRef<Path>, packages: &PackageMap) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::input::read_urdf_text(path)?;
        Self::from_text(text, path, packages)
    }

    /// Like [`UrdfAssets::read`] on text already read; `path` anchors relative mesh paths.
    ///
    /// # Errors
    /// As [`UrdfAssets::read`], without the I/O.
    pub fn from_text(text: String, path: &Path, packages: &PackageMap) -> Result<Self> {
        let parse = |message: String| RobotError::Parse {
            path: path.to_path_buf(),
            message,
        };
        let doc = crate::input::parse_xml(&text).map_err(parse)?;
        if doc.root_element().tag_name().name() != "robot" {
            return Err(parse(format!(
                "the root element is <{}>, not <robot>",
                doc.root_element().tag_name().name()
            )));
        }
        let root = doc.root_element().range();
        let root_end = text[root.clone()]
            .rfind("</")
            .map(|i| root.start + i)
            .filter(|&i| i > root.start);
        let urdf_dir = path.parent().unwrap_or(Path::new("."));
        let mut meshes = Vec::new();
        for node in doc
            .descendants()
            .filter(|n| n.has_tag_name("mesh") && is_geometry(n))
        {
            let Some(attribute) = node.attribute_node("filename") else {
                continue; // the URDF loader reports a mesh without a file
            };
            let uri = attribute.value().to_string();
            let element = owner_name(&node);
            let resolved = packages
                .resolve(&uri, urdf_dir)
                .map_err(|e| e.to_string())
                .and_then(|p| {
                    if p.is_file() {
                        Ok(p)
                    } else {
                        Err(format!("{} does not exist", p.display()))
                    }
                })
                .map_err(|message| RobotError::Mesh {
                    path: path.to_path_buf(),
                    element,
                    uri: uri.clone(),
                    message,
                })?;
            meshes.push(MeshReference {
                uri,
                path: resolved,
                value: attribute.range_value(),
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            text,
            meshes,
            root_end,
        })
    }

    /// The URDF text with the `k`-th mesh's filename replaced by `new_uris[k]` (escaped for
    /// XML here) and `extra` (XML elements, inserted verbatim) placed before `</robot>`.
    ///
    /// # Errors
    /// [`RobotError::InvalidArgument`] when `new_uris` does not have one entry per mesh.
    pub fn rewrite(&self, new_uris: &[String], extra: &str) -> Result<String> {
        if new_uris.len() != self.meshes.len() {
            return Err(RobotError::InvalidArgument {
                message: format!(
                    "{} new mesh paths for {} meshes",
                    new_uris.len(),
                    self.meshes.len()
                ),
            });
        }
        let mut out = String::with_capacity(self.text.len() + extra.len() + 256);
        let mut at = 0;
        for (m, uri) in self.meshes.iter().zip(new_uris) {
            out.push_str(&self.text[at..m.value.start]);
            out.push_str(&escape_attribute(uri));
            at = m.value.end;
        }
        if !extra.is_empty() {
            let end = self.root_end.ok_or_else(|| RobotError::Parse {
                path: self.path.clone(),
                message: "<robot/> is empty".into(),
            })?;
            out.push_str(&self.text[at..end]);
            out.push_str(extra);
            at = end;
        }
        out.push_str(&self.text[at..]);
        Ok(out)
    }
}

impl crate::catalogue::RobotSource {
    /// The URDF text and meshes of the robot (the embedded text for a built-in robot).
    ///
    /// # Errors
    /// As [`UrdfAssets::read`].
    pub fn assets(&self, packages: &PackageMap) -> Result<UrdfAssets> {
        match self {
            Self::Catalogue(entry) => {
                UrdfAssets::from_text(entry.urdf.to_string(), &self.path(), packages)
            }
            Self::File(path) => UrdfAssets::read(path, packages),
        }
    }
}

/// Writes `mesh` as a binary STL (facet normals from the vertex order).
///
/// # Errors
/// The I/O error of creating or writing the file.
pub fn write_binary_stl(mesh: &TriMesh, path: &Path) -> std::io::Result<()> {
    let count = u32::try_from(mesh.triangles.len()).map_err(|_| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "more triangles than binary STL can count",
        )
    })?;
    let mut bytes = Vec::with_capacity(84 + 50 * mesh.triangles.len());
    let mut header = [0_u8; 80];
    let note = b"binary STL written by workcell";
    header[..note.len()].copy_from_slice(note);
    bytes.extend_from_slice(&header);
    bytes.extend_from_slice(&count.to_le_bytes());
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let n = (b - a).cross(c - a).normalize_or_zero();
        for v in [n, a, b, c] {
            for x in [v.x, v.y, v.z] {
                bytes.extend_from_slice(&(x as f32).to_le_bytes());
            }
        }
        bytes.extend_from_slice(&[0, 0]);
    }
    let mut file = std::fs::File::create(path)?;
    file.write_all(&bytes)?;
    file.sync_all()
}

/// A robot copied into a library folder by [`add_robot`].
#[derive(Debug, Clone)]
pub struct AddedRobot {
    /// `<library>/<name>/<name>.urdf`.
    pub urdf: PathBuf,
    /// The distinct mesh files copied, as paths relative to the robot's folder.
    pub meshes: Vec<PathBuf>,
}

/// A robot's name in the library is a folder name that no path can be made of: ASCII letters,
/// digits, `_` and `-`, at most 64 of them. Check it before any file is touched: the name
/// becomes `<library>/<name>/` and the staging folders beside it.
///
/// # Errors
/// [`RobotError::InvalidArgument`] saying what the name may hold.
pub fn check_robot_name(name: &str) -> Result<()> {
    let valid = !name.is_empty()
        && name.len() <= MAX_ROBOT_NAME
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if valid {
        Ok(())
    } else {
        Err(RobotError::InvalidArgument {
            message: format!(
                "robot name {name:?} must be 1 to {MAX_ROBOT_NAME} letters, digits, '_' or '-'"
            ),
        })
    }
}

/// The longest robot name, characters.
pub const MAX_ROBOT_NAME: usize = 64;

/// Copies the URDF at `source` and every mesh it references into `<library>/<name>/`: the URDF
/// becomes `<name>.urdf` with its mesh paths made relative (`meshes/<package>/<path>` for
/// `package://` URIs, `meshes/<file>` otherwise), and `source.toml` records where it came
/// from. The folder is assembled beside its final place and renamed when complete; an
/// existing robot of that name is replaced only with `replace`.
///
/// # Errors
/// [`RobotError::InvalidArgument`] for a name [`check_robot_name`] refuses or that exists,
/// the errors of [`UrdfAssets::read`], [`RobotError::Io`] for a file that cannot be copied.
pub fn add_robot(
    source: &Path,
    packages: &PackageMap,
    name: &str,
    library: &Path,
    replace: bool,
) -> Result<AddedRobot> {
    let invalid = |message: String| RobotError::InvalidArgument { message };
    check_robot_name(name)?;
    let assets = UrdfAssets::read(source, packages)?;
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |error| RobotError::Io { path, error }
    };
    let target = library.join(name);
    if target.exists() && !replace {
        return Err(invalid(format!(
            "{} already exists (pass --force to replace it)",
            target.display()
        )));
    }
    let partial = library.join(format!(".{name}.partial"));
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(io(&partial))?;
    }
    std::fs::create_dir_all(&partial).map_err(io(&partial))?;

    // One relative path per distinct source file.
    let mut copied: Vec<(PathBuf, PathBuf)> = Vec::new();
    let mut uris = Vec::with_capacity(assets.meshes.len());
    for m in &assets.meshes {
        let relative = match copied.iter().find(|(from, _)| *from == m.path) {
            Some((_, to)) => to.clone(),
            None => {
                let mut to = mesh_destination(&m.uri, &m.path);
                let stem = to.clone();
                let mut k = 1;
                while copied.iter().any(|(_, t)| *t == to) {
                    to = stem.with_file_name(format!(
                        "{}_{k}.{}",
                        stem.file_stem().unwrap_or_default().to_string_lossy(),
                        stem.extension().unwrap_or_default().to_string_lossy()
                    ));
                    k += 1;
                }
                let dest = partial.join(&to);
                if let Some(dir) = dest.parent() {
                    std::fs::create_dir_all(dir).map_err(io(dir))?;
                }
                let bytes = crate::input::read_regular_file(&m.path, crate::input::MAX_MESH_BYTES)
                    .map_err(io(&m.path))?;
                std::fs::write(&dest, &bytes).map_err(io(&dest))?;
                // A .gltf's buffers in files of their own go beside it, under the names it
                // gives them (inside its folder only).
                for uri in crate::gltf_buffer_files(&bytes, &m.path) {
                    let from = crate::mesh::gltf_buffer_path(&m.path, &uri)
                        .map_err(|why| invalid(format!("{}: {why}", m.path.display())))?;
                    let to_file = dest.parent().unwrap_or(Path::new(".")).join(&uri);
                    if let Some(dir) = to_file.parent() {
                        std::fs::create_dir_all(dir).map_err(io(dir))?;
                    }
                    let buffer =
                        crate::input::read_regular_file(&from, crate::input::MAX_MESH_BYTES)
                            .map_err(io(&from))?;
                    std::fs::write(&to_file, buffer).map_err(io(&to_file))?;
                }
                copied.push((m.path.clone(), to.clone()));
                to
            }
        };
        uris.push(relative.to_string_lossy().replace('\\', "/"));
    }
    let text = assets.rewrite(&uris, "")?;
    let urdf_name = format!("{name}.urdf");
    let urdf = partial.join(&urdf_name);
    std::fs::write(&urdf, text).map_err(io(&urdf))?;
    let absolute = source.canonicalize().map_err(io(source))?;
    let record = format!(
        "# Written by `workcell robot add`: where this robot came from.\n\
         source = {:?}\n\
         meshes = {}\n\
         workcell = {:?}\n",
        absolute.to_string_lossy(),
        copied.len(),
        env!("CARGO_PKG_VERSION"),
    );
    let record_path = partial.join("source.toml");
    std::fs::write(&record_path, record).map_err(io(&record_path))?;
    if target.exists() {
        std::fs::remove_dir_all(&target).map_err(io(&target))?;
    }
    std::fs::rename(&partial, &target).map_err(io(&target))?;
    Ok(AddedRobot {
        urdf: target.join(urdf_name),
        meshes: copied.into_iter().map(|(_, to)| to).collect(),
    })
}

/// `meshes/<package>/<path>` for `package://<package>/<path>`, else `meshes/<file name>`.
fn mesh_destination(uri: &str, path: &Path) -> PathBuf {
    let mut out = PathBuf::from("meshes");
    if let Some(rest) = uri.strip_prefix("package://") {
        for part in rest.trim_start_matches('/').split('/') {
            if !part.is_empty() && part != "." && part != ".." {
                out.push(part);
            }
        }
        if out.components().count() > 1 {
            return out;
        }
    }
    out.push(path.file_name().unwrap_or_default());
    out
}

/// `<mesh>` inside `<geometry>` (URDF extensions may use the tag elsewhere).
fn is_geometry(node: &roxmltree::Node<'_, '_>) -> bool {
    node.parent().is_some_and(|p| p.has_tag_name("geometry"))
}

/// `link 'name' visual` or `link 'name' collision`, for errors.
fn owner_name(node: &roxmltree::Node<'_, '_>) -> String {
    let role = node
        .ancestors()
        .find(|a| a.has_tag_name("visual") || a.has_tag_name("collision"))
        .map_or("geometry", |a| a.tag_name().name());
    let link = node
        .ancestors()
        .find(|a| a.has_tag_name("link"))
        .and_then(|l| l.attribute("name"))
        .unwrap_or("?");
    format!("link '{link}' {role}")
}

fn escape_attribute(value: &str) -> String {
    let mut out = String::with_capacity(value.len());
    for c in value.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const URDF: &str = r#"<?xml version="1.0"?>
<!-- a vendor's comment -->
<robot name="r">
  <link name="base"><visual><geometry><mesh filename="a &amp; b.stl" scale="1 1 1"/></geometry></visual>
  <collision><geometry><mesh filename='a &amp; b.stl'/></geometry></collision></link>
</robot>
<!-- trailing </robot> look-alike in a comment: </robotics> -->
"#;

    #[test]
    fn rewrites_only_filenames_and_inserts_before_the_root_end() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a & b.stl"), b"x").unwrap();
        let path = dir.path().join("r.urdf");
        let assets = UrdfAssets::from_text(URDF.into(), &path, &PackageMap::new()).unwrap();
        assert_eq!(assets.meshes.len(), 2);
        assert_eq!(assets.meshes[0].uri, "a & b.stl");
        assert_eq!(assets.meshes[1].path, dir.path().join("a & b.stl"));
        let out = assets
            .rewrite(&["x\"y.stl".into(), "/abs/z.stl".into()], "<extra/>")
            .unwrap();
        let expected = URDF
            .replacen("a &amp; b.stl", "x&quot;y.stl", 1)
            .replacen("a &amp; b.stl", "/abs/z.stl", 1)
            .replacen("</robot>\n", "<extra/></robot>\n", 1);
        assert_eq!(out, expected);
        // Identity rewrite: byte for byte the input.
        let same: Vec<String> = assets.meshes.iter().map(|m| m.uri.clone()).collect();
        assert_eq!(assets.rewrite(&same, "").unwrap(), URDF);
        assert!(assets.rewrite(&[], "").is_err());
    }

    #[test]
    fn missing_meshes_and_non_urdf_text_are_errors() {
        let path = Path::new("/nonexistent/r.urdf");
        let e = UrdfAssets::from_text(URDF.into(), path, &PackageMap::new()).unwrap_err();
        assert!(e.to_string().contains("link 'base' visual"), "{e}");
        let e = UrdfAssets::from_text("<sdf/>".into(), path, &PackageMap::new()).unwrap_err();
        assert!(e.to_string().contains("not <robot>"), "{e}");
        let e = UrdfAssets::from_text("<robot".into(), path, &PackageMap::new()).unwrap_err();
        assert!(matches!(e, RobotError::Parse { .. }), "{e}");
    }

    #[test]
    fn binary_stl_round_trips_through_the_loader() {
        let mesh = TriMesh {
            vertices: vec![
                crate::math::Vector::new(0.0, 0.0, 0.0),
                crate::math::Vector::new(1.0, 0.0, 0.0),
                crate::math::Vector::new(0.0, 1.0, 0.0),
                crate::math::Vector::new(0.0, 0.0, 1.0),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.stl");
        write_binary_stl(&mesh, &path).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 84 + 4 * 50);
        let back = TriMesh::load(&path, [1.0; 3]).unwrap();
        assert_eq!(back.triangles.len(), 4);
        let (lo, hi) = back.bounds();
        assert_eq!((lo.to_array(), hi.to_array()), ([0.0; 3], [1.0; 3]));
    }
}

//! Resolution of mesh URIs (`package://pkg/path`, `file://`, relative paths) to files.
//!
//! Resolution is explicit: a [`PackageMap`] names the root folder of each package, searches
//! folders given by the caller or by `ROS_PACKAGE_PATH` / `WORKCELL_PACKAGE_PATH`, and finally
//! the ancestors of the URDF's own folder. A path that leaves its package root (by `..` or
//! by a symbolic link) is refused, never read.

use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

/// Environment variables read by [`PackageMap::from_env`]: lists of folders separated by `:`.
pub const PACKAGE_PATH_VARS: [&str; 2] = ["WORKCELL_PACKAGE_PATH", "ROS_PACKAGE_PATH"];

/// Why a mesh URI did not resolve to a file: the message names the URI and the reason.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ResolveError(String);

/// Where packages live. See the [module docs](self).
#[derive(Debug, Clone, Default)]
pub struct PackageMap {
    packages: BTreeMap<String, PathBuf>,
    search_paths: Vec<PathBuf>,
}

impl PackageMap {
    /// An empty map: only the URDF's own ancestors are searched.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// A map that also searches the folders listed in `WORKCELL_PACKAGE_PATH` and
    /// `ROS_PACKAGE_PATH`.
    #[must_use]
    pub fn from_env() -> Self {
        let mut map = Self::new();
        for var in PACKAGE_PATH_VARS {
            if let Some(value) = std::env::var_os(var) {
                for dir in std::env::split_paths(&value) {
                    if !dir.as_os_str().is_empty() {
                        map.search_paths.push(dir);
                    }
                }
            }
        }
        map
    }

    /// Maps package `name` to the folder `root` (the folder that holds its `package.xml`).
    pub fn insert(&mut self, name: impl Into<String>, root: impl Into<PathBuf>) -> &mut Self {
        self.packages.insert(name.into(), root.into());
        self
    }

    /// Adds a folder in which a package `pkg` is looked up as `folder/pkg`.
    pub fn add_search_path(&mut self, folder: impl Into<PathBuf>) -> &mut Self {
        self.search_paths.push(folder.into());
        self
    }

    /// The explicitly mapped packages, sorted by name.
    pub fn packages(&self) -> impl Iterator<Item = (&str, &Path)> {
        self.packages.iter().map(|(k, v)| (k.as_str(), v.as_path()))
    }

    /// Resolves `uri`, as written in a URDF found in folder `urdf_dir`, to a file path.
    ///
    /// # Errors
    /// [`ResolveError`], saying why: unknown package, a path escaping its root, an
    /// unsupported scheme.
    pub fn resolve(&self, uri: &str, urdf_dir: &Path) -> Result<PathBuf, ResolveError> {
        self.resolve_inner(uri, urdf_dir).map_err(ResolveError)
    }

    fn resolve_inner(&self, uri: &str, urdf_dir: &Path) -> Result<PathBuf, String> {
        if let Some(rest) = uri.strip_prefix("package://") {
            // `package:///name/...` appears in exported files; the extra slash means nothing.
            let rest = rest.trim_start_matches('/');
            let (package, relative) = rest
                .split_once('/')
                .ok_or_else(|| format!("'{uri}' has no path after the package name"))?;
            let root = self.package_root(package, urdf_dir).ok_or_else(|| {
                format!(
                    "package '{package}' not found (map it explicitly, or list its parent \
                     folder in WORKCELL_PACKAGE_PATH or ROS_PACKAGE_PATH)"
                )
            })?;
            return join_inside(&root, relative);
        }
        // The package that holds the URDF (the nearest folder with a package.xml), or the
        // URDF's own folder when there is none.
        let own_root = urdf_dir
            .ancestors()
            .find(|dir| dir.join("package.xml").is_file())
            .unwrap_or(urdf_dir);
        let absolute = match uri.strip_prefix("file://") {
            Some(rest) if !Path::new(rest).is_absolute() => {
                return Err(format!("'{uri}' is not an absolute file:// URI"));
            }
            Some(rest) => Some(Path::new(rest)),
            None if uri.contains("://") => {
                return Err(format!("'{uri}' uses an unsupported URI scheme"));
            }
            None => Some(Path::new(uri)).filter(|p| p.is_absolute()),
        };
        if let Some(path) = absolute {
            // An absolute path must lie inside a root the user named or the URDF's package.
            let roots = self
                .packages
                .values()
                .chain(&self.search_paths)
                .map(PathBuf::as_path)
                .chain([own_root]);
            for root in roots {
                if let Ok(relative) = path.strip_prefix(root) {
                    return join_inside(root, &relative.to_string_lossy());
                }
            }
            return Err(format!(
                "'{uri}' is outside every known package root (the URDF's package {}, mapped \
                 packages and package search paths)",
                own_root.display()
            ));
        }
        let within = urdf_dir.strip_prefix(own_root).unwrap_or(Path::new(""));
        join_inside(own_root, &within.join(uri).to_string_lossy())
    }

    fn package_root(&self, package: &str, urdf_dir: &Path) -> Option<PathBuf> {
        if let Some(root) = self.packages.get(package) {
            return Some(root.clone());
        }
        for dir in &self.search_paths {
            if dir.file_name().is_some_and(|n| n == package) && dir.is_dir() {
                return Some(dir.clone());
            }
            let candidate = dir.join(package);
            if candidate.is_dir() {
                return Some(candidate);
            }
        }
        // The URDF's ancestors: one named like the package, or one holding the package. Only
        // a folder with a package.xml (or the URDF's own folder) is a package here: otherwise
        // `package://root/.bashrc` in a URDF under /root would open /root/.bashrc.
        let is_package = |dir: &Path| dir.join("package.xml").is_file();
        for dir in urdf_dir.ancestors() {
            if dir.file_name().is_some_and(|n| n == package) && (is_package(dir) || dir == urdf_dir)
            {
                return Some(dir.to_path_buf());
            }
            let candidate = dir.join(package);
            if is_package(&candidate) {
                return Some(candidate);
            }
        }
        None
    }
}

/// `root/relative`, refusing any path that leaves `root` lexically or through a link.
fn join_inside(root: &Path, relative: &str) -> Result<PathBuf, String> {
    let mut depth = 0_usize;
    let mut joined = root.to_path_buf();
    for component in Path::new(relative).components() {
        match component {
            Component::Normal(part) => {
                joined.push(part);
                depth += 1;
            }
            Component::CurDir => {}
            Component::ParentDir => {
                if depth == 0 {
                    return Err(format!(
                        "'{relative}' escapes its package root {}",
                        root.display()
                    ));
                }
                joined.pop();
                depth -= 1;
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(format!("'{relative}' is absolute inside a package"));
            }
        }
    }
    // A symbolic link inside the root may still point outside it.
    if let (Ok(real), Ok(real_root)) = (joined.canonicalize(), root.canonicalize())
        && !real.starts_with(&real_root)
    {
        return Err(format!(
            "'{relative}' resolves to {} outside its package root {}",
            real.display(),
            real_root.display()
        ));
    }
    Ok(joined)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree() -> tempfile::TempDir {
        let dir = tempfile::tempdir().expect("tempdir");
        let pkg = dir.path().join("share/my_robot");
        std::fs::create_dir_all(pkg.join("urdf")).expect("mkdir");
        std::fs::create_dir_all(pkg.join("meshes")).expect("mkdir");
        std::fs::write(pkg.join("package.xml"), "<package/>").expect("write");
        std::fs::write(pkg.join("meshes/a.stl"), "solid a\nendsolid a\n").expect("write");
        dir
    }

    #[test]
    fn package_found_among_urdf_ancestors() {
        let dir = tree();
        let urdf_dir = dir.path().join("share/my_robot/urdf");
        let map = PackageMap::new();
        let path = map
            .resolve("package://my_robot/meshes/a.stl", &urdf_dir)
            .expect("resolves");
        assert_eq!(path, dir.path().join("share/my_robot/meshes/a.stl"));
    }

    #[test]
    fn explicit_map_wins_and_search_path_works() {
        let dir = tree();
        let elsewhere = tempfile::tempdir().expect("tempdir");
        let mut map = PackageMap::new();
        map.insert("my_robot", dir.path().join("share/my_robot"));
        let p = map
            .resolve("package://my_robot/meshes/a.stl", elsewhere.path())
            .expect("explicit");
        assert!(p.is_file());
        let mut map = PackageMap::new();
        map.add_search_path(dir.path().join("share"));
        let p = map
            .resolve("package://my_robot/meshes/a.stl", elsewhere.path())
            .expect("search path");
        assert!(p.is_file());
    }

    #[test]
    fn escaping_the_package_root_is_refused() {
        let dir = tree();
        let urdf_dir = dir.path().join("share/my_robot/urdf");
        let map = PackageMap::new();
        let err = map
            .resolve("package://my_robot/../../../etc/passwd", &urdf_dir)
            .expect_err("escape");
        assert!(err.to_string().contains("escapes"), "{err}");
        // Relative paths may climb inside the package but not out of it.
        let ok = map.resolve("../meshes/a.stl", &urdf_dir).expect("inside");
        assert!(ok.is_file());
        let err = map
            .resolve("../../../x.stl", &urdf_dir)
            .expect_err("escape");
        assert!(err.to_string().contains("escapes"), "{err}");
    }

    #[cfg(unix)]
    #[test]
    fn symlink_out_of_the_package_is_refused() {
        let dir = tree();
        let outside = tempfile::tempdir().expect("tempdir");
        std::fs::write(outside.path().join("secret.stl"), "x").expect("write");
        let link = dir.path().join("share/my_robot/meshes/link.stl");
        std::os::unix::fs::symlink(outside.path().join("secret.stl"), &link).expect("symlink");
        let urdf_dir = dir.path().join("share/my_robot/urdf");
        let err = PackageMap::new()
            .resolve("package://my_robot/meshes/link.stl", &urdf_dir)
            .expect_err("symlink escape");
        assert!(err.to_string().contains("outside"), "{err}");
    }

    #[test]
    fn absolute_paths_stay_inside_known_roots() {
        let dir = tree();
        let pkg = dir.path().join("share/my_robot");
        let urdf_dir = pkg.join("urdf");
        let map = PackageMap::new();
        let inside = pkg.join("meshes/a.stl");
        for uri in [
            inside.display().to_string(),
            format!("file://{}", inside.display()),
        ] {
            assert_eq!(map.resolve(&uri, &urdf_dir).expect("inside"), inside);
        }
        for uri in ["/etc/hostname", "file:///etc/hostname", "/dev/zero"] {
            let err = map.resolve(uri, &urdf_dir).expect_err("outside");
            assert!(
                err.to_string().contains("outside every known package root"),
                "{err}"
            );
        }
        // `..` in an absolute path may not climb out either.
        let climb = format!("{}/../../../../etc/hostname", pkg.display());
        assert!(map.resolve(&climb, &urdf_dir).is_err());
        // A mapped package's files may be named absolutely.
        let elsewhere = tempfile::tempdir().expect("tempdir");
        let mut mapped = PackageMap::new();
        mapped.insert("my_robot", &pkg);
        assert_eq!(
            mapped
                .resolve(&inside.display().to_string(), elsewhere.path())
                .expect("mapped"),
            inside
        );
    }

    #[test]
    fn an_ancestor_is_a_package_only_with_a_package_xml() {
        let dir = tree();
        // `package://share/...` names an ancestor folder that is no package.
        let urdf_dir = dir.path().join("share/my_robot/urdf");
        let err = PackageMap::new()
            .resolve("package://share/my_robot/meshes/a.stl", &urdf_dir)
            .expect_err("not a package");
        assert!(err.to_string().contains("not found"), "{err}");
    }

    #[test]
    fn unknown_package_and_scheme() {
        let dir = tree();
        let map = PackageMap::new();
        assert!(
            map.resolve("package://nope/a.stl", dir.path())
                .unwrap_err()
                .to_string()
                .contains("not found")
        );
        assert!(
            map.resolve("http://x/a.stl", dir.path())
                .unwrap_err()
                .to_string()
                .contains("scheme")
        );
        assert!(map.resolve("package://nope", dir.path()).is_err());
    }
}

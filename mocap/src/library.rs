//! A clip library: collections of clip files, each with its format and the clips held out
//! of every tuning and training (the test split), in one TOML file
//! (`data/mocap/library.toml` for the shipped recordings).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{MocapError, Result};
use crate::{Clip, ClipFormat};

/// The largest library file read, bytes.
pub const MAX_LIBRARY_BYTES: u64 = 1 << 20;
/// The most clips a collection may hold.
pub const MAX_CLIPS: usize = 100_000;

/// Which clips.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// The clips settings may be chosen on (and networks trained on).
    Tuning,
    /// The held-out clips: reported, never tuned on.
    Test,
}

impl Split {
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Tuning => "tuning",
            Self::Test => "test",
        }
    }
}

/// One collection of a library file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Collection {
    /// Its name, the first part of each clip's id.
    pub name: String,
    /// Its folder, relative to the library file.
    pub dir: PathBuf,
    /// The ending of its clip files' names (`.bvh.gz`): every such file under `dir` is a
    /// clip.
    pub suffix: String,
    /// How its files are read.
    pub format: ClipFormat,
    /// The held-out clips, by their path under `dir` without `suffix`
    /// (`CollaborativeHammering/3`).
    #[serde(default)]
    pub test: Vec<String>,
    /// Where the recordings come from, for reports and the notice.
    #[serde(default)]
    pub source: String,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct LibraryFile {
    #[serde(rename = "collection")]
    collections: Vec<Collection>,
}

/// A clip of a library: its id (`collection/path`), file, format and split.
#[derive(Debug, Clone, PartialEq)]
pub struct LibraryClip {
    pub id: String,
    pub collection: String,
    pub path: PathBuf,
    pub format: ClipFormat,
    pub split: Split,
}

impl LibraryClip {
    /// Reads the clip, named by its id.
    ///
    /// # Errors
    /// As [`crate::read_clip`].
    pub fn read(&self) -> Result<Clip> {
        crate::read_clip(&self.path, &self.format, self.id.clone())
    }
}

/// A library file's clips, every one found on disk.
#[derive(Debug, Clone, PartialEq)]
pub struct Library {
    pub path: PathBuf,
    pub collections: Vec<Collection>,
    pub clips: Vec<LibraryClip>,
}

impl Library {
    /// Reads a library file and finds its clips.
    ///
    /// # Errors
    /// [`MocapError::Io`] for the file or a folder that cannot be read;
    /// [`MocapError::Parse`] for TOML that is not a library; [`MocapError::Invalid`] for a
    /// collection with no clips, a held-out clip that is not there, two collections of one
    /// name, more than [`MAX_CLIPS`] clips.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text =
            workcell_robots::input::read_text_file(path, MAX_LIBRARY_BYTES).map_err(|source| {
                MocapError::Io {
                    path: path.to_path_buf(),
                    source,
                }
            })?;
        Self::from_toml(&text, path)
    }

    /// Like [`Library::from_file`] on text already read; `path` names it in errors and
    /// anchors the collections' folders.
    ///
    /// # Errors
    /// As [`Library::from_file`], without the I/O of the file itself.
    pub fn from_toml(text: &str, path: &Path) -> Result<Self> {
        let file: LibraryFile = toml::from_str(text).map_err(|e| MocapError::Parse {
            path: path.to_path_buf(),
            line: None,
            message: e.to_string(),
        })?;
        let invalid = |message: String| MocapError::Invalid {
            path: path.to_path_buf(),
            message,
        };
        let root = path.parent().unwrap_or(Path::new("."));
        let mut clips = Vec::new();
        for (i, c) in file.collections.iter().enumerate() {
            if file.collections[..i].iter().any(|d| d.name == c.name) {
                return Err(invalid(format!("two collections named {:?}", c.name)));
            }
            let dir = root.join(&c.dir);
            let mut found = Vec::new();
            walk(&dir, &c.suffix, &mut found)?;
            found.sort();
            if found.is_empty() {
                return Err(invalid(format!(
                    "collection {}: no files ending in {:?} under {}",
                    c.name,
                    c.suffix,
                    dir.display()
                )));
            }
            let relative = |p: &Path| -> String {
                let r = p
                    .strip_prefix(&dir)
                    .unwrap_or(p)
                    .to_string_lossy()
                    .replace('\\', "/");
                r.strip_suffix(&c.suffix).unwrap_or(&r).to_string()
            };
            for held in &c.test {
                if !found.iter().any(|p| &relative(p) == held) {
                    return Err(invalid(format!(
                        "collection {}: held-out clip {held:?} is not one of its files",
                        c.name
                    )));
                }
            }
            for p in found {
                let name = relative(&p);
                clips.push(LibraryClip {
                    id: format!("{}/{name}", c.name),
                    collection: c.name.clone(),
                    split: if c.test.contains(&name) {
                        Split::Test
                    } else {
                        Split::Tuning
                    },
                    path: p,
                    format: c.format.clone(),
                });
                if clips.len() > MAX_CLIPS {
                    return Err(invalid(format!("more than {MAX_CLIPS} clips")));
                }
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            collections: file.collections,
            clips,
        })
    }

    /// The clips of `split` (all when `None`), in the library's order.
    pub fn clips(&self, split: Option<Split>) -> impl Iterator<Item = &LibraryClip> {
        self.clips
            .iter()
            .filter(move |c| split.is_none_or(|s| c.split == s))
    }
}

/// The deepest folder below a collection's `dir` that is searched for clips.
pub const MAX_DEPTH: usize = 16;
/// The most entries (files and folders) a collection's search looks at.
pub const MAX_ENTRIES: usize = 200_000;

/// Every regular file under `dir` whose name ends in `suffix` (symbolic links are not
/// followed; at most [`MAX_DEPTH`] folders deep and [`MAX_ENTRIES`] entries looked at).
fn walk(dir: &Path, suffix: &str, out: &mut Vec<PathBuf>) -> Result<()> {
    let mut seen = 0;
    walk_below(dir, suffix, out, 0, &mut seen)
}

fn walk_below(
    dir: &Path,
    suffix: &str,
    out: &mut Vec<PathBuf>,
    depth: usize,
    seen: &mut usize,
) -> Result<()> {
    let io = |source: std::io::Error| MocapError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let refuse = |message: String| MocapError::Invalid {
        path: dir.to_path_buf(),
        message,
    };
    if depth > MAX_DEPTH {
        return Err(refuse(format!("more than {MAX_DEPTH} folders deep")));
    }
    for entry in std::fs::read_dir(dir).map_err(io)? {
        *seen += 1;
        if *seen > MAX_ENTRIES {
            return Err(refuse(format!(
                "more than {MAX_ENTRIES} files and folders to search"
            )));
        }
        let entry = entry.map_err(io)?;
        let kind = entry.file_type().map_err(io)?;
        let path = entry.path();
        if kind.is_dir() {
            walk_below(&path, suffix, out, depth + 1, seen)?;
        } else if kind.is_file() && path.to_string_lossy().ends_with(suffix) {
            out.push(path);
            if out.len() > MAX_CLIPS {
                return Err(MocapError::Invalid {
                    path: dir.to_path_buf(),
                    message: format!("more than {MAX_CLIPS} clip files"),
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped library: every clip is found, the held-out ones are the test split, and
    /// no clip is in both.
    #[test]
    fn the_shipped_library_holds_out_its_test_clips() {
        let path = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../data/mocap/library.toml"
        ));
        let library = Library::from_file(path).expect("library");
        let count = |collection: &str, split: Option<Split>| {
            library
                .clips(split)
                .filter(|c| c.collection == collection)
                .count()
        };
        // 78 in the source, of which 8 are copies of others (data/mocap/hrc-task-clips/DUPLICATES).
        assert_eq!(count("hrc-task-clips", None), 70);
        assert_eq!(count("human-assembly-data", None), 20);
        let held: usize = library.collections.iter().map(|c| c.test.len()).sum();
        assert_eq!(library.clips(Some(Split::Test)).count(), held);
        assert_eq!(held, 18);
        for c in library.clips(Some(Split::Test)) {
            assert!(library.clips(Some(Split::Tuning)).all(|t| t.id != c.id));
        }
    }

    /// A collection's search stops at its depth bound instead of walking a whole disk.
    #[test]
    fn a_search_too_deep_is_refused() {
        let dir = tempfile::tempdir().expect("dir");
        let mut deep = dir.path().to_path_buf();
        for k in 0..=MAX_DEPTH + 1 {
            deep = deep.join(format!("d{k}"));
        }
        std::fs::create_dir_all(&deep).expect("dirs");
        let mut found = Vec::new();
        let err = walk(dir.path(), ".txt", &mut found)
            .expect_err("too deep")
            .to_string();
        assert!(err.contains("folders deep"), "{err}");
    }

    #[test]
    fn a_held_out_clip_that_is_not_there_is_refused() {
        let dir = tempfile::tempdir().expect("dir");
        std::fs::create_dir(dir.path().join("c")).expect("dir");
        std::fs::write(dir.path().join("c/a.txt"), "0 0 0\n0 0 0\n").expect("write");
        let lib = dir.path().join("library.toml");
        std::fs::write(
            &lib,
            "[[collection]]\nname = \"c\"\ndir = \"c\"\nsuffix = \".txt\"\ntest = [\"b\"]\n\
             format = { format = \"table\", columns = [\"pelvis\"], rate_hz = 10.0 }\n",
        )
        .expect("write");
        let err = Library::from_file(&lib).expect_err("no b").to_string();
        assert!(err.contains("held-out clip \"b\""), "{err}");
        std::fs::write(
            &lib,
            "[[collection]]\nname = \"c\"\ndir = \"c\"\nsuffix = \".txt\"\ntest = [\"a\"]\n\
             format = { format = \"table\", columns = [\"pelvis\"], rate_hz = 10.0 }\n",
        )
        .expect("write");
        let library = Library::from_file(&lib).expect("library");
        assert_eq!(library.clips(Some(Split::Test)).count(), 1);
        let clip = library.clips[0].read().expect("clip");
        assert_eq!((clip.name.as_str(), clip.frames()), ("c/a", 2));
    }
}

#[cfg(test)]
mod sides {
    use super::*;
    use crate::Landmark as L;

    fn shipped() -> Library {
        let path = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../data/mocap/library.toml"
        ));
        Library::from_file(path).expect("library")
    }

    /// The bone directions of the source's own Vicon export (`CollaborativeHammering/0.csv`
    /// of human-robot-animations at its SOURCE_COMMIT: the segments' global positions, frames
    /// 716, 1077 and 1567, the BVH's frames 500, 861 and 1351), turned into the BVH's axes
    /// as the source's converter turns them (SciPy 1.17.1: `Rz(90) Ry(90) Rz(-90)`), unit
    /// vectors: right upper arm, right forearm, left upper arm, left forearm, neck to head.
    const VICON: [(usize, [[f64; 3]; 5]); 3] = [
        (
            500,
            [
                [0.5527, -0.4162, 0.7220],
                [0.1718, -0.6829, -0.7100],
                [-0.4012, -0.4318, -0.8078],
                [0.4352, -0.5907, -0.6794],
                [-0.4668, 0.8727, 0.1432],
            ],
        ),
        (
            861,
            [
                [0.5125, -0.4227, 0.7475],
                [0.1744, -0.6719, -0.7198],
                [-0.3837, -0.4338, -0.8152],
                [0.4234, -0.6391, -0.6421],
                [-0.3616, 0.9011, 0.2394],
            ],
        ),
        (
            1351,
            [
                [0.7303, 0.2914, 0.6178],
                [0.9976, -0.0519, -0.0467],
                [-0.8224, 0.2043, 0.5309],
                [-0.9959, 0.0040, -0.0906],
                [-0.0349, 0.8881, 0.4583],
            ],
        ),
    ];

    /// The largest angle, degrees, between `clip`'s bones and the Vicon export's at each of
    /// [`VICON`]'s frames.
    fn worst_angles(clip: &crate::Clip) -> Vec<f64> {
        let bones = [
            (L::RightShoulder, L::RightElbow),
            (L::RightElbow, L::RightWrist),
            (L::LeftShoulder, L::LeftElbow),
            (L::LeftElbow, L::LeftWrist),
            (L::Neck, L::Head),
        ];
        VICON
            .iter()
            .map(|(f, vicon)| {
                bones
                    .iter()
                    .zip(vicon)
                    .map(|(&(a, b), v)| {
                        let bone = (clip.track(b)[*f] - clip.track(a)[*f]).normalize();
                        let reference = crate::Axes::Y_UP.apply(*v).normalize();
                        bone.dot(reference).clamp(-1.0, 1.0).acos().to_degrees()
                    })
                    .fold(0.0, f64::max)
            })
            .collect()
    }

    /// Read as their converter wrote them (`euler = "fixed_zxy"`, the sides as named), the
    /// shipped Vicon clips give the recording's own bones to a fraction of a degree (the
    /// values were rounded to 0.01 degrees on import); read by the format's convention they
    /// are tens of degrees off wherever the person is out of the rest pose.
    #[test]
    fn the_vicon_clips_give_the_recordings_own_bones() {
        let library = shipped();
        let c = library
            .clips(None)
            .find(|c| c.id.ends_with("CollaborativeHammering/0"))
            .expect("the clip");
        let worst = worst_angles(&c.read().expect("clip"));
        assert!(worst.iter().all(|&a| a < 0.5), "{worst:?} degrees");
        let crate::ClipFormat::Bvh {
            joints,
            metres_per_unit,
            axes,
            ..
        } = c.format.clone()
        else {
            panic!("the Vicon clips are BVH");
        };
        let listed = crate::ClipFormat::Bvh {
            joints,
            metres_per_unit,
            axes,
            euler: Some(crate::bvh::Euler::Listed),
        };
        let clip = crate::read_clip(&c.path, &listed, c.id.clone()).expect("clip");
        let worst = worst_angles(&clip);
        assert!(worst[0] > 20.0 && worst[1] > 20.0, "{worst:?} degrees");
    }

    /// The sides are the person's: in every handover clip the hand the source's placement
    /// file says holds the object (`object_holding_hand` in `HumanRobotHandover/*_info.json`)
    /// is the one that travels farther about the neck.
    #[test]
    fn the_hand_that_holds_the_object_is_the_one_that_travels() {
        let holding = [
            ("0", L::RightWrist),
            ("1", L::RightWrist),
            ("2", L::RightWrist),
            ("3", L::RightWrist),
            ("4", L::RightWrist),
            ("5", L::LeftWrist),
            ("6", L::LeftWrist),
            ("7", L::LeftWrist),
            ("advanced_0", L::RightWrist),
            ("advanced_1", L::RightWrist),
            ("advanced_2", L::LeftWrist),
        ];
        let library = shipped();
        for (name, hand) in holding {
            let id = format!("HumanRobotHandover/{name}");
            let c = library
                .clips(None)
                .find(|c| c.id.ends_with(&id))
                .expect("the clip");
            let clip = c.read().expect("clip");
            let neck = clip.track(L::Neck);
            let travel = |l| {
                let t = clip.track(l);
                (1..clip.frames())
                    .map(|f| ((t[f] - neck[f]) - (t[f - 1] - neck[f - 1])).length())
                    .sum::<f64>()
            };
            let (right, left) = (travel(L::RightWrist), travel(L::LeftWrist));
            let farther = if right > left {
                L::RightWrist
            } else {
                L::LeftWrist
            };
            assert_eq!(farther, hand, "{id}: right {right:.1} m, left {left:.1} m");
        }
    }
}

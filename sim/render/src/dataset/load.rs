//! Reading a dataset back as float arrays.

use std::path::{Path, PathBuf};

use crate::Class;
use crate::dataset::frame_files;
use crate::dataset::labels::{
    FrameLabels, Manifest, READS, SEES_THROUGH_OCCLUDER, SequenceEntry, Split,
};
use crate::error::{RenderError, Result};
use crate::image::{PixelKind, read_png};
use crate::occlusion::OCCLUDER_DEPTH_M;
use workcell_robots::input::{MAX_CONFIG_BYTES, read_regular_file};

/// An opened dataset: its manifest and root folder.
#[derive(Debug, Clone)]
pub struct Dataset {
    pub root: PathBuf,
    pub manifest: Manifest,
}

/// One sequence, loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    pub entry: SequenceEntry,
    pub width: u32,
    pub height: u32,
    /// The network input, `[frames, 3, height, width]`, in [0, 1].
    pub rgb: Vec<f32>,
    /// Class per pixel without the occluder, `[frames, height, width]`.
    pub classes: Vec<u8>,
    /// Class per pixel seen through the occluder, `[frames, height, width]`.
    pub visible: Vec<u8>,
    /// 1 under the occluder, `[frames, height, width]`.
    pub occluder: Vec<u8>,
    /// 1 where the forearm rendered alone covers, `[frames, height, width]`.
    pub amodal_forearm: Vec<u8>,
    pub labels: Vec<FrameLabels>,
}

impl Sequence {
    /// Number of frames.
    #[must_use]
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    /// Whether the sequence has no frame.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// Pixels per frame.
    #[must_use]
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The input of frame `t`, `[3, height, width]`.
    #[must_use]
    pub fn rgb_frame(&self, t: usize) -> &[f32] {
        let n = 3 * self.pixels();
        &self.rgb[t * n..(t + 1) * n]
    }

    /// The classes of frame `t`, `[height, width]`.
    #[must_use]
    pub fn class_frame(&self, t: usize) -> &[u8] {
        let n = self.pixels();
        &self.classes[t * n..(t + 1) * n]
    }

    /// The classes of frame `t` seen through the occluder (0 under it), `[height, width]`.
    #[must_use]
    pub fn visible_frame(&self, t: usize) -> &[u8] {
        let n = self.pixels();
        &self.visible[t * n..(t + 1) * n]
    }
}

/// The most frames a sequence may have (the generator's limit too).
pub const MAX_SEQUENCE_FRAMES: usize = 10_000;
/// The most sequences a dataset may have.
pub const MAX_SEQUENCES: usize = 1_000_000;

fn invalid(path: &Path, message: impl std::fmt::Display) -> RenderError {
    RenderError::Dataset {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

impl Dataset {
    /// Opens the dataset in `root`.
    ///
    /// # Errors
    /// [`RenderError::Dataset`] when there is no manifest (the generation did not finish: run
    /// it again to complete it) or it is not a manifest of this format.
    pub fn open(root: impl AsRef<Path>) -> Result<Self> {
        let root = root.as_ref().to_path_buf();
        let path = root.join("manifest.json");
        let bytes = read_regular_file(&path, MAX_CONFIG_BYTES).map_err(|e| {
            invalid(
                &path,
                format!(
                    "{e}: not a finished dataset (rerun `workcell dataset generate` to complete it)"
                ),
            )
        })?;
        Self::from_manifest(root, &bytes)
    }

    /// The dataset in `root` whose `manifest.json` holds `bytes`, checked as [`Dataset::open`]
    /// checks it.
    ///
    /// # Errors
    /// As [`Dataset::open`], without the I/O.
    pub fn from_manifest(root: PathBuf, bytes: &[u8]) -> Result<Self> {
        let path = root.join("manifest.json");
        let manifest: Manifest = serde_json::from_slice(bytes).map_err(|e| invalid(&path, e))?;
        if !READS.contains(&manifest.format.as_str()) {
            return Err(invalid(
                &path,
                format!(
                    "format {:?}; this version reads {}",
                    manifest.format,
                    READS.join(", ")
                ),
            ));
        }
        // Every number is checked before anything is allocated from it.
        let side = 1..=crate::image::MAX_IMAGE_SIDE;
        if !side.contains(&manifest.width_px) || !side.contains(&manifest.height_px) {
            return Err(invalid(
                &path,
                format!(
                    "frames of {}x{} pixels; each side must be 1..={}",
                    manifest.width_px,
                    manifest.height_px,
                    crate::image::MAX_IMAGE_SIDE
                ),
            ));
        }
        if manifest.sequences.len() > MAX_SEQUENCES {
            return Err(invalid(
                &path,
                format!(
                    "{} sequences, more than the limit of {MAX_SEQUENCES}",
                    manifest.sequences.len()
                ),
            ));
        }
        if let Some(e) = manifest
            .sequences
            .iter()
            .find(|e| !(1..=MAX_SEQUENCE_FRAMES).contains(&e.frames))
        {
            return Err(invalid(
                &path,
                format!(
                    "sequence {} has {} frames; a sequence has 1..={MAX_SEQUENCE_FRAMES}",
                    e.index, e.frames
                ),
            ));
        }
        Ok(Self { root, manifest })
    }

    /// The sequences of `split` (all with `None`), in manifest order.
    pub fn entries(&self, split: Option<Split>) -> impl Iterator<Item = &SequenceEntry> {
        self.manifest
            .sequences
            .iter()
            .filter(move |e| split.is_none_or(|s| e.split == s))
    }

    /// The dataset's camera classes ([`SequenceEntry::camera_class`]) and occlusion levels in
    /// the order its configuration lists them (the generator writes the sequences pair by
    /// pair in that order, so it is their order of first appearance in the manifest): the
    /// order of every table's rows, whatever the classes and levels are named.
    #[must_use]
    pub fn label_order(&self) -> (Vec<String>, Vec<String>) {
        let (mut classes, mut levels) = (Vec::<String>::new(), Vec::<String>::new());
        for e in &self.manifest.sequences {
            let class = e.camera_class();
            if !classes.contains(&class) {
                classes.push(class);
            }
            if !levels.contains(&e.occlusion_level) {
                levels.push(e.occlusion_level.clone());
            }
        }
        (classes, levels)
    }

    /// Loads the sequences of `split` one after another.
    pub fn sequences(&self, split: Option<Split>) -> impl Iterator<Item = Result<Sequence>> + '_ {
        self.entries(split).map(|e| self.load(e))
    }

    /// The labels of one sequence's frames, without its images.
    ///
    /// # Errors
    /// [`RenderError::Io`] or [`RenderError::Dataset`] naming the file.
    pub fn labels(&self, entry: &SequenceEntry) -> Result<Vec<FrameLabels>> {
        (0..entry.frames)
            .map(|f| self.frame_labels(entry, f))
            .collect()
    }

    /// The labels of frame `f` of a sequence.
    ///
    /// # Errors
    /// [`RenderError::Io`] or [`RenderError::Dataset`] naming the file.
    pub fn frame_labels(&self, entry: &SequenceEntry, f: usize) -> Result<FrameLabels> {
        let path = self.sequence_dir(entry)?.join(&frame_files(f)[5]);
        let bytes =
            read_regular_file(&path, MAX_CONFIG_BYTES).map_err(|source| RenderError::Io {
                path: path.clone(),
                source,
            })?;
        serde_json::from_slice(&bytes).map_err(|e| invalid(&path, e))
    }

    /// The forearm's amodal mask of frame `f` of a sequence (1 where it covers).
    ///
    /// # Errors
    /// [`RenderError::Io`] or [`RenderError::Dataset`] naming the file.
    pub fn amodal_forearm(&self, entry: &SequenceEntry, f: usize) -> Result<Vec<u8>> {
        self.mask(entry, f, 4)
    }

    /// The grey mask `k` of [`frame_files`] of frame `f` (1 where it is set).
    fn mask(&self, entry: &SequenceEntry, f: usize, k: usize) -> Result<Vec<u8>> {
        let path = self.sequence_dir(entry)?.join(&frame_files(f)[k]);
        let (w, h, kind, data) = read_png(&path)?;
        if (w, h, kind)
            != (
                self.manifest.width_px,
                self.manifest.height_px,
                PixelKind::Gray,
            )
        {
            return Err(invalid(&path, "not a grey mask of the manifest's size"));
        }
        Ok(data.iter().map(|&v| u8::from(v >= 128)).collect())
    }

    /// The depth of frame `f` of a sequence: the camera-frame z of the surface each pixel
    /// shows, m (0 where nothing is; [`OCCLUDER_DEPTH_M`] under the artificial occluder).
    /// Formats 2 and 3 store it; it is read on demand, not by [`Dataset::load`], whose frames
    /// a training run holds in memory. Format 2 stored the scene behind the occluder, which
    /// no depth camera sees: its depth is read with the occluder put back in front.
    ///
    /// # Errors
    /// [`RenderError::Io`] or [`RenderError::Dataset`] naming the file: missing (a format 1
    /// dataset), corrupt, or not a 16-bit image of the manifest's size.
    pub fn depth(&self, entry: &SequenceEntry, f: usize) -> Result<Vec<f32>> {
        let path = self.sequence_dir(entry)?.join(&frame_files(f)[6]);
        let (w, h, kind, data) = read_png(&path)?;
        if (w, h, kind)
            != (
                self.manifest.width_px,
                self.manifest.height_px,
                PixelKind::Gray16,
            )
        {
            return Err(invalid(
                &path,
                "not a 16-bit depth image of the manifest's size",
            ));
        }
        let mut depth: Vec<f32> = data
            .chunks_exact(2)
            .map(|b| f32::from(u16::from_be_bytes([b[0], b[1]])) / 1000.0)
            .collect();
        if self.manifest.format == SEES_THROUGH_OCCLUDER {
            for (d, o) in depth.iter_mut().zip(self.mask(entry, f, 3)?) {
                if o != 0 {
                    *d = OCCLUDER_DEPTH_M;
                }
            }
        }
        Ok(depth)
    }

    /// The folder of a sequence (refusing one that leaves the dataset).
    fn sequence_dir(&self, entry: &SequenceEntry) -> Result<PathBuf> {
        if entry.dir.contains("..") || Path::new(&entry.dir).is_absolute() {
            return Err(invalid(
                &self.root.join("manifest.json"),
                format!("bad folder {:?}", entry.dir),
            ));
        }
        Ok(self.root.join(&entry.dir))
    }

    /// Loads one sequence and checks it against the manifest.
    ///
    /// # Errors
    /// [`RenderError::Io`] or [`RenderError::Dataset`] naming the file that is missing, corrupt or
    /// of the wrong size.
    pub fn load(&self, entry: &SequenceEntry) -> Result<Sequence> {
        let dir = self.sequence_dir(entry)?;
        let (w, h) = (self.manifest.width_px, self.manifest.height_px);
        let n = w as usize * h as usize;
        let mut s = Sequence {
            entry: entry.clone(),
            width: w,
            height: h,
            rgb: Vec::with_capacity(entry.frames * 3 * n),
            classes: Vec::with_capacity(entry.frames * n),
            visible: Vec::with_capacity(entry.frames * n),
            occluder: Vec::with_capacity(entry.frames * n),
            amodal_forearm: Vec::with_capacity(entry.frames * n),
            labels: Vec::with_capacity(entry.frames),
        };
        let classes = Class::ALL.len() as u8;
        for f in 0..entry.frames {
            let names = frame_files(f);
            let image = |name: &str, kind: PixelKind| -> Result<Vec<u8>> {
                let path = dir.join(name);
                let (iw, ih, k, data) = read_png(&path)?;
                if (iw, ih, k) != (w, h, kind) {
                    return Err(invalid(
                        &path,
                        format!("{iw}x{ih} {k:?}; the manifest says {w}x{h} {kind:?}"),
                    ));
                }
                Ok(data)
            };
            let rgb = image(&names[0], PixelKind::Rgb)?;
            for c in 0..3 {
                s.rgb
                    .extend(rgb.iter().skip(c).step_by(3).map(|&v| f32::from(v) / 255.0));
            }
            for (k, out) in [(1, &mut s.classes), (2, &mut s.visible)] {
                let data = image(&names[k], PixelKind::Gray)?;
                if let Some(bad) = data.iter().find(|&&v| v >= classes) {
                    return Err(invalid(
                        &dir.join(&names[k]),
                        format!("class {bad} is not one of 0..{classes}"),
                    ));
                }
                out.extend_from_slice(&data);
            }
            for (k, out) in [(3, &mut s.occluder), (4, &mut s.amodal_forearm)] {
                out.extend(
                    image(&names[k], PixelKind::Gray)?
                        .iter()
                        .map(|&v| u8::from(v >= 128)),
                );
            }
            let path = dir.join(&names[5]);
            let bytes =
                read_regular_file(&path, MAX_CONFIG_BYTES).map_err(|source| RenderError::Io {
                    path: path.clone(),
                    source,
                })?;
            let labels: FrameLabels =
                serde_json::from_slice(&bytes).map_err(|e| invalid(&path, e))?;
            s.labels.push(labels);
        }
        Ok(s)
    }
}

//! Loading URDF into a [`RobotModel`], with every field read and checked.
//!
//! urdf-rs parses the XML; this module turns it into our model and rejects what is not a
//! valid robot: a missing parent or child, a link with two parents, a cycle, several roots,
//! non-finite or negative numbers, a zero joint axis, a mimic of an unknown joint, a mesh that
//! cannot be found or decoded. Each error names the file and the element.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::{Result, RobotError};
use crate::math::{Pose, Vector, all_finite, pose_from_xyz_rpy};
use crate::mesh::TriMesh;
use crate::model::{
    Coordinate, Geometry, Inertial, Joint, JointKind, JointLimits, Link, RobotModel,
    SafetyController, Shape,
};
use crate::package::PackageMap;

impl RobotModel {
    /// Loads a URDF file; meshes are resolved through `packages`, then the URDF's ancestors.
    ///
    /// # Errors
    /// [`RobotError`] naming the file and the element that is wrong.
    pub fn from_urdf_file(path: impl AsRef<Path>, packages: &PackageMap) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::input::read_urdf_text(path)?;
        Self::from_urdf_str(&text, path, packages)
    }

    /// Loads URDF text; `path` names it in errors and anchors relative mesh paths.
    ///
    /// # Errors
    /// [`RobotError`] naming `path` and the element that is wrong.
    pub fn from_urdf_str(text: &str, path: &Path, packages: &PackageMap) -> Result<Self> {
        // Well-formed, bounded XML with a <robot> root before the recursive parser sees it.
        check_urdf_document(text, path)?;
        // urdf-rs reports an unknown joint type without saying which joint: find it first.
        if let Some((joint, kind)) = unknown_joint_type(text) {
            return Err(RobotError::invalid(
                path,
                format!("joint '{joint}'"),
                format!("unknown joint type '{kind}' (revolute, continuous, prismatic, fixed)"),
            ));
        }
        let mut warnings = Vec::new();
        // `<texture/>` without a filename is common in exported files and means nothing;
        // urdf-rs refuses it.
        let empty_textures =
            text.matches("<texture />").count() + text.matches("<texture/>").count();
        let text = if empty_textures > 0 {
            warnings.push(format!(
                "{empty_textures} empty <texture/> elements ignored"
            ));
            std::borrow::Cow::Owned(text.replace("<texture />", "").replace("<texture/>", ""))
        } else {
            std::borrow::Cow::Borrowed(text)
        };
        let robot = urdf_rs::read_from_string(&text).map_err(|e| RobotError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Builder {
            path,
            urdf_dir: path.parent().unwrap_or(Path::new(".")),
            packages,
            meshes: HashMap::new(),
            warnings,
        }
        .build(&robot)
    }
}

/// Checks that `text` is one well-formed XML document with a `<robot>` root, nested no
/// deeper than [`MAX_XML_DEPTH`](crate::input::MAX_XML_DEPTH), with at most
/// [`MAX_LINKS`](crate::input::MAX_LINKS) links.
fn check_urdf_document(text: &str, path: &Path) -> Result<()> {
    let parse = |message: String| RobotError::Parse {
        path: path.to_path_buf(),
        message,
    };
    let doc = crate::input::parse_xml(text).map_err(parse)?;
    let root = doc.root_element().tag_name().name();
    if root != "robot" {
        let hint = match root {
            "sdf" => " (this is an SDFormat file: export the model as URDF)",
            "mujoco" => " (this is an MJCF file for MuJoCo: export the model as URDF)",
            _ => "",
        };
        return Err(parse(format!(
            "the root element is <{root}>, not <robot>{hint}"
        )));
    }
    let links = doc
        .root_element()
        .children()
        .filter(|n| n.has_tag_name("link"))
        .count();
    if links > crate::input::MAX_LINKS {
        return Err(parse(format!(
            "{links} links, more than the limit of {}",
            crate::input::MAX_LINKS
        )));
    }
    Ok(())
}

/// The first `<joint name=".." type="..">` whose type URDF does not define, as
/// `(name, type)`. A plain scan of the start tags: the XML parser reports the rest.
fn unknown_joint_type(text: &str) -> Option<(String, String)> {
    const KNOWN: [&str; 7] = [
        "revolute",
        "continuous",
        "prismatic",
        "fixed",
        "floating",
        "planar",
        "spherical",
    ];
    let attribute = |tag: &str, name: &str| -> Option<String> {
        let start = tag.find(&format!(" {name}="))? + name.len() + 2;
        let quote = tag[start..].chars().next()?;
        let rest = &tag[start + quote.len_utf8()..];
        Some(rest[..rest.find(quote)?].to_string())
    };
    let mut rest = text;
    while let Some(at) = rest.find("<joint") {
        let tail = &rest[at + "<joint".len()..];
        let end = tail.find('>').unwrap_or(tail.len());
        let tag = &tail[..end];
        // `<joint` followed by whitespace is a joint element (not `<joint_properties>`).
        if tag.starts_with(char::is_whitespace)
            && let Some(kind) = attribute(tag, "type")
            && !KNOWN.contains(&kind.as_str())
        {
            return Some((attribute(tag, "name").unwrap_or_default(), kind));
        }
        rest = &tail[end..];
    }
    None
}

/// Negative inertia moments smaller than this (kg m^2) are rounding noise, not errors.
const INERTIA_NOISE_KGM2: f64 = 1e-12;
/// Positive principal moments below this (kg m^2) are noise, taken as 0 (a 1 g sphere of
/// 1 mm radius has 4e-10).
const MIN_INERTIA_KGM2: f64 = 1e-15;
/// The smallest positive mass accepted, kg.
const MIN_MASS_KG: f64 = 1e-9;

/// `v` scaled to unit length; `None` when it has no direction (zero or not finite). Scaled by
/// its largest component first, so that huge components (`1e200 1e200 0`) do not overflow
/// the length to infinity.
fn unit_direction(v: Vector) -> Option<Vector> {
    let largest = v.abs().max_element();
    if !largest.is_finite() || largest < 1e-9 {
        return None;
    }
    let unit = (v / largest).normalize();
    unit.is_normalized().then_some(unit)
}

struct Builder<'a> {
    path: &'a Path,
    urdf_dir: &'a Path,
    packages: &'a PackageMap,
    meshes: HashMap<(PathBuf, [u64; 3]), Arc<TriMesh>>,
    warnings: Vec<String>,
}

impl Builder<'_> {
    fn invalid(&self, element: impl Into<String>, message: impl Into<String>) -> RobotError {
        RobotError::invalid(self.path, element, message)
    }

    fn build(mut self, robot: &urdf_rs::Robot) -> Result<RobotModel> {
        if robot.links.is_empty() {
            let element = if robot.name.is_empty() {
                "<robot>".to_string()
            } else {
                format!("robot '{}'", robot.name)
            };
            return Err(self.invalid(element, "has no <link> element"));
        }
        let materials: HashMap<&str, [f64; 4]> = robot
            .materials
            .iter()
            .filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), c.rgba.0)))
            .collect();

        // Links, by name.
        let mut link_ids = HashMap::new();
        let mut links = Vec::with_capacity(robot.links.len());
        for (id, l) in robot.links.iter().enumerate() {
            if link_ids.insert(l.name.as_str(), id).is_some() {
                return Err(self.invalid(format!("link '{}'", l.name), "is defined twice"));
            }
            links.push(self.link(l, &materials)?);
        }

        // Joints: endpoints, one parent per link, values.
        let mut joint_names = HashMap::new();
        let mut raw = Vec::with_capacity(robot.joints.len());
        for j in &robot.joints {
            let element = format!("joint '{}'", j.name);
            if joint_names.insert(j.name.as_str(), raw.len()).is_some() {
                return Err(self.invalid(element, "is defined twice"));
            }
            let parent = *link_ids.get(j.parent.link.as_str()).ok_or_else(|| {
                self.invalid(
                    &element,
                    format!("parent link '{}' does not exist", j.parent.link),
                )
            })?;
            let child = *link_ids.get(j.child.link.as_str()).ok_or_else(|| {
                self.invalid(
                    &element,
                    format!("child link '{}' does not exist", j.child.link),
                )
            })?;
            if parent == child {
                return Err(self.invalid(element, "connects a link to itself"));
            }
            if let Some(other) = links[child].parent_joint {
                return Err(self.invalid(
                    element,
                    format!(
                        "link '{}' already has parent joint '{}'",
                        j.child.link, robot.joints[other].name
                    ),
                ));
            }
            links[child].parent_joint = Some(raw.len());
            raw.push(self.joint(j, parent, child)?);
        }

        // The root, then a depth-first order that reaches every link exactly once: each
        // branch's joints together, siblings in the file's order (a two-armed body's right
        // arm, written first, keeps its coordinates when the left arm is added after it).
        let roots: Vec<usize> = (0..links.len())
            .filter(|&l| links[l].parent_joint.is_none())
            .collect();
        let root = match roots.as_slice() {
            [root] => *root,
            [] => {
                return Err(self.invalid(
                    format!("robot '{}'", robot.name),
                    "every link has a parent joint: the joints form a cycle",
                ));
            }
            many => {
                let names: Vec<&str> = many.iter().map(|&l| links[l].name.as_str()).collect();
                return Err(self.invalid(
                    format!("robot '{}'", robot.name),
                    format!(
                        "has {} root links ({}); joints must connect them into one tree",
                        many.len(),
                        names.join(", ")
                    ),
                ));
            }
        };
        let mut order = Vec::with_capacity(raw.len());
        // Joints still to visit, the next on top.
        let mut stack: Vec<usize> = (0..raw.len())
            .rev()
            .filter(|&j| raw[j].parent == root)
            .collect();
        while let Some(j) = stack.pop() {
            if order.len() == raw.len() {
                break; // a cycle below the root would loop: reported below
            }
            order.push(j);
            let child = raw[j].child;
            stack.extend((0..raw.len()).rev().filter(|&k| raw[k].parent == child));
        }
        if order.len() != raw.len() {
            let stuck = (0..raw.len()).find(|j| !order.contains(j)).unwrap_or(0);
            return Err(self.invalid(
                format!("joint '{}'", raw[stuck].name),
                "is part of a cycle not connected to the root link",
            ));
        }

        // Renumber joints in topological order.
        let mut new_id = vec![0; raw.len()];
        for (new, &old) in order.iter().enumerate() {
            new_id[old] = new;
        }
        let mut joints: Vec<Joint> = order.iter().map(|&old| raw[old].clone()).collect();
        for link in &mut links {
            link.parent_joint = link.parent_joint.map(|old| new_id[old]);
        }

        // Coordinates: every movable joint that is not a mimic, in topological order.
        let mut actuated = Vec::new();
        for (id, joint) in joints.iter_mut().enumerate() {
            if joint.kind.is_movable() && joint.mimic.is_none() {
                joint.coordinate = Coordinate::Own {
                    index: actuated.len(),
                };
                actuated.push(id);
            }
        }
        if actuated.len() > crate::input::MAX_DOF {
            return Err(self.invalid(
                format!("robot '{}'", robot.name),
                format!(
                    "{} actuated joints, more than the limit of {} (rapier's multibody \
                     solver costs O(n^3) per step)",
                    actuated.len(),
                    crate::input::MAX_DOF
                ),
            ));
        }
        self.resolve_mimics(&mut joints)?;

        tracing::debug!(
            path = %self.path.display(),
            links = links.len(),
            joints = joints.len(),
            dof = actuated.len(),
            meshes = self.meshes.len(),
            "URDF loaded"
        );
        Ok(RobotModel {
            name: robot.name.clone(),
            source: self.path.to_path_buf(),
            links,
            joints,
            actuated,
            root,
            warnings: self.warnings,
        })
    }

    /// Resolves each mimic joint to the coordinate it follows, through chains of mimics.
    fn resolve_mimics(&self, joints: &mut [Joint]) -> Result<()> {
        let by_name: BTreeMap<String, usize> = joints
            .iter()
            .enumerate()
            .map(|(i, j)| (j.name.clone(), i))
            .collect();
        for id in 0..joints.len() {
            let Some((_, _, _)) = joints[id].mimic else {
                continue;
            };
            let element = format!("joint '{}'", joints[id].name);
            let (mut multiplier, mut offset) = (1.0, 0.0);
            let mut current = id;
            let mut hops = 0;
            while let Some((target, m, o)) = joints[current].mimic.clone() {
                let next = *by_name.get(&target).ok_or_else(|| {
                    self.invalid(
                        &element,
                        format!("mimics joint '{target}', which does not exist"),
                    )
                })?;
                if !joints[next].kind.is_movable() {
                    return Err(self.invalid(&element, format!("mimics fixed joint '{target}'")));
                }
                // q_current = m * q_next + o, and q_next = multiplier' * q_root + offset'.
                offset += multiplier * o;
                multiplier *= m;
                current = next;
                hops += 1;
                if hops > joints.len() {
                    return Err(self.invalid(&element, "mimic joints form a cycle"));
                }
            }
            let max = crate::input::MAX_MIMIC_FACTOR;
            if multiplier.abs() > max || offset.abs() > max {
                return Err(self.invalid(
                    &element,
                    format!(
                        "its chain of mimics multiplies to {multiplier:e} with offset \
                         {offset:e}, beyond +-{max}"
                    ),
                ));
            }
            let Coordinate::Own { index } = joints[current].coordinate else {
                return Err(self.invalid(&element, "mimics a joint with no coordinate"));
            };
            joints[id].coordinate = Coordinate::Mimic {
                index,
                multiplier,
                offset,
            };
        }
        Ok(())
    }

    fn joint(&mut self, j: &urdf_rs::Joint, parent: usize, child: usize) -> Result<Joint> {
        let element = format!("joint '{}'", j.name);
        let mut kind = match j.joint_type {
            urdf_rs::JointType::Revolute => JointKind::Revolute,
            urdf_rs::JointType::Continuous => JointKind::Continuous,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Fixed => JointKind::Fixed,
            ref other => {
                return Err(self.invalid(
                    element,
                    format!("joint type '{other:?}' is not supported (revolute, continuous, prismatic, fixed)").to_lowercase(),
                ));
            }
        };
        let X_PJ = self.origin(&element, &j.origin)?;
        let axis = if kind.is_movable() {
            unit_direction(Vector::from_array(j.axis.xyz.0)).ok_or_else(|| {
                self.invalid(
                    &element,
                    format!("axis {:?} is not a direction", j.axis.xyz.0),
                )
            })?
        } else {
            Vector::X
        };
        let l = &j.limit;
        for (name, v) in [("velocity", l.velocity), ("effort", l.effort)] {
            if v.is_nan() || v < 0.0 {
                return Err(self.invalid(&element, format!("limit {name}={v} must be >= 0")));
            }
        }
        if l.lower.is_nan() || l.upper.is_nan() || l.acceleration.is_nan() || l.acceleration < 0.0 {
            return Err(self.invalid(&element, "limit has a NaN or negative value"));
        }
        let (lower, upper) = match kind {
            JointKind::Continuous => (f64::NEG_INFINITY, f64::INFINITY),
            JointKind::Fixed => (0.0, 0.0),
            JointKind::Revolute
                if l.lower.abs().max(l.upper.abs()) > crate::input::MAX_JOINT_LIMIT =>
            {
                self.warnings.push(format!(
                    "{element}: limits lower={:e} upper={:e} beyond +-{:e} rad taken as \
                     none: the joint is continuous",
                    l.lower,
                    l.upper,
                    crate::input::MAX_JOINT_LIMIT
                ));
                kind = JointKind::Continuous;
                (f64::NEG_INFINITY, f64::INFINITY)
            }
            JointKind::Revolute | JointKind::Prismatic => {
                let max = crate::input::MAX_JOINT_LIMIT;
                if l.lower.abs() > max || l.upper.abs() > max {
                    return Err(self.invalid(
                        element,
                        format!(
                            "prismatic limit lower={:e} upper={:e} is beyond +-{max:e} m",
                            l.lower, l.upper
                        ),
                    ));
                }
                if l.lower > l.upper {
                    return Err(self.invalid(
                        element,
                        format!("limit lower={} is above upper={}", l.lower, l.upper),
                    ));
                }
                (l.lower, l.upper)
            }
        };
        let safety_controller = match &j.safety_controller {
            Some(s) => {
                let v = [
                    s.soft_lower_limit,
                    s.soft_upper_limit,
                    s.k_position,
                    s.k_velocity,
                ];
                if !all_finite(&v) || s.k_velocity < 0.0 || s.k_position < 0.0 {
                    return Err(self.invalid(
                        element,
                        "safety_controller has a non-finite or negative value",
                    ));
                }
                Some(SafetyController {
                    soft_lower_limit: s.soft_lower_limit,
                    soft_upper_limit: s.soft_upper_limit,
                    k_position: s.k_position,
                    k_velocity: s.k_velocity,
                })
            }
            None => None,
        };
        let mimic = match &j.mimic {
            Some(m) => {
                let multiplier = m.multiplier.unwrap_or(1.0);
                let offset = m.offset.unwrap_or(0.0);
                let max = crate::input::MAX_MIMIC_FACTOR;
                if !all_finite(&[multiplier, offset])
                    || multiplier.abs() > max
                    || offset.abs() > max
                {
                    return Err(self.invalid(
                        element,
                        format!(
                            "mimic multiplier {multiplier:e} or offset {offset:e} is not finite or \
                             beyond +-{max}"
                        ),
                    ));
                }
                if kind.is_movable() {
                    Some((m.joint.clone(), multiplier, offset))
                } else {
                    // A fixed joint does not move: its mimic means nothing (ROS ignores it).
                    self.warnings
                        .push(format!("{element}: <mimic> on a fixed joint ignored"));
                    None
                }
            }
            None => None,
        };
        let (damping, friction) = j
            .dynamics
            .as_ref()
            .map_or((0.0, 0.0), |d| (d.damping, d.friction));
        if !all_finite(&[damping, friction]) || damping < 0.0 || friction < 0.0 {
            return Err(self.invalid(element, "dynamics damping/friction must be finite and >= 0"));
        }
        Ok(Joint {
            name: j.name.clone(),
            kind,
            parent,
            child,
            X_PJ,
            axis,
            limits: JointLimits {
                lower,
                upper,
                velocity: l.velocity,
                effort: l.effort,
                acceleration: l.acceleration,
            },
            safety_controller,
            mimic,
            damping,
            friction,
            coordinate: Coordinate::None,
        })
    }

    fn origin(&self, element: &str, origin: &urdf_rs::Pose) -> Result<Pose> {
        if !all_finite(&origin.xyz.0) || !all_finite(&origin.rpy.0) {
            return Err(self.invalid(element, "origin has a non-finite value"));
        }
        Ok(pose_from_xyz_rpy(origin.xyz.0, origin.rpy.0))
    }

    fn link(&mut self, l: &urdf_rs::Link, materials: &HashMap<&str, [f64; 4]>) -> Result<Link> {
        let element = format!("link '{}'", l.name);
        let i = &l.inertial;
        let tensor = [
            i.inertia.ixx,
            i.inertia.ixy,
            i.inertia.ixz,
            i.inertia.iyy,
            i.inertia.iyz,
            i.inertia.izz,
        ];
        if !i.mass.value.is_finite() || i.mass.value < 0.0 {
            return Err(self.invalid(
                element,
                format!("inertial mass {} must be finite and >= 0", i.mass.value),
            ));
        }
        if !all_finite(&tensor)
            || [tensor[0], tensor[3], tensor[5]]
                .iter()
                .any(|d| *d < -INERTIA_NOISE_KGM2)
        {
            return Err(self.invalid(
                element,
                "inertia has a non-finite or negative diagonal value",
            ));
        }
        if i.mass.value > 0.0 && i.mass.value < MIN_MASS_KG {
            return Err(self.invalid(
                element,
                format!(
                    "inertial mass {:e} kg: 0 (massless) or at least {MIN_MASS_KG:e} kg",
                    i.mass.value
                ),
            ));
        }
        // Exporters write numerical noise such as -5e-20 for zero moments: clamp it to zero.
        let mut tensor = tensor;
        // Moments far below any physical body's (icub writes 2.7e-20) are noise too, and
        // rapier divides by them: take them as 0 (rotation about that axis locked).
        for k in [0, 3, 5] {
            if tensor[k] < 0.0 {
                tensor[k] = 0.0;
                self.warnings.push(format!(
                    "{element}: inertia diagonal {k} below zero by rounding, taken as 0"
                ));
            } else if tensor[k] > 0.0 && tensor[k] < MIN_INERTIA_KGM2 {
                self.warnings.push(format!(
                    "{element}: inertia diagonal {k} = {:e} below {MIN_INERTIA_KGM2:e} kg m^2, \
                     taken as 0",
                    tensor[k]
                ));
                tensor[k] = 0.0;
            }
        }
        let inertial = (i.mass.value > 0.0).then(|| -> Result<Inertial> {
            Ok(Inertial {
                mass_kg: i.mass.value,
                X_LI: self.origin(&element, &i.origin)?,
                inertia_kgm2: tensor,
            })
        });
        let inertial = inertial.transpose()?;

        let mut visuals = Vec::with_capacity(l.visual.len());
        for (k, v) in l.visual.iter().enumerate() {
            let el = format!("{element} visual {k}");
            let rgba = v.material.as_ref().and_then(|m| {
                m.color
                    .as_ref()
                    .map(|c| c.rgba.0)
                    .or_else(|| materials.get(m.name.as_str()).copied())
            });
            visuals.push(Geometry {
                name: v.name.clone(),
                X_LG: self.origin(&el, &v.origin)?,
                shape: self.shape(&el, &v.geometry)?,
                rgba,
            });
        }
        let mut collisions = Vec::with_capacity(l.collision.len());
        for (k, c) in l.collision.iter().enumerate() {
            let el = format!("{element} collision {k}");
            collisions.push(Geometry {
                name: c.name.clone(),
                X_LG: self.origin(&el, &c.origin)?,
                shape: self.shape(&el, &c.geometry)?,
                rgba: None,
            });
        }
        Ok(Link {
            name: l.name.clone(),
            parent_joint: None,
            inertial,
            visuals,
            collisions,
        })
    }

    fn shape(&mut self, element: &str, g: &urdf_rs::Geometry) -> Result<Shape> {
        let positive = |what: &str, v: &[f64]| -> Result<()> {
            if v.iter().all(|x| x.is_finite() && *x >= 0.0) {
                Ok(())
            } else {
                Err(self.invalid(element, format!("{what} {v:?} must be finite and >= 0")))
            }
        };
        Ok(match g {
            urdf_rs::Geometry::Box { size } => {
                positive("box size", &size.0)?;
                Shape::Box { size_m: size.0 }
            }
            urdf_rs::Geometry::Cylinder { radius, length } => {
                positive("cylinder radius/length", &[*radius, *length])?;
                Shape::Cylinder {
                    radius_m: *radius,
                    length_m: *length,
                }
            }
            urdf_rs::Geometry::Capsule { radius, length } => {
                positive("capsule radius/length", &[*radius, *length])?;
                Shape::Capsule {
                    radius_m: *radius,
                    length_m: *length,
                }
            }
            urdf_rs::Geometry::Sphere { radius } => {
                positive("sphere radius", &[*radius])?;
                Shape::Sphere { radius_m: *radius }
            }
            urdf_rs::Geometry::Mesh { filename, scale } => {
                let scale = scale.map_or([1.0; 3], |s| s.0);
                if !all_finite(&scale) {
                    return Err(self.invalid(element, "mesh scale has a non-finite value"));
                }
                let mesh_error = |message: String| RobotError::Mesh {
                    path: self.path.to_path_buf(),
                    element: element.to_string(),
                    uri: filename.clone(),
                    message,
                };
                let path = self
                    .packages
                    .resolve(filename, self.urdf_dir)
                    .map_err(|e| mesh_error(e.to_string()))?;
                let key = (path.clone(), scale.map(f64::to_bits));
                let mesh = match self.meshes.get(&key) {
                    Some(mesh) => mesh.clone(),
                    None => {
                        let mesh = Arc::new(TriMesh::load(&path, scale).map_err(|e| {
                            RobotError::Mesh {
                                path: self.path.to_path_buf(),
                                element: element.to_string(),
                                uri: filename.clone(),
                                message: e.to_string(),
                            }
                        })?);
                        self.meshes.insert(key, mesh.clone());
                        mesh
                    }
                };
                Shape::Mesh {
                    uri: filename.clone(),
                    path,
                    scale,
                    mesh,
                }
            }
        })
    }
}

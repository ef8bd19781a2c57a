//! The human's parts: one vocabulary for the renderer's classes, the dataset's labels, the
//! network's outputs and the safety layer's capsules.

use serde::{Deserialize, Serialize};

/// A part of the human body that the cell models, named as the links of the catalogue's
/// `human` and `human_arm` and as the segmentation classes (`snake_case` in files). The head
/// is a part of the safety layer's (ISO/TS 15066's head and face: no contact permitted); a
/// camera's classes show it as the torso's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HumanPart {
    Torso,
    UpperArm,
    Forearm,
    Hand,
    Head,
    LeftUpperArm,
    LeftForearm,
    LeftHand,
}

impl HumanPart {
    /// Every part, torso first, the right arm's before the left arm's (the one-armed
    /// models' parts are the first five).
    pub const ALL: [HumanPart; 8] = [
        HumanPart::Torso,
        HumanPart::UpperArm,
        HumanPart::Forearm,
        HumanPart::Hand,
        HumanPart::Head,
        HumanPart::LeftUpperArm,
        HumanPart::LeftForearm,
        HumanPart::LeftHand,
    ];

    /// The parts of the (right) arm, in the order used in tables (the safety layer's
    /// capsules): the arm of the one-armed models, the one the articulated fit follows.
    pub const ARM: [HumanPart; 3] = [HumanPart::UpperArm, HumanPart::Forearm, HumanPart::Hand];

    /// The left arm's parts, in [`HumanPart::ARM`]'s order.
    pub const LEFT_ARM: [HumanPart; 3] = [
        HumanPart::LeftUpperArm,
        HumanPart::LeftForearm,
        HumanPart::LeftHand,
    ];

    /// The side of the body the part is on: `Some(Side::Right)` for the right arm's parts,
    /// `Some(Side::Left)` for the left's, `None` for the torso and the head.
    #[must_use]
    pub fn side(self) -> Option<Side> {
        match self {
            HumanPart::Torso | HumanPart::Head => None,
            HumanPart::UpperArm | HumanPart::Forearm | HumanPart::Hand => Some(Side::Right),
            HumanPart::LeftUpperArm | HumanPart::LeftForearm | HumanPart::LeftHand => {
                Some(Side::Left)
            }
        }
    }

    /// The same part on the other side of the body (the torso and the head are their own).
    #[must_use]
    pub fn mirrored(self) -> HumanPart {
        match self {
            HumanPart::UpperArm => HumanPart::LeftUpperArm,
            HumanPart::Forearm => HumanPart::LeftForearm,
            HumanPart::Hand => HumanPart::LeftHand,
            HumanPart::LeftUpperArm => HumanPart::UpperArm,
            HumanPart::LeftForearm => HumanPart::Forearm,
            HumanPart::LeftHand => HumanPart::Hand,
            HumanPart::Torso | HumanPart::Head => self,
        }
    }

    /// The part of the right arm (or the torso or head) this part is the same limb as: the
    /// part without its side, for the figures that are the same on both sides (sizes, ISO/TS
    /// 15066's body regions).
    #[must_use]
    pub fn limb(self) -> HumanPart {
        match self.side() {
            Some(Side::Left) => self.mirrored(),
            _ => self,
        }
    }

    /// Lower-case name, also the link name of the part in the catalogue `human_arm`
    /// (`upper_arm`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            HumanPart::Torso => "torso",
            HumanPart::UpperArm => "upper_arm",
            HumanPart::Forearm => "forearm",
            HumanPart::Hand => "hand",
            HumanPart::Head => "head",
            HumanPart::LeftUpperArm => "left_upper_arm",
            HumanPart::LeftForearm => "left_forearm",
            HumanPart::LeftHand => "left_hand",
        }
    }

    /// The link name of the part in a human model (the same as [`HumanPart::name`]).
    #[must_use]
    pub fn link_name(self) -> &'static str {
        self.name()
    }

    /// The part a human model's link of this name belongs to: the part names themselves,
    /// and `shoulder` (the upper arm's first joint frame) as the upper arm, `left_shoulder`
    /// as the left's. Other links (the frames between a joint's axes) belong to their
    /// parent's part.
    #[must_use]
    pub fn of_link_name(name: &str) -> Option<HumanPart> {
        match name {
            "shoulder" => Some(HumanPart::UpperArm),
            "left_shoulder" => Some(HumanPart::LeftUpperArm),
            _ => HumanPart::from_name(name),
        }
    }

    /// The part named `name` (`forearm`), as [`HumanPart::name`] writes it.
    #[must_use]
    pub fn from_name(name: &str) -> Option<HumanPart> {
        HumanPart::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// A side of the body, as the person sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Right,
    Left,
}

impl Side {
    /// `right` or `left`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Side::Right => "right",
            Side::Left => "left",
        }
    }

    /// The other side.
    #[must_use]
    pub fn other(self) -> Self {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

impl std::fmt::Display for Side {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::fmt::Display for HumanPart {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for HumanPart {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        HumanPart::from_name(s).ok_or_else(|| {
            format!(
                "unknown human part {s:?} (one of {})",
                HumanPart::ALL.map(HumanPart::name).join(", ")
            )
        })
    }
}

/// How a human model looks to a camera: which of its visuals are drawn. Visuals named
/// `bone/*` belong to the skeletal look, `flesh/*` to the flesh look; unnamed (or otherwise
/// named) visuals are drawn in both, so any human URDF has at least one look.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HumanLook {
    /// Soft tissue: a torso with chest, shoulders, neck and head; tapered limbs and a hand.
    #[default]
    Flesh,
    /// The paper's bones (thin rods), kept for the paper's tables.
    Skeletal,
}

impl HumanLook {
    /// Both looks, flesh first.
    pub const ALL: [HumanLook; 2] = [HumanLook::Flesh, HumanLook::Skeletal];

    /// Lower-case name as in files.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            HumanLook::Flesh => "flesh",
            HumanLook::Skeletal => "skeletal",
        }
    }

    /// Whether a visual named `name` is drawn in this look.
    #[must_use]
    pub fn shows(self, name: Option<&str>) -> bool {
        let name = name.unwrap_or("");
        match self {
            HumanLook::Flesh => !name.starts_with("bone/"),
            HumanLook::Skeletal => !name.starts_with("flesh/"),
        }
    }

    /// What a flesh visual is dressed in: the second part of its name, `skin`, `sleeve`,
    /// `shirt` or `forearm` (bare or long-sleeved) (`flesh/sleeve/upper_arm`), else `None`.
    #[must_use]
    pub fn role(name: Option<&str>) -> Option<&str> {
        name?.strip_prefix("flesh/")?.split('/').next()
    }
}

impl std::fmt::Display for HumanLook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for HumanLook {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        HumanLook::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| format!("unknown look {s:?} (flesh or skeletal)"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_through_text_and_serde() {
        for part in HumanPart::ALL {
            assert_eq!(part.name().parse::<HumanPart>(), Ok(part));
            let json = format!("\"{}\"", part.name());
            assert_eq!(serde_json::to_string(&part).unwrap(), json);
            assert_eq!(serde_json::from_str::<HumanPart>(&json).unwrap(), part);
        }
        assert_eq!(
            HumanPart::of_link_name("shoulder"),
            Some(HumanPart::UpperArm)
        );
        assert_eq!(
            HumanPart::of_link_name("left_shoulder"),
            Some(HumanPart::LeftUpperArm)
        );
        assert_eq!(HumanPart::of_link_name("pelvis"), None);
        for (right, left) in HumanPart::ARM.into_iter().zip(HumanPart::LEFT_ARM) {
            assert_eq!(right.mirrored(), left);
            assert_eq!(left.mirrored(), right);
            assert_eq!(left.limb(), right);
            assert_eq!(left.name(), format!("left_{}", right.name()));
            assert_eq!(
                (right.side(), left.side()),
                (Some(Side::Right), Some(Side::Left))
            );
        }
        for part in [HumanPart::Torso, HumanPart::Head] {
            assert_eq!(
                (part.side(), part.mirrored(), part.limb()),
                (None, part, part)
            );
        }
        assert!("elbow".parse::<HumanPart>().is_err());
    }

    #[test]
    fn looks_split_named_visuals_and_share_the_rest() {
        let (flesh, bone) = (Some("flesh/skin/forearm"), Some("bone/forearm"));
        assert!(HumanLook::Flesh.shows(flesh) && !HumanLook::Flesh.shows(bone));
        assert!(HumanLook::Skeletal.shows(bone) && !HumanLook::Skeletal.shows(flesh));
        for look in HumanLook::ALL {
            assert!(look.shows(None) && look.shows(Some("visor")));
            assert_eq!(look.name().parse::<HumanLook>(), Ok(look));
        }
        assert_eq!(HumanLook::role(flesh), Some("skin"));
        assert_eq!(HumanLook::role(bone), None);
        assert_eq!(HumanLook::default(), HumanLook::Flesh);
    }
}

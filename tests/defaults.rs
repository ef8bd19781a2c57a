//! Every default is written once, in its `impl Default`, and the docs that state it are held
//! to it: where a field's doc comment says `Default V`, V is what the type's `Default` holds
//! (as its TOML, the form a user writes). A default changed in code without its doc, or the
//! other way round, fails here.

use std::path::PathBuf;

use serde::Serialize;
use workcell::evaluate::{
    ControllerConfig, EvaluationConfig, GroundTruthConfig, NoisyConfig, ProcNetConfig,
};
use workcell::perception::pose::{ArmFitConfig, PoseConfig};
use workcell::safety::{FilterConfig, SsmConfig};
use workcell::sim::Scenario;
use workcell::sim::ik::IkOptions;
use workcell::sim::scenario::{CameraConfig, HumanConfig, RobotConfig, RobotMotionConfig};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn table_of<T: Serialize>(value: &T) -> toml::Table {
    toml::Table::try_from(value).expect("a default serialises to TOML")
}

/// The `(field, stated default)` pairs of struct `name` in `source`: the token after
/// `Default ` in the doc comment right above each `pub field:` line (a number, `true`,
/// `false`, `inf`, `empty` or a backticked value; phrases such as `Default: the cell's` state
/// no value and are skipped).
fn stated_defaults(source: &str, name: &str) -> Vec<(String, String)> {
    // A struct, or a struct-like variant of an enum (`Enum::Variant`), whose fields have no
    // `pub`.
    let header = match name.split_once("::") {
        Some((_, variant)) => format!("\n    {variant} {{"),
        None => format!("pub struct {name} {{"),
    };
    let start = source
        .find(&header)
        .unwrap_or_else(|| panic!("no struct {name}"));
    let mut out = Vec::new();
    let mut doc = String::new();
    for line in source[start..]
        .lines()
        .skip(if header.starts_with('\n') { 2 } else { 1 })
    {
        let t = line.trim();
        if t == "}" || t == "}," {
            break;
        }
        if let Some(d) = t.strip_prefix("///") {
            doc.push(' ');
            doc.push_str(d.trim());
            continue;
        }
        if t.starts_with("#[") {
            continue;
        }
        if let Some(rest) = t.strip_prefix("pub ").or_else(|| {
            name.contains("::")
                .then_some(t)
                .filter(|t| t.contains(": "))
        }) {
            let field = rest
                .split(':')
                .next()
                .unwrap_or_default()
                .trim()
                .to_string();
            if let Some(token) = default_token(&doc) {
                out.push((field, token));
            }
        }
        doc.clear();
    }
    out
}

/// The value a doc states after its last `Default ` (see [`stated_defaults`]).
fn default_token(doc: &str) -> Option<String> {
    let at = doc.rfind("Default ")?;
    let rest = &doc[at + "Default ".len()..];
    if let Some(quoted) = rest.strip_prefix('`') {
        return quoted.split('`').next().map(str::to_string);
    }
    let word: String = rest
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '+'))
        .collect();
    let word = word.trim_end_matches('.').to_string();
    let is_number = word.parse::<f64>().is_ok();
    (is_number || matches!(word.as_str(), "true" | "false" | "inf" | "empty")).then_some(word)
}

/// Whether the stated `token` is the TOML `value`.
fn agrees(token: &str, value: &toml::Value) -> bool {
    let number = |v: &toml::Value| match v {
        toml::Value::Float(x) => Some(*x),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    };
    match value {
        toml::Value::Boolean(b) => token == b.to_string(),
        toml::Value::String(s) => token == s || (token == "empty" && s.is_empty()),
        // "Default 0" of an array: every element.
        toml::Value::Array(items) if token.parse::<f64>().is_ok() => items
            .iter()
            .all(|x| number(x).is_some_and(|x| token.parse::<f64>().is_ok_and(|t| x == t))),
        toml::Value::Array(_) => toml::from_str::<toml::Table>(&format!("v = {token}"))
            .ok()
            .and_then(|t| t.get("v").cloned())
            .is_some_and(|stated| {
                let (toml::Value::Array(a), toml::Value::Array(b)) = (&stated, value) else {
                    return false;
                };
                a.len() == b.len()
                    && a.iter().zip(b).all(|(x, y)| match (number(x), number(y)) {
                        (Some(x), Some(y)) => (x - y).abs() <= 1e-12 * y.abs().max(1.0),
                        _ => x == y,
                    })
            }),
        v => match (
            number(v),
            if token == "inf" {
                Some(f64::INFINITY)
            } else {
                token.parse::<f64>().ok()
            },
        ) {
            (Some(x), Some(y)) => x == y || (x - y).abs() <= 1e-12 * y.abs().max(1.0),
            _ => false,
        },
    }
}

#[test]
fn every_stated_default_is_the_one_in_code() {
    let cases: Vec<(&str, &str, toml::Table)> = vec![
        (
            "src/evaluate/mod.rs",
            "EvaluationConfig",
            table_of(&EvaluationConfig::default()),
        ),
        (
            "src/evaluate/perception/config.rs",
            "GroundTruthConfig",
            table_of(&GroundTruthConfig::default()),
        ),
        (
            "src/evaluate/perception/config.rs",
            "NoisyConfig",
            table_of(&NoisyConfig::default()),
        ),
        (
            "src/evaluate/perception/config.rs",
            "ProcNetConfig",
            table_of(&ProcNetConfig::default()),
        ),
        (
            "src/evaluate/controller.rs",
            "ControllerConfig",
            table_of(&ControllerConfig::default()),
        ),
        (
            "safety/src/filter.rs",
            "FilterConfig",
            table_of(&FilterConfig::default()),
        ),
        (
            "safety/src/iso.rs",
            "SsmConfig",
            table_of(&SsmConfig::default()),
        ),
        (
            "sim/src/scenario.rs",
            "Scenario",
            table_of(&Scenario::default()),
        ),
        (
            "sim/src/scenario.rs",
            "RobotConfig",
            table_of(&RobotConfig::default()),
        ),
        (
            "sim/src/scenario.rs",
            "HumanConfig",
            table_of(&HumanConfig::default()),
        ),
        (
            "sim/src/scenario.rs",
            "CameraConfig",
            table_of(&CameraConfig::default()),
        ),
        (
            "perception/src/pose/articulated/config.rs",
            "ArmFitConfig",
            table_of(&ArmFitConfig::default()),
        ),
        (
            "perception/src/pose/config.rs",
            "PoseConfig",
            table_of(&PoseConfig::default()),
        ),
        (
            "sim/src/ik.rs",
            "IkOptions",
            table_of(&IkOptions::default()),
        ),
        (
            "sim/src/scenario.rs",
            "RobotMotionConfig::Random",
            table_of(&RobotMotionConfig::default()),
        ),
        (
            "sim/src/scenario.rs",
            "RobotMotionConfig::PickAndPlace",
            table_of(
                &toml::from_str::<RobotMotionConfig>("kind = \"pick_and_place\"\nwaypoints = []\n")
                    .expect("a pick and place with its defaults"),
            ),
        ),
    ];
    let mut wrong = Vec::new();
    let mut checked = 0;
    for (file, name, defaults) in &cases {
        let source = std::fs::read_to_string(root().join(file)).expect("source");
        for (field, token) in stated_defaults(&source, name) {
            checked += 1;
            match defaults.get(&field) {
                Some(value) if agrees(&token, value) => {}
                Some(value) => wrong.push(format!(
                    "{file}: {name}::{field}: the doc says {token}, the code has {value}"
                )),
                None => wrong.push(format!(
                    "{file}: {name}::{field}: the doc says {token}, the code has none"
                )),
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "docs that state another default:\n{}",
        wrong.join("\n")
    );
    // The parser found the docs (a change of their form would otherwise pass silently).
    assert!(checked >= 80, "only {checked} stated defaults found");
    eprintln!("{checked} stated defaults agree with the code");
}

/// The checker itself: it reads the forms the docs use, and a wrong one is caught.
#[test]
fn the_default_check_reads_the_docs_forms_and_catches_a_wrong_one() {
    let source = r#"
pub struct Demo {
    /// Rate, Hz. Default 30.
    pub rate_hz: f64,
    /// A file. Default `default.toml`.
    #[serde(default)]
    pub cell: String,
    /// Where. Default `[0, 0, -9.81]`.
    pub gravity: [f64; 3],
    /// Off. Default inf (off).
    pub yield_after_s: f64,
    /// Stated by a phrase. Default: the cell's.
    pub speed: Option<f64>,
    /// Clutter. Default false: it costs.
    pub bound: bool,
}
"#;
    let stated = stated_defaults(source, "Demo");
    let fields: Vec<&str> = stated.iter().map(|(f, _)| f.as_str()).collect();
    assert_eq!(
        fields,
        ["rate_hz", "cell", "gravity", "yield_after_s", "bound"]
    );
    let table: toml::Table = toml::from_str(
        "rate_hz = 30.0\ncell = \"default.toml\"\ngravity = [0.0, 0.0, -9.81]\nyield_after_s = inf\nbound = false\n",
    )
    .expect("toml");
    for (field, token) in &stated {
        assert!(agrees(token, &table[field]), "{field}: {token}");
    }
    assert!(!agrees("31", &table["rate_hz"]));
    assert!(!agrees("[0, 0, -9.8]", &table["gravity"]));
    assert!(!agrees("true", &table["bound"]));
    // A struct-like variant of an enum: its fields have no `pub`, and its closing `},` ends
    // it before the next variant's fields.
    let source = r#"
pub enum Motion {
    Random {
        /// Scale. Default 0.5.
        #[serde(default = "half")]
        speed_scale: f64,
    },
    Other {
        /// Dwell. Default 0.3.
        dwell_s: f64,
    },
}
"#;
    assert_eq!(
        stated_defaults(source, "Motion::Random"),
        [("speed_scale".to_string(), "0.5".to_string())]
    );
    assert_eq!(
        stated_defaults(source, "Motion::Other"),
        [("dwell_s".to_string(), "0.3".to_string())]
    );
}

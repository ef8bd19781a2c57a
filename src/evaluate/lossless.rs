//! Floats that survive JSON exactly, NaN and infinities included.
//!
//! A run record (`run.json`) must give back the very values the report was made of, so that
//! shards merged later reproduce a single run's report bit for bit. `serde_json` writes
//! finite floats so that they parse back to the same bits (feature `float_roundtrip`), but
//! writes NaN and infinities as `null`, which does not parse back into `f64`. These helpers
//! write the non-finite values as the strings `"NaN"`, `"inf"` and `"-inf"` instead
//! (`#[serde(with = "lossless::f64")]` and friends).

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A float as JSON writes it: a number when finite, else a name.
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum Repr {
    Number(f64),
    Name(String),
}

fn to_repr(v: f64) -> Repr {
    if v.is_finite() {
        Repr::Number(v)
    } else if v.is_nan() {
        Repr::Name("NaN".into())
    } else if v > 0.0 {
        Repr::Name("inf".into())
    } else {
        Repr::Name("-inf".into())
    }
}

fn from_repr<E: serde::de::Error>(r: Repr) -> Result<f64, E> {
    match r {
        Repr::Number(v) => Ok(v),
        Repr::Name(name) => match name.as_str() {
            "NaN" => Ok(f64::NAN),
            "inf" => Ok(f64::INFINITY),
            "-inf" => Ok(f64::NEG_INFINITY),
            other => Err(E::custom(format!(
                "expected a number, \"NaN\", \"inf\" or \"-inf\", got {other:?}"
            ))),
        },
    }
}

/// One float.
pub mod f64 {
    use super::*;

    /// # Errors
    /// The serializer's.
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        to_repr(*v).serialize(s)
    }

    /// # Errors
    /// Neither a number nor one of the names.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        from_repr(Repr::deserialize(d)?)
    }
}

/// A list of floats.
pub mod vec {
    use super::*;

    /// # Errors
    /// The serializer's.
    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|&x| to_repr(x)))
    }

    /// # Errors
    /// An element that is neither a number nor one of the names.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        Vec::<Repr>::deserialize(d)?
            .into_iter()
            .map(from_repr)
            .collect()
    }
}

/// A list of optional floats (`null` for `None`).
pub mod vec_option {
    use super::*;

    /// # Errors
    /// The serializer's.
    pub fn serialize<S: Serializer>(v: &[Option<f64>], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|x| x.map(to_repr)))
    }

    /// # Errors
    /// An element that is neither `null`, a number nor one of the names.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Option<f64>>, D::Error> {
        Vec::<Option<Repr>>::deserialize(d)?
            .into_iter()
            .map(|x| x.map(from_repr).transpose())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, Serialize, Deserialize)]
    struct Sample {
        #[serde(with = "super::f64")]
        one: f64,
        #[serde(with = "super::vec")]
        many: Vec<f64>,
        #[serde(with = "super::vec_option")]
        gaps: Vec<Option<f64>>,
    }

    /// Every bit pattern class comes back: subnormals, the extremes, signed zero, NaN and
    /// both infinities, and values whose shortest decimal form needs 17 digits.
    #[test]
    fn every_float_comes_back_with_its_bits() {
        let values = vec![
            0.1 + 0.2,
            -0.0,
            f64::MIN_POSITIVE / 3.0,
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1.0 / 3.0,
        ];
        for &v in &values {
            let sample = Sample {
                one: v,
                many: values.clone(),
                gaps: vec![None, Some(v), None],
            };
            let json = serde_json::to_string(&sample).expect("serialise");
            let back: Sample = serde_json::from_str(&json).expect("parse");
            assert_eq!(back.one.to_bits(), v.to_bits(), "{json}");
            for (a, b) in back.many.iter().zip(&values) {
                // NaN's payload is not kept, only that it is NaN.
                assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
            }
            assert_eq!(back.gaps.len(), 3);
            assert!(back.gaps[0].is_none() && back.gaps[2].is_none());
            let g = back.gaps[1].expect("some");
            assert!(g.to_bits() == v.to_bits() || (g.is_nan() && v.is_nan()));
        }
        let bad = r#"{"one": "many", "many": [], "gaps": []}"#;
        let err = serde_json::from_str::<Sample>(bad).expect_err("not a float");
        assert!(err.to_string().contains("got \"many\""), "{err}");
    }
}

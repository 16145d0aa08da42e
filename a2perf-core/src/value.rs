//! Dynamically typed configuration values and typed parameter specifications.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

/// A configuration value (the data model of RON experiment files).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Value {
    /// `None` / unit: "not set".
    Null,
    /// `true` / `false`.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A floating-point number.
    Float(f64),
    /// A string.
    Str(String),
    /// A list.
    List(Vec<Value>),
    /// A map with string keys (RON structs and maps).
    Map(BTreeMap<String, Value>),
}

impl Value {
    /// Parses a command-line literal: `true`/`false`, `None`, integers, floats, quoted strings,
    /// `[a, b]` lists of those; anything else is taken as a bare string.
    ///
    /// ```
    /// use a2perf_core::Value;
    /// assert_eq!(Value::parse_literal("3"), Value::Int(3));
    /// assert_eq!(Value::parse_literal("1e-4"), Value::Float(1e-4));
    /// assert_eq!(Value::parse_literal("simulated"), Value::Str("simulated".into()));
    /// assert_eq!(Value::parse_literal("\"a b\""), Value::Str("a b".into()));
    /// assert_eq!(Value::parse_literal("[1, 2.5]"), Value::List(vec![Value::Int(1), Value::Float(2.5)]));
    /// ```
    pub fn parse_literal(text: &str) -> Value {
        let t = text.trim();
        match t {
            "true" => return Value::Bool(true),
            "false" => return Value::Bool(false),
            "None" | "none" | "()" => return Value::Null,
            _ => {}
        }
        if let Ok(i) = t.parse::<i64>() {
            return Value::Int(i);
        }
        if t.chars()
            .next()
            .is_some_and(|c| c.is_ascii_digit() || c == '-' || c == '+' || c == '.')
            && let Ok(f) = t.parse::<f64>()
        {
            return Value::Float(f);
        }
        if t.len() >= 2 && t.starts_with('"') && t.ends_with('"') {
            return Value::Str(
                t[1..t.len() - 1]
                    .replace("\\\"", "\"")
                    .replace("\\\\", "\\"),
            );
        }
        if t.starts_with('[') && t.ends_with(']') {
            let inner = t[1..t.len() - 1].trim();
            if inner.is_empty() {
                return Value::List(Vec::new());
            }
            return Value::List(inner.split(',').map(Value::parse_literal).collect());
        }
        Value::Str(t.to_string())
    }

    /// The type's name as used in error messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Null => "none",
            Value::Bool(_) => "bool",
            Value::Int(_) => "integer",
            Value::Float(_) => "float",
            Value::Str(_) => "string",
            Value::List(_) => "list",
            Value::Map(_) => "map",
        }
    }

    /// The value as `f64` (integers convert).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Int(i) => Some(*i as f64),
            Value::Float(f) => Some(*f),
            _ => None,
        }
    }

    /// The value as `i64` (floats with no fractional part convert).
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Value::Int(i) => Some(*i),
            Value::Float(f) if f.fract() == 0.0 && f.abs() < 9.0e15 => Some(*f as i64),
            _ => None,
        }
    }

    /// The value as a string slice.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The value as a bool.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    }
}

impl fmt::Display for Value {
    /// RON-like rendering (used by `config show` and error messages).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Null => write!(f, "None"),
            Value::Bool(b) => write!(f, "{b}"),
            Value::Int(i) => write!(f, "{i}"),
            Value::Float(x) => {
                if x.is_finite() && x.fract() == 0.0 && x.abs() < 1e15 {
                    write!(f, "{x:.1}")
                } else {
                    write!(f, "{x:?}")
                }
            }
            Value::Str(s) => write!(f, "{s:?}"),
            Value::List(items) => {
                write!(f, "[")?;
                for (i, v) in items.iter().enumerate() {
                    if i > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{v}")?;
                }
                write!(f, "]")
            }
            Value::Map(m) => {
                write!(f, "{{")?;
                for (i, (k, v)) in m.iter().enumerate() {
                    if i > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{k:?}: {v}")?;
                }
                write!(f, "}}")
            }
        }
    }
}

/// The type a parameter accepts.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamKind {
    /// `true`/`false`.
    Bool,
    /// An integer (a float with no fractional part is accepted).
    Int,
    /// A number (integers are accepted).
    Float,
    /// Any string.
    Str,
    /// A file or directory path (a string).
    Path,
    /// One of a fixed set of strings.
    Choice(&'static [&'static str]),
    /// A list of numbers.
    FloatList,
    /// A list of integers.
    IntList,
}

impl ParamKind {
    /// Human-readable name for error messages.
    pub fn describe(&self) -> String {
        match self {
            ParamKind::Bool => "bool".into(),
            ParamKind::Int => "integer".into(),
            ParamKind::Float => "float".into(),
            ParamKind::Str => "string".into(),
            ParamKind::Path => "path (string)".into(),
            ParamKind::Choice(c) => format!("one of {}", c.join(", ")),
            ParamKind::FloatList => "list of floats".into(),
            ParamKind::IntList => "list of integers".into(),
        }
    }

    /// Checks `v` against the kind, converting where lossless (int → float). `Null` is accepted
    /// for every kind and means "not set".
    pub fn check(&self, v: &Value) -> Result<Value, String> {
        let wrong = || {
            format!(
                "expected {}, found {} `{v}`",
                self.describe(),
                v.type_name()
            )
        };
        match (self, v) {
            (_, Value::Null) => Ok(Value::Null),
            (ParamKind::Bool, Value::Bool(_)) => Ok(v.clone()),
            (ParamKind::Int, _) => v.as_i64().map(Value::Int).ok_or_else(wrong),
            (ParamKind::Float, _) => v.as_f64().map(Value::Float).ok_or_else(wrong),
            (ParamKind::Str | ParamKind::Path, Value::Str(_)) => Ok(v.clone()),
            (ParamKind::Choice(c), Value::Str(s)) => {
                if c.contains(&s.as_str()) {
                    Ok(v.clone())
                } else {
                    let hint = did_you_mean(s, c.iter().copied())
                        .map(|h| format!(" (did you mean `{h}`?)"))
                        .unwrap_or_default();
                    Err(format!("`{s}` is not {}{hint}", self.describe()))
                }
            }
            (ParamKind::FloatList, Value::List(items)) => items
                .iter()
                .map(|i| i.as_f64().map(Value::Float))
                .collect::<Option<Vec<_>>>()
                .map(Value::List)
                .ok_or_else(wrong),
            (ParamKind::IntList, Value::List(items)) => items
                .iter()
                .map(|i| i.as_i64().map(Value::Int))
                .collect::<Option<Vec<_>>>()
                .map(Value::List)
                .ok_or_else(wrong),
            _ => Err(wrong()),
        }
    }
}

/// A typed, documented parameter with its default.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamSpec {
    /// Name, as written in configs.
    pub name: &'static str,
    /// Accepted type.
    pub kind: ParamKind,
    /// Default (`Value::Null` = unset / optional).
    pub default: Value,
    /// One-line documentation.
    pub doc: &'static str,
    /// A setting of the simulator rather than of the task (see [`Self::follows_run`]).
    pub follows_run: bool,
}

impl ParamSpec {
    /// Shorthand constructor.
    pub fn new(name: &'static str, kind: ParamKind, default: Value, doc: &'static str) -> Self {
        Self {
            name,
            kind,
            default,
            doc,
            follows_run: false,
        }
    }

    /// Marks a setting of the simulator rather than of the task (locomotion's physics engine):
    /// a run's generalization tasks take the run's value wherever theirs would differ and the
    /// suite does not set it, so a policy is scored on the engine it was trained on.
    ///
    /// ```
    /// use a2perf_core::{ParamKind, ParamSpec, Value};
    /// let spec = ParamSpec::new("physics", ParamKind::Str, Value::Str("rapier".into()), "engine");
    /// assert!(!spec.follows_run && spec.follows_run().follows_run);
    /// ```
    pub fn follows_run(mut self) -> Self {
        self.follows_run = true;
        self
    }
}

/// Error resolving parameters against their specs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// A key that no spec declares.
    #[error("unknown parameter `{key}`{}", hint.as_ref().map(|h| format!(" (did you mean `{h}`?)")).unwrap_or_default())]
    Unknown {
        /// The key.
        key: String,
        /// Closest known key.
        hint: Option<String>,
    },
    /// A value of the wrong type.
    #[error("parameter `{key}`: {reason}")]
    WrongType {
        /// The key.
        key: String,
        /// What was expected and found.
        reason: String,
    },
    /// A required value is missing or an accessor asked for the wrong type.
    #[error("parameter `{key}`: {reason}")]
    Missing {
        /// The key.
        key: String,
        /// What is missing.
        reason: String,
    },
}

/// Levenshtein distance, for did-you-mean suggestions.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for (i, ca) in a.chars().enumerate() {
        cur[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// The closest candidate to `word`, if it is close enough to be a plausible typo.
///
/// ```
/// use a2perf_core::did_you_mean;
/// assert_eq!(did_you_mean("lerning_rate", ["learning_rate", "seed"]), Some("learning_rate".into()));
/// assert_eq!(did_you_mean("zzz", ["learning_rate"]), None);
/// // A shortened name is recognised too.
/// assert_eq!(did_you_mean("netlist", ["netlist_file", "seed"]), Some("netlist_file".into()));
/// ```
pub fn did_you_mean<'a>(
    word: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<String> {
    let candidates: Vec<&str> = candidates.into_iter().collect();
    let typo = candidates
        .iter()
        .map(|c| (edit_distance(word, c), *c))
        .filter(|(d, c)| *d <= (c.len().max(word.len()) / 3).max(1))
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c.to_string());
    // Otherwise a name that contains the word whole (`netlist` for `netlist_file`); short words
    // would match too much to be a useful hint.
    typo.or_else(|| {
        (word.len() >= 4)
            .then(|| {
                candidates
                    .iter()
                    .filter(|c| c.contains(word))
                    .min_by_key(|c| (c.len(), **c))
                    .map(|c| c.to_string())
            })
            .flatten()
    })
}

/// Parameters resolved against their specs: every declared key present, defaults filled in, types
/// checked.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Params {
    values: BTreeMap<String, Value>,
}

impl Params {
    /// Resolves `given` against `specs`.
    ///
    /// ```
    /// use a2perf_core::{ParamKind, ParamSpec, Params, Value};
    /// let specs = [ParamSpec::new("lr", ParamKind::Float, Value::Float(3e-4), "learning rate")];
    /// let p = Params::resolve(&specs, &Default::default()).unwrap();
    /// assert_eq!(p.f64("lr").unwrap(), 3e-4);
    /// let mut bad = std::collections::BTreeMap::new();
    /// bad.insert("lrr".to_string(), Value::Int(1));
    /// assert!(Params::resolve(&specs, &bad).unwrap_err().to_string().contains("did you mean `lr`"));
    /// ```
    pub fn resolve(
        specs: &[ParamSpec],
        given: &BTreeMap<String, Value>,
    ) -> Result<Self, ParamError> {
        for key in given.keys() {
            if !specs.iter().any(|s| s.name == key) {
                return Err(ParamError::Unknown {
                    key: key.clone(),
                    hint: did_you_mean(key, specs.iter().map(|s| s.name)),
                });
            }
        }
        let mut values = BTreeMap::new();
        for spec in specs {
            let v = given.get(spec.name).unwrap_or(&spec.default);
            let v = spec.kind.check(v).map_err(|reason| ParamError::WrongType {
                key: spec.name.to_string(),
                reason,
            })?;
            values.insert(spec.name.to_string(), v);
        }
        Ok(Self { values })
    }

    /// Every value in force, defaults included.
    pub fn values(&self) -> &BTreeMap<String, Value> {
        &self.values
    }

    /// The raw value of `key`.
    pub fn get(&self, key: &str) -> Option<&Value> {
        self.values.get(key).filter(|v| **v != Value::Null)
    }

    fn need(&self, key: &str) -> Result<&Value, ParamError> {
        self.get(key).ok_or_else(|| ParamError::Missing {
            key: key.into(),
            reason: "required but not set".into(),
        })
    }

    fn typed<T>(
        &self,
        key: &str,
        f: impl Fn(&Value) -> Option<T>,
        want: &str,
    ) -> Result<T, ParamError> {
        let v = self.need(key)?;
        f(v).ok_or_else(|| ParamError::WrongType {
            key: key.into(),
            reason: format!("expected {want}, found {} `{v}`", v.type_name()),
        })
    }

    /// A float parameter.
    pub fn f64(&self, key: &str) -> Result<f64, ParamError> {
        self.typed(key, Value::as_f64, "float")
    }

    /// An integer parameter.
    pub fn i64(&self, key: &str) -> Result<i64, ParamError> {
        self.typed(key, Value::as_i64, "integer")
    }

    /// A non-negative integer parameter.
    pub fn usize(&self, key: &str) -> Result<usize, ParamError> {
        self.typed(
            key,
            |v| v.as_i64().and_then(|i| usize::try_from(i).ok()),
            "non-negative integer",
        )
    }

    /// A non-negative integer parameter as `u64`.
    pub fn u64(&self, key: &str) -> Result<u64, ParamError> {
        self.typed(
            key,
            |v| v.as_i64().and_then(|i| u64::try_from(i).ok()),
            "non-negative integer",
        )
    }

    /// A bool parameter.
    pub fn bool(&self, key: &str) -> Result<bool, ParamError> {
        self.typed(key, Value::as_bool, "bool")
    }

    /// A string parameter.
    pub fn str(&self, key: &str) -> Result<&str, ParamError> {
        let v = self.need(key)?;
        v.as_str().ok_or_else(|| ParamError::WrongType {
            key: key.into(),
            reason: format!("expected string, found {} `{v}`", v.type_name()),
        })
    }

    /// An optional string parameter (`None` when unset).
    pub fn opt_str(&self, key: &str) -> Result<Option<&str>, ParamError> {
        match self.get(key) {
            None => Ok(None),
            Some(_) => self.str(key).map(Some),
        }
    }

    /// A list of floats.
    pub fn f64_list(&self, key: &str) -> Result<Vec<f64>, ParamError> {
        self.typed(
            key,
            |v| match v {
                Value::List(items) => items.iter().map(Value::as_f64).collect(),
                _ => None,
            },
            "list of floats",
        )
    }
}

//! Checks shared by the experiment schema and the profile: a struct node's fields, a value
//! against its parameter kind, and the unknown-key error with its did-you-mean.

use super::error::{ConfigError, Location};
use super::syntax::{Field, Node, NodeValue};
use crate::value::{ParamKind, ParamSpec, Value, did_you_mean};

fn known_list<'a>(names: impl Iterator<Item = &'a str>) -> String {
    names
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

pub(super) fn unknown_key<'a>(
    field: &Field,
    prefix: &str,
    known: impl Iterator<Item = &'a str> + Clone,
) -> ConfigError {
    let hint = did_you_mean(&field.key, known.clone());
    ConfigError::UnknownKey {
        location: field.key_location.clone(),
        key: format!("{prefix}{}", field.key),
        known: hint.is_none().then(|| known_list(known)),
        hint,
    }
}

pub(super) fn as_struct<'a>(node: &'a Node, key: &str) -> Result<&'a [Field], ConfigError> {
    match &node.value {
        NodeValue::Struct(fields) => Ok(fields),
        _ => Err(ConfigError::WrongType {
            location: node.location.clone(),
            key: key.to_string(),
            reason: format!(
                "expected a struct `(key: value, ...)`, found {}",
                node.type_name()
            ),
        }),
    }
}

pub(super) fn check_kind(
    spec: &ParamSpec,
    node: &Node,
    key: &str,
    nullable: bool,
) -> Result<Value, ConfigError> {
    let value = node.to_value();
    let wrong = |reason: String| ConfigError::WrongType {
        location: node.location.clone(),
        key: key.to_string(),
        reason,
    };
    if value == Value::Null && !nullable {
        return Err(wrong(format!(
            "expected {}, found none",
            spec.kind.describe()
        )));
    }
    spec.kind.check(&value).map_err(|reason| {
        let quote_hint = matches!(node.location, Location::Override(_))
            && matches!(spec.kind, ParamKind::Str | ParamKind::Path)
            && !matches!(value, Value::Str(_) | Value::Null);
        if quote_hint {
            wrong(format!(
                "{reason} (quote it to pass a string: `{key}='\"{value}\"'`)"
            ))
        } else {
            wrong(reason)
        }
    })
}

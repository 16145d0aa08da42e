//! Environment variables in config strings: `${NAME}` and `${NAME:-default}`.
//!
//! Third-party files (netlists, motion clips, design files) live wherever a user keeps them, and
//! one experiment may name several of them. A string value may therefore start from a variable,
//! `"${A2PERF_PAPER_DATA:-../shared/data}/circuit/toy_macro_stdcell/netlist.pb.txt"`, so that one
//! setting moves them all. Every string value of the merged config is expanded (file values and
//! `--set` values alike; keys never), before the schema checks, so the experiment holds the
//! expanded text: the operative config and `run.json` record the file actually used, never the
//! variable.
//!
//! Rules, as in a POSIX shell where they overlap:
//! - `${NAME}` is the variable's value; an unset variable is an error naming it;
//! - `${NAME:-default}` is the value when the variable is set and not empty, else `default`
//!   (the text up to the closing brace, taken literally);
//! - `$${` is a literal `${`; any other `$` is itself;
//! - `NAME` is a letter or `_` followed by letters, digits or `_`.
//!
//! [`escape`] is the inverse used when the operative config is written, so it loads back to the
//! same values.

use super::error::ConfigError;
use super::syntax::{Node, NodeValue};

/// Expands the references in `text`, looking variables up with `lookup` (`Ok(None)` = unset).
/// The error says what is wrong, naming the variable.
pub(crate) fn expand_vars(
    text: &str,
    lookup: &impl Fn(&str) -> Result<Option<String>, String>,
) -> Result<String, String> {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find('$') {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        if let Some(tail) = after.strip_prefix("${") {
            out.push_str("${");
            rest = tail;
            continue;
        }
        let Some(body_start) = after.strip_prefix('{') else {
            out.push('$');
            rest = after;
            continue;
        };
        let Some(close) = body_start.find('}') else {
            return Err(format!(
                "`${{` without a closing `}}` in `{text}` (write `$${{` for a literal `${{`)"
            ));
        };
        let body = &body_start[..close];
        let (name, default) = match body.split_once(":-") {
            Some((n, d)) => (n, Some(d)),
            None => (body, None),
        };
        if !is_variable_name(name) {
            return Err(format!(
                "`${{{body}}}` in `{text}`: `{name}` is not a variable name (letters, digits and \
                 `_`, not starting with a digit: `${{NAME}}` or `${{NAME:-default}}`)"
            ));
        }
        match (lookup(name)?, default) {
            (Some(v), Some(d)) if v.is_empty() => out.push_str(d),
            (Some(v), _) => out.push_str(&v),
            (None, Some(d)) => out.push_str(d),
            (None, None) => {
                return Err(format!(
                    "environment variable `{name}` is not set (set it, or give a default: \
                     `${{{name}:-DEFAULT}}`)"
                ));
            }
        }
        rest = &body_start[close + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

fn is_variable_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// `text` written so that [`expand_vars`] gives it back unchanged: every `${` becomes `$${`.
///
/// ```text
/// escape("/data/${x}") == "/data/$${x}"
/// ```
pub(crate) fn escape(text: &str) -> std::borrow::Cow<'_, str> {
    if text.contains("${") {
        text.replace("${", "$${").into()
    } else {
        text.into()
    }
}

fn process_env(name: &str) -> Result<Option<String>, String> {
    match std::env::var(name) {
        Ok(v) => Ok(Some(v)),
        Err(std::env::VarError::NotPresent) => Ok(None),
        Err(std::env::VarError::NotUnicode(_)) => {
            Err(format!("environment variable `{name}` is not valid UTF-8"))
        }
    }
}

/// Expands every string value of `tree` from the process environment. An error names the
/// value's place and dotted key.
pub(crate) fn expand_tree(tree: &mut Node) -> Result<(), ConfigError> {
    expand_node(tree, "", &process_env)
}

fn expand_node(
    node: &mut Node,
    key: &str,
    lookup: &impl Fn(&str) -> Result<Option<String>, String>,
) -> Result<(), ConfigError> {
    match &mut node.value {
        NodeValue::Str(text) if text.contains('$') => {
            *text = expand_vars(text, lookup).map_err(|reason| ConfigError::InvalidValue {
                location: node.location.clone(),
                key: if key.is_empty() {
                    "(top level)".into()
                } else {
                    key.to_string()
                },
                reason,
            })?;
        }
        NodeValue::List(items) => {
            for (i, item) in items.iter_mut().enumerate() {
                expand_node(item, &format!("{key}[{i}]"), lookup)?;
            }
        }
        NodeValue::Struct(fields) => {
            for field in fields {
                let path = if key.is_empty() {
                    field.key.clone()
                } else {
                    format!("{key}.{}", field.key)
                };
                expand_node(&mut field.value, &path, lookup)?;
            }
        }
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(vars: &[(&str, &str)], text: &str) -> Result<String, String> {
        expand_vars(text, &|name: &str| {
            Ok(vars
                .iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| v.to_string()))
        })
    }

    #[test]
    fn variables_and_defaults_expand_as_in_a_shell() {
        let vars = [("DATA", "/mnt/d"), ("EMPTY", "")];
        assert_eq!(with(&vars, "${DATA}/x.txt").unwrap(), "/mnt/d/x.txt");
        assert_eq!(with(&vars, "${DATA:-../d}/x").unwrap(), "/mnt/d/x");
        assert_eq!(with(&vars, "${NOPE:-../d}/x").unwrap(), "../d/x");
        // `:-` also replaces an empty value, as in a shell.
        assert_eq!(with(&vars, "${EMPTY:-../d}/x").unwrap(), "../d/x");
        assert_eq!(with(&vars, "a${EMPTY}b").unwrap(), "ab");
        assert_eq!(with(&vars, "${DATA}${DATA}").unwrap(), "/mnt/d/mnt/d");
        assert_eq!(with(&vars, "${NOPE:-}x").unwrap(), "x");
        // A default is literal text, references included.
        assert_eq!(with(&vars, "${NOPE:-${DATA}").unwrap(), "${DATA");
    }

    #[test]
    fn text_without_references_is_unchanged() {
        for t in [
            "",
            "plain/path.txt",
            "a$b",
            "cost$",
            "$ {X}",
            "x{y}",
            "$$",
            "$$x",
        ] {
            assert_eq!(with(&[], t).unwrap(), t, "{t}");
        }
        assert_eq!(with(&[("X", "v")], "$${X}").unwrap(), "${X}");
        assert_eq!(with(&[("X", "v")], "$$${X}").unwrap(), "$${X}");
    }

    #[test]
    fn errors_name_the_variable_or_the_problem() {
        let e = with(&[], "${A2PERF_PAPER_DATA}/x").unwrap_err();
        assert!(e.contains("`A2PERF_PAPER_DATA` is not set"), "{e}");
        assert!(e.contains("${A2PERF_PAPER_DATA:-DEFAULT}"), "{e}");
        let e = with(&[], "${DATA/x").unwrap_err();
        assert!(e.contains("without a closing"), "{e}");
        for bad in ["${}", "${1X}", "${A-B}", "${A B}"] {
            let e = with(&[], bad).unwrap_err();
            assert!(e.contains("is not a variable name"), "{bad}: {e}");
        }
        let e = expand_vars("${X}", &|_: &str| Err("bad bytes".into())).unwrap_err();
        assert_eq!(e, "bad bytes");
    }

    proptest::proptest! {
        #[test]
        fn escaped_text_expands_back_to_itself(t in "[${}a/]{0,24}") {
            // No variable may be looked up: every reference in the escaped text is escaped.
            let back = expand_vars(&escape(&t), &|n: &str| Err(format!("looked up {n}")));
            proptest::prop_assert_eq!(back, Ok(t));
        }

        #[test]
        fn a_defined_variable_is_replaced_by_its_value(prefix in "[a-z/]{0,8}", value in "[^$]{0,12}", suffix in "[a-z/.]{0,8}") {
            let text = format!("{prefix}${{V_1}}{suffix}");
            proptest::prop_assert_eq!(
                with(&[("V_1", &value)], &text).unwrap(),
                format!("{prefix}{value}{suffix}")
            );
        }
    }
}

//! Includes, command-line overrides and the merge rule that stacks them.
//!
//! The merge rule, applied layer by layer (base first):
//! 1. a file's `include`s are loaded (recursively) and merged in the order listed, so a later include
//!    overrides an earlier one; the including file is merged last and overrides all of them;
//! 2. the `--set` overrides form one final layer (in command-line order, later ones win);
//! 3. merging a struct into a struct goes key by key, recursively; anything else (a list, a scalar,
//!    or a struct over a non-struct) replaces the value below it;
//! 4. exception: the top-level `env` and `algorithm` sections are replaced wholesale, not merged,
//!    when the upper layer names a different `id` / `name` than the layer below, because one
//!    environment's parameters (or one algorithm's hyperparameters) mean nothing to another.

use std::path::{Component, Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;

use super::error::{ConfigError, Location};
use super::syntax::{Field, Node, NodeValue, parse_override_value, parse_str};

/// The key naming the variant of a section that is replaced rather than merged when it changes.
fn discriminator(section: &str) -> Option<&'static str> {
    match section {
        "env" => Some("id"),
        "algorithm" => Some("name"),
        _ => None,
    }
}

/// Merges `over` into `base` by the module's rule. `top` is true for the experiment's top level.
pub(crate) fn merge(base: &mut Node, over: Node, top: bool) {
    let Node {
        value: over_value,
        location: over_location,
    } = over;
    match (&mut base.value, over_value) {
        (NodeValue::Struct(base_fields), NodeValue::Struct(over_fields)) => {
            for field in over_fields {
                match base_fields.iter_mut().find(|b| b.key == field.key) {
                    Some(existing) => {
                        if top && switches_variant(&field.key, &existing.value, &field.value) {
                            *existing = field;
                        } else {
                            merge(&mut existing.value, field.value, false);
                        }
                    }
                    None => base_fields.push(field),
                }
            }
        }
        (_, value) => {
            *base = Node::new(value, over_location);
        }
    }
}

fn switches_variant(section: &str, base: &Node, over: &Node) -> bool {
    let Some(key) = discriminator(section) else {
        return false;
    };
    match (base.field(key), over.field(key)) {
        (Some(b), Some(o)) => b.value.to_value() != o.value.to_value(),
        _ => false,
    }
}

/// A `--set dotted.path=value` override.
///
/// The value is a RON literal (`1e-4`, `true`, `[0, 1]`, `"text"`, `(k: v)`); text that is not
/// valid RON and does not start with a bracket or quote is taken as a bare string, so
/// `--set env.id=WebNavigation-Difficulty-01-v0` needs no quotes.
///
/// ```
/// use a2perf_core::config::Override;
/// let o: Override = "algorithm.learning_rate=1e-4".parse().unwrap();
/// assert_eq!(o.path(), ["algorithm", "learning_rate"]);
/// assert_eq!(o.value(), a2perf_core::Value::Float(1e-4));
/// assert!("=3".parse::<Override>().is_err());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    text: Arc<str>,
    path: Vec<String>,
    node: Node,
}

impl Override {
    /// Parses `dotted.path=value`.
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        let bad = |reason: &str| ConfigError::BadOverride {
            text: text.to_string(),
            reason: reason.to_string(),
        };
        let Some((key, value)) = text.split_once('=') else {
            return Err(bad("expected `dotted.path=value`"));
        };
        let path: Vec<String> = key.trim().split('.').map(str::to_string).collect();
        if path.iter().any(|p| {
            p.is_empty()
                || !p.chars().all(|c| c.is_alphanumeric() || c == '_')
                || p.starts_with(|c: char| c.is_ascii_digit())
        }) {
            return Err(bad(
                "the key must be a dotted path of identifiers, e.g. `algorithm.learning_rate`",
            ));
        }
        if path[0] == "include" {
            return Err(bad(
                "`include` can only be used in files (pass the file itself instead)",
            ));
        }
        let value = value.trim();
        if value.is_empty() {
            return Err(bad("missing value (write `key=\"\"` for an empty string)"));
        }
        let whole: Arc<str> = Arc::from(text);
        let node = match parse_override_value(value, &whole) {
            Ok(node) => node,
            Err(err) if value.starts_with(['[', '(', '{', '"']) => return Err(err),
            Err(_) => Node::new(
                NodeValue::Str(value.to_string()),
                Location::Override(Arc::clone(&whole)),
            ),
        };
        Ok(Self {
            text: whole,
            path,
            node,
        })
    }

    /// The override as written.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The dotted path, split.
    pub fn path(&self) -> &[String] {
        &self.path
    }

    /// The value, locations dropped.
    pub fn value(&self) -> crate::Value {
        self.node.to_value()
    }

    /// The override as a one-key-per-level struct tree.
    fn to_tree(&self) -> Node {
        let location = Location::Override(Arc::clone(&self.text));
        let mut node = self.node.clone();
        for key in self.path.iter().rev() {
            node = Node::new(
                NodeValue::Struct(vec![Field {
                    key: key.clone(),
                    key_location: location.clone(),
                    value: node,
                }]),
                location.clone(),
            );
        }
        node
    }
}

impl FromStr for Override {
    type Err = ConfigError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::parse(s)
    }
}

/// Applies `overrides` (later ones win) as the last layer on `tree`.
pub(crate) fn apply_overrides(tree: &mut Node, overrides: &[Override]) {
    let mut layer = Node::new(NodeValue::Struct(Vec::new()), Location::Default);
    for o in overrides {
        merge(&mut layer, o.to_tree(), true);
    }
    merge(tree, layer, true);
}

/// Drops `.` and resolves `..` lexically, so include chains print readably. Cycle detection uses
/// canonical paths instead.
fn tidy(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if matches!(out.components().next_back(), Some(Component::Normal(_))) {
                    out.pop();
                } else {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}

struct Stack {
    /// (canonical path, path as displayed), outermost first.
    files: Vec<(PathBuf, PathBuf)>,
}

impl Stack {
    fn chain_with(&self, last: &Path) -> Vec<PathBuf> {
        self.files
            .iter()
            .map(|(_, shown)| shown.clone())
            .chain(std::iter::once(last.to_path_buf()))
            .collect()
    }
}

/// Loads `path` with its includes merged in (no overrides, no validation).
pub(crate) fn load_file_tree(path: &Path) -> Result<Node, ConfigError> {
    let mut stack = Stack { files: Vec::new() };
    load_file(&tidy(path), None, &mut stack)
}

/// Parses `text` as if it were the file `path` (includes resolve relative to it).
pub(crate) fn load_text_tree(text: &str, path: &Path) -> Result<Node, ConfigError> {
    let shown = tidy(path);
    let mut stack = Stack {
        files: vec![(
            std::fs::canonicalize(&shown).unwrap_or_else(|_| shown.clone()),
            shown.clone(),
        )],
    };
    let node = parse_str(text, &shown)?;
    expand_includes(node, &shown, &mut stack)
}

fn load_file(
    shown: &Path,
    included_at: Option<Location>,
    stack: &mut Stack,
) -> Result<Node, ConfigError> {
    let read_error = |source, stack: &Stack| ConfigError::Read {
        path: shown.to_path_buf(),
        included_at: included_at.clone(),
        chain: stack.chain_with(shown),
        source,
    };
    let canonical = std::fs::canonicalize(shown).map_err(|e| read_error(e, stack))?;
    if stack.files.iter().any(|(c, _)| *c == canonical) {
        return Err(ConfigError::IncludeCycle {
            location: included_at.clone().unwrap_or(Location::Default),
            chain: stack.chain_with(shown),
        });
    }
    let text = std::fs::read_to_string(shown).map_err(|e| read_error(e, stack))?;
    let node = parse_str(&text, shown)?;
    stack.files.push((canonical, shown.to_path_buf()));
    let result = expand_includes(node, shown, stack);
    stack.files.pop();
    result
}

/// Takes the `include` list out of a file's top-level struct, loads and merges the includes, then
/// merges the file itself on top.
fn expand_includes(mut node: Node, shown: &Path, stack: &mut Stack) -> Result<Node, ConfigError> {
    let NodeValue::Struct(fields) = &mut node.value else {
        return Err(ConfigError::WrongType {
            location: node.location.clone(),
            key: "(top level)".into(),
            reason: format!(
                "an experiment file is a struct `(key: value, ...)`, found {}",
                node.type_name()
            ),
        });
    };
    let Some(index) = fields.iter().position(|f| f.key == "include") else {
        return Ok(node);
    };
    let include = fields.remove(index);
    let wrong = |location: &Location, found: &str| ConfigError::WrongType {
        location: location.clone(),
        key: "include".into(),
        reason: format!(
            "expected a list of file paths, e.g. `include: [\"../base.ron\"]`, found {found}"
        ),
    };
    let NodeValue::List(items) = include.value.value else {
        return Err(wrong(&include.value.location, include.value.type_name()));
    };
    let folder = shown.parent().unwrap_or(Path::new(""));
    let mut merged: Option<Node> = None;
    for item in items {
        let NodeValue::Str(relative) = &item.value else {
            return Err(wrong(
                &item.location,
                &format!("a {} item", item.type_name()),
            ));
        };
        let target = tidy(&folder.join(relative));
        let loaded = load_file(&target, Some(item.location.clone()), stack)?;
        match &mut merged {
            None => merged = Some(loaded),
            Some(base) => merge(base, loaded, true),
        }
    }
    Ok(match merged {
        None => node,
        Some(mut base) => {
            merge(&mut base, node, true);
            base
        }
    })
}

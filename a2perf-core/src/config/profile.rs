//! Profiles (named sets of environment switches and generalization suites per domain) and
//! generalization task lists, as written in experiment configs.
//!
//! A profile lets one file (say `configs/paper/profile.ron`, included by every paper config)
//! switch every domain to another set of semantics: its `env` entries give parameter values per
//! domain (or per environment id), applied to any parameter the config layers leave unset, and
//! its `generalization` entries give the suite of each domain.

use std::collections::{BTreeMap, BTreeSet};

use super::error::ConfigError;
use super::schema::{as_struct, check_kind, unknown_key};
use super::syntax::{Field, Node, NodeValue};
use crate::registry::{EnvEntry, Registry, TaskRef};
use crate::value::{ParamSpec, Value, did_you_mean};

/// A named profile: environment switches and generalization suites per domain.
///
/// ```
/// use a2perf_core::{Registry, config};
/// let exp = config::load_str(r#"(profile: "mine")"#, "exp.ron".as_ref(), &[], &Registry::new()).unwrap();
/// let profile = exp.profile.unwrap();
/// assert_eq!(profile.name, "mine");
/// assert!(profile.env.is_empty() && profile.generalization.is_empty());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Profile {
    /// Name, recorded with every run (e.g. `a2perf`).
    pub name: String,
    /// Switches per domain (`web_navigation`) or environment id: parameter name → value, as
    /// written. A domain's switches apply to every environment of the domain that declares the
    /// parameter; an id's switches apply to that environment and override its domain's.
    pub env: BTreeMap<String, BTreeMap<String, Value>>,
    /// Generalization suite per domain.
    pub generalization: BTreeMap<String, Vec<TaskRef>>,
}

impl Profile {
    /// The switches that apply to the environment `entry`: its domain's switches that it
    /// declares, then its id's, each converted to the parameter's kind (`1` → `1.0` for a float).
    pub fn switches_for(&self, entry: &EnvEntry) -> BTreeMap<String, Value> {
        let mut out = BTreeMap::new();
        for key in [&entry.domain, &entry.id] {
            let Some(switches) = self.env.get(key) else {
                continue;
            };
            for (param, value) in switches {
                if let Some(spec) = entry.params.iter().find(|s| s.name == param)
                    && let Ok(v) = spec.kind.check(value)
                {
                    out.insert(param.clone(), v);
                }
            }
        }
        out
    }

    /// `task` with this profile's switches for its environment filled into the parameters it
    /// does not set (so a suite runs under the same semantics as the training task).
    pub fn apply_to_task(&self, task: &TaskRef, registry: &Registry) -> TaskRef {
        let mut out = task.clone();
        if let Ok(entry) = registry.env(&task.env_id) {
            for (k, v) in self.switches_for(entry) {
                out.params.entry(k).or_insert(v);
            }
        }
        out
    }

    /// The profile's fields in the form the config accepts, empty ones left out (for the
    /// operative config).
    pub(crate) fn fields(&self) -> Vec<(String, Value)> {
        let mut out = vec![("name".to_string(), Value::Str(self.name.clone()))];
        if !self.env.is_empty() {
            let env = self
                .env
                .iter()
                .map(|(k, switches)| (k.clone(), Value::Map(switches.clone())))
                .collect();
            out.push(("env".to_string(), Value::Map(env)));
        }
        if !self.generalization.is_empty() {
            let suites = self
                .generalization
                .iter()
                .map(|(domain, tasks)| (domain.clone(), tasks_to_value(tasks)))
                .collect();
            out.push(("generalization".to_string(), Value::Map(suites)));
        }
        out
    }
}

/// A task list as the config accepts it: `[{"env": ..., "name": ..., "params": {...}}, ...]`.
pub(crate) fn tasks_to_value(tasks: &[TaskRef]) -> Value {
    Value::List(
        tasks
            .iter()
            .map(|t| {
                Value::Map(
                    [
                        ("env".to_string(), Value::Str(t.env_id.clone())),
                        ("name".to_string(), Value::Str(t.name.clone())),
                        ("params".to_string(), Value::Map(t.params.clone())),
                    ]
                    .into(),
                )
            })
            .collect(),
    )
}

fn domains(registry: &Registry) -> BTreeSet<&str> {
    registry.envs().map(|e| e.domain.as_str()).collect()
}

fn wrong_type(node: &Node, key: &str, expected: &str) -> ConfigError {
    ConfigError::WrongType {
        location: node.location.clone(),
        key: key.to_string(),
        reason: format!("expected {expected}, found {}", node.type_name()),
    }
}

fn non_empty_string(node: &Node, key: &str) -> Result<String, ConfigError> {
    match &node.value {
        NodeValue::Str(s) if !s.trim().is_empty() => Ok(s.clone()),
        NodeValue::Str(_) => Err(ConfigError::InvalidValue {
            location: node.location.clone(),
            key: key.to_string(),
            reason: "must not be empty".into(),
        }),
        _ => Err(wrong_type(node, key, "string")),
    }
}

/// Parses the top-level `profile` value: `None`, a name (`"a2perf"`), or
/// `(name: "...", env: {...}, generalization: {...})`.
pub(crate) fn parse_profile(
    node: &Node,
    registry: &Registry,
) -> Result<Option<Profile>, ConfigError> {
    let fields = match &node.value {
        NodeValue::Null => return Ok(None),
        NodeValue::Str(_) => {
            return Ok(Some(Profile {
                name: non_empty_string(node, "profile")?,
                env: BTreeMap::new(),
                generalization: BTreeMap::new(),
            }));
        }
        NodeValue::Struct(fields) => fields,
        _ => {
            return Err(wrong_type(
                node,
                "profile",
                "a name `\"a2perf\"` or a struct `(name: ..., env: {...}, generalization: {...})`",
            ));
        }
    };
    const KEYS: [&str; 3] = ["name", "env", "generalization"];
    for f in fields {
        if !KEYS.contains(&f.key.as_str()) {
            return Err(unknown_key(f, "profile.", KEYS.iter().copied()));
        }
    }
    let Some(name) = fields.iter().find(|f| f.key == "name") else {
        return Err(ConfigError::MissingKey {
            location: node.location.clone(),
            key: "profile.name".into(),
            reason: "a profile needs a name (recorded with every run)".into(),
        });
    };
    let name = non_empty_string(&name.value, "profile.name")?;
    let mut env = BTreeMap::new();
    if let Some(f) = fields.iter().find(|f| f.key == "env") {
        for entry in as_struct(&f.value, "profile.env")? {
            env.insert(entry.key.clone(), env_switches(entry, registry)?);
        }
    }
    let mut generalization = BTreeMap::new();
    if let Some(f) = fields.iter().find(|f| f.key == "generalization") {
        for entry in as_struct(&f.value, "profile.generalization")? {
            let key = format!("profile.generalization.{}", entry.key);
            let known = domains(registry);
            if !known.contains(entry.key.as_str()) {
                return Err(ConfigError::InvalidValue {
                    location: entry.key_location.clone(),
                    key,
                    reason: format!(
                        "`{}` is not a registered domain{}; domains: {}",
                        entry.key,
                        hint(&entry.key, known.iter().copied()),
                        list(known.iter().copied())
                    ),
                });
            }
            let tasks = parse_tasks(&entry.value, &key, registry, Some(&entry.key))?;
            generalization.insert(entry.key.clone(), tasks);
        }
    }
    Ok(Some(Profile {
        name,
        env,
        generalization,
    }))
}

fn hint<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    did_you_mean(word, candidates)
        .map(|h| format!(" (did you mean `{h}`?)"))
        .unwrap_or_default()
}

fn list<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    let v: Vec<String> = names.into_iter().map(|n| format!("`{n}`")).collect();
    if v.is_empty() {
        "none registered".into()
    } else {
        v.join(", ")
    }
}

/// One `profile.env.<domain or id>` entry: its switches, each checked against the parameter
/// specs of the environments it can apply to.
fn env_switches(
    entry: &Field,
    registry: &Registry,
) -> Result<BTreeMap<String, Value>, ConfigError> {
    let prefix = format!("profile.env.{}.", entry.key);
    let targets: Vec<&EnvEntry> = match registry.env(&entry.key) {
        Ok(e) => vec![e],
        Err(_) => registry.envs().filter(|e| e.domain == entry.key).collect(),
    };
    if targets.is_empty() {
        let known = domains(registry);
        let ids = registry.envs().map(|e| e.id.as_str());
        return Err(ConfigError::InvalidValue {
            location: entry.key_location.clone(),
            key: format!("profile.env.{}", entry.key),
            reason: format!(
                "`{}` is neither a registered domain nor an environment id{}; domains: {}",
                entry.key,
                hint(&entry.key, known.iter().copied().chain(ids)),
                list(known.iter().copied())
            ),
        });
    }
    let mut out = BTreeMap::new();
    for field in as_struct(&entry.value, prefix.trim_end_matches('.'))? {
        let specs: Vec<&ParamSpec> = targets
            .iter()
            .filter_map(|e| e.params.iter().find(|s| s.name == field.key))
            .collect();
        if specs.is_empty() {
            let known: BTreeSet<&str> = targets
                .iter()
                .flat_map(|e| e.params.iter().map(|s| s.name))
                .collect();
            return Err(unknown_key(field, &prefix, known.iter().copied()));
        }
        let key = format!("{prefix}{}", field.key);
        for spec in specs {
            check_kind(spec, &field.value, &key, true)?;
        }
        out.insert(field.key.clone(), field.value.to_value());
    }
    Ok(out)
}

/// Parses a generalization task list: `[(env: "...", params: {...}, name: "..."), ...]`. With
/// `domain`, every task must be an environment of that domain.
pub(crate) fn parse_tasks(
    node: &Node,
    key: &str,
    registry: &Registry,
    domain: Option<&str>,
) -> Result<Vec<TaskRef>, ConfigError> {
    let NodeValue::List(items) = &node.value else {
        return Err(wrong_type(
            node,
            key,
            "a list of tasks `[(env: \"...\", params: {...}, name: \"...\"), ...]`",
        ));
    };
    if items.is_empty() {
        return Err(ConfigError::InvalidValue {
            location: node.location.clone(),
            key: key.to_string(),
            reason: "a generalization suite needs at least one task".into(),
        });
    }
    let mut out: Vec<TaskRef> = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let item_key = format!("{key}[{i}]");
        let task = parse_task(item, &item_key, registry, domain)?;
        if out.iter().any(|t| t.name == task.name) {
            return Err(ConfigError::InvalidValue {
                location: item.location.clone(),
                key: item_key,
                reason: format!(
                    "task name `{}` is listed twice (give the tasks distinct `name`s)",
                    task.name
                ),
            });
        }
        out.push(task);
    }
    Ok(out)
}

fn parse_task(
    node: &Node,
    key: &str,
    registry: &Registry,
    domain: Option<&str>,
) -> Result<TaskRef, ConfigError> {
    const KEYS: [&str; 3] = ["env", "params", "name"];
    let fields = as_struct(node, key)?;
    let prefix = format!("{key}.");
    for f in fields {
        if !KEYS.contains(&f.key.as_str()) {
            return Err(unknown_key(f, &prefix, KEYS.iter().copied()));
        }
    }
    let Some(env_field) = fields.iter().find(|f| f.key == "env") else {
        return Err(ConfigError::MissingKey {
            location: node.location.clone(),
            key: format!("{prefix}env"),
            reason: "a task names a registered environment id".into(),
        });
    };
    let env_key = format!("{prefix}env");
    let env_id = non_empty_string(&env_field.value, &env_key)?;
    let entry = registry
        .env(&env_id)
        .map_err(|e| ConfigError::InvalidValue {
            location: env_field.value.location.clone(),
            key: env_key.clone(),
            reason: format!("{e}; `a2perf list` shows what is registered"),
        })?;
    if let Some(domain) = domain
        && entry.domain != domain
    {
        return Err(ConfigError::InvalidValue {
            location: env_field.value.location.clone(),
            key: env_key,
            reason: format!(
                "`{env_id}` belongs to domain `{}`, not `{domain}`",
                entry.domain
            ),
        });
    }
    let mut params = BTreeMap::new();
    if let Some(f) = fields.iter().find(|f| f.key == "params") {
        let params_key = format!("{prefix}params");
        for p in as_struct(&f.value, &params_key)? {
            let Some(spec) = entry.params.iter().find(|s| s.name == p.key) else {
                return Err(unknown_key(
                    p,
                    &format!("{params_key}."),
                    entry.params.iter().map(|s| s.name),
                ));
            };
            let value = check_kind(spec, &p.value, &format!("{params_key}.{}", p.key), true)?;
            params.insert(p.key.clone(), value);
        }
    }
    let name = match fields.iter().find(|f| f.key == "name") {
        Some(f) => non_empty_string(&f.value, &format!("{prefix}name"))?,
        None => default_task_name(&env_id, &params),
    };
    Ok(TaskRef {
        name,
        env_id,
        params,
    })
}

/// `Id` or `Id[k=v,...]`: what a task without a `name` is called.
fn default_task_name(env_id: &str, params: &BTreeMap<String, Value>) -> String {
    if params.is_empty() {
        env_id.to_string()
    } else {
        let p: Vec<String> = params.iter().map(|(k, v)| format!("{k}={v}")).collect();
        format!("{env_id}[{}]", p.join(","))
    }
}

//! The resolved experiment: the schema every merged config is checked against, and the operative
//! config rendered back to RON.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::error::{ConfigError, Location};
use super::profile::{Profile, parse_profile, parse_tasks, tasks_to_value};
use super::schema::{as_struct, check_kind, unknown_key};
use super::syntax::{Field, Node, NodeValue};
use crate::registry::{Registry, TaskRef};
use crate::training::TrainingSettings;
use crate::value::{ParamKind, ParamSpec, Params, Value};

/// The file name pipelines write the operative config to, next to their results.
pub const OPERATIVE_CONFIG_FILE: &str = "operative_config.ron";

/// The environment an experiment runs on.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvConfig {
    /// Registered id, e.g. `WebNavigation-Difficulty-01-v0`.
    pub id: String,
    /// Every parameter in force, registry defaults filled in.
    pub params: Params,
    /// The switches the experiment's profile gives this environment (parameter → the profile's
    /// value). A switch is in force when `params` holds that value; a config layer that sets the
    /// parameter itself overrides it.
    pub profile_switches: BTreeMap<String, Value>,
}

/// The algorithm an experiment trains.
#[derive(Clone, Debug, PartialEq)]
pub struct AlgorithmConfig {
    /// Registered name, e.g. `ppo`.
    pub name: String,
    /// Every hyperparameter in force, registry defaults filled in.
    pub params: Params,
}

/// Where the inference benchmark takes the observations it times from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObservationSource {
    /// Observations recorded during the rollouts (what a deployed policy sees).
    Rollouts,
    /// Uniform samples of the observation space (what the original A2Perf harness timed).
    Random,
}

/// How energy is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EnergyMethod {
    /// RAPL counters when readable, else the estimate.
    Auto,
    /// RAPL counters only (an error when unavailable).
    Rapl,
    /// Estimated from CPU time and a power model; reports say it is an estimate.
    Estimate,
}

/// Which definitions the reliability metrics follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReliabilityDefinition {
    /// A2Perf's own analysis code (e.g. the upper tail for drawdown risk).
    A2Perf,
    /// The rl-reliability-metrics library of Chan et al. (2019) with its defaults.
    Chan2019,
}

/// Settings of the inference phase.
#[derive(Clone, Debug, PartialEq)]
pub struct InferenceSettings {
    /// Episodes rolled out with the trained policy.
    pub rollouts: usize,
    /// Single-observation inference calls timed.
    pub timing_samples: usize,
    /// Where the timed observations come from.
    pub observation_source: ObservationSource,
}

/// Settings of the generalization phase.
#[derive(Clone, Debug, PartialEq)]
pub struct GeneralizationSettings {
    /// Episodes per generalization task.
    pub episodes: usize,
    /// The suite, when the config lists one (`tasks: [...]`); otherwise the profile's suite for
    /// the domain, else the registry's, is used.
    pub tasks: Option<Vec<TaskRef>>,
}

/// Settings of the system and reliability metrics.
#[derive(Clone, Debug, PartialEq)]
pub struct MetricSettings {
    /// Seconds between RAM samples.
    pub ram_sample_interval_s: f64,
    /// Grid carbon intensity used to turn energy into emissions, in g CO2-eq per kWh.
    pub carbon_intensity_g_per_kwh: f64,
    /// How energy is measured.
    pub energy_method: EnergyMethod,
    /// Which reliability-metric definitions to use.
    pub reliability_definition: ReliabilityDefinition,
    /// Bootstrap resamples for confidence intervals.
    pub bootstrap_reps: usize,
}

/// Where results go.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputSettings {
    /// Results directory (relative paths are relative to the working directory, not the config).
    pub dir: PathBuf,
}

/// A fully resolved experiment: every value in force, defaults included.
///
/// `env` and `algorithm` are optional so that base files can be loaded and shown on their own; a
/// pipeline asks for them with [`Experiment::require_env`] / [`Experiment::require_algorithm`].
#[derive(Clone, Debug, PartialEq)]
pub struct Experiment {
    /// Experiment name (defaults to the file's stem).
    pub name: String,
    /// The profile (`profile: "a2perf"` or `profile: (name: ..., env: ..., generalization: ...)`),
    /// if the config names one.
    pub profile: Option<Profile>,
    /// The environment, if the config names one.
    pub env: Option<EnvConfig>,
    /// The algorithm, if the config names one.
    pub algorithm: Option<AlgorithmConfig>,
    /// Seeds, one run each.
    pub seeds: Vec<u64>,
    /// Training budgets.
    pub training: TrainingSettings,
    /// Inference benchmark settings.
    pub inference: InferenceSettings,
    /// Generalization settings.
    pub generalization: GeneralizationSettings,
    /// Metric settings.
    pub metrics: MetricSettings,
    /// Output settings.
    pub output: OutputSettings,
}

/// Top-level keys, in the order the operative config lists them.
const TOP_KEYS: [&str; 10] = [
    "name",
    "profile",
    "env",
    "algorithm",
    "seeds",
    "training",
    "inference",
    "generalization",
    "metrics",
    "output",
];

/// Sections with fixed keys.
const FIXED_SECTIONS: [&str; 5] = [
    "training",
    "inference",
    "generalization",
    "metrics",
    "output",
];

/// The schema of a fixed section: its keys, types, defaults and docs.
pub fn section_schema(section: &str) -> Option<Vec<ParamSpec>> {
    let t = TrainingSettings::default();
    let int = |v: u64| Value::Int(i64::try_from(v).unwrap_or(i64::MAX));
    Some(match section {
        "training" => vec![
            ParamSpec::new(
                "total_env_steps",
                ParamKind::Int,
                int(t.total_env_steps),
                "environment steps the algorithm may consume",
            ),
            ParamSpec::new(
                "eval_interval",
                ParamKind::Int,
                int(t.eval_interval),
                "evaluate every this many environment steps (0 = only at the end)",
            ),
            ParamSpec::new(
                "eval_episodes",
                ParamKind::Int,
                int(t.eval_episodes as u64),
                "episodes per evaluation",
            ),
            ParamSpec::new(
                "checkpoint_interval",
                ParamKind::Int,
                int(t.checkpoint_interval),
                "checkpoint every this many environment steps (0 = only at the end)",
            ),
            ParamSpec::new(
                "num_envs",
                ParamKind::Int,
                int(t.num_envs as u64),
                "parallel environments",
            ),
        ],
        "inference" => vec![
            ParamSpec::new(
                "rollouts",
                ParamKind::Int,
                Value::Int(100),
                "episodes rolled out with the trained policy",
            ),
            ParamSpec::new(
                "timing_samples",
                ParamKind::Int,
                Value::Int(1000),
                "single-observation inference calls timed",
            ),
            ParamSpec::new(
                "observation_source",
                ParamKind::Choice(&["rollouts", "random"]),
                Value::Str("rollouts".into()),
                "observations timed: recorded in rollouts, or random samples of the space",
            ),
        ],
        "generalization" => vec![ParamSpec::new(
            "episodes",
            ParamKind::Int,
            Value::Int(100),
            "episodes per generalization task",
        )],
        "metrics" => vec![
            ParamSpec::new(
                "ram_sample_interval_s",
                ParamKind::Float,
                Value::Float(1.0),
                "seconds between RAM samples",
            ),
            ParamSpec::new(
                "carbon_intensity_g_per_kwh",
                ParamKind::Float,
                Value::Float(475.0),
                "grid carbon intensity, g CO2-eq per kWh (475 = world average used by CodeCarbon)",
            ),
            ParamSpec::new(
                "energy_method",
                ParamKind::Choice(&["auto", "rapl", "estimate"]),
                Value::Str("auto".into()),
                "energy measurement: RAPL counters, an estimate, or RAPL when readable",
            ),
            ParamSpec::new(
                "reliability_definition",
                ParamKind::Choice(&["a2perf", "chan2019"]),
                Value::Str("a2perf".into()),
                "reliability metric definitions: A2Perf's analysis code or Chan et al. 2019",
            ),
            ParamSpec::new(
                "bootstrap_reps",
                ParamKind::Int,
                Value::Int(50_000),
                "bootstrap resamples for confidence intervals",
            ),
        ],
        "output" => vec![ParamSpec::new(
            "dir",
            ParamKind::Path,
            Value::Str("results".into()),
            "results directory (relative to the working directory)",
        )],
        _ => return None,
    })
}

/// A checked value with where it came from.
struct Checked {
    value: Value,
    location: Location,
}

/// Keys of a fixed section whose values are structured (lists of structs) and checked on their
/// own rather than against [`section_schema`].
fn structured_keys(section: &str) -> &'static [&'static str] {
    match section {
        "generalization" => &["tasks"],
        _ => &[],
    }
}

/// Checks a fixed section against its schema (keys of [`structured_keys`] are left to their own
/// checks); every schema key is present in the result.
fn check_fixed(
    section: &str,
    node: Option<&Node>,
    specs: &[ParamSpec],
) -> Result<BTreeMap<&'static str, Checked>, ConfigError> {
    let mut out = BTreeMap::new();
    let extra = structured_keys(section);
    if let Some(node) = node {
        for field in as_struct(node, section)? {
            let prefix = format!("{section}.");
            if extra.contains(&field.key.as_str()) {
                continue;
            }
            let Some(spec) = specs.iter().find(|s| s.name == field.key) else {
                let known = specs.iter().map(|s| s.name).chain(extra.iter().copied());
                return Err(unknown_key(field, &prefix, known));
            };
            let key = format!("{prefix}{}", field.key);
            let value = check_kind(spec, &field.value, &key, false)?;
            out.insert(
                spec.name,
                Checked {
                    value,
                    location: field.value.location.clone(),
                },
            );
        }
    }
    for spec in specs {
        out.entry(spec.name).or_insert_with(|| Checked {
            value: spec.default.clone(),
            location: Location::Default,
        });
    }
    Ok(out)
}

/// Accessors over a checked section that enforce ranges and name the key on failure.
struct Section<'a> {
    name: &'a str,
    values: BTreeMap<&'static str, Checked>,
}

impl Section<'_> {
    fn invalid(&self, key: &str, reason: String) -> ConfigError {
        ConfigError::InvalidValue {
            location: self
                .values
                .get(key)
                .map_or(Location::Default, |c| c.location.clone()),
            key: format!("{}.{key}", self.name),
            reason,
        }
    }

    fn value(&self, key: &str) -> &Value {
        self.values.get(key).map_or(&Value::Null, |c| &c.value)
    }

    fn count(&self, key: &str, min: u64) -> Result<u64, ConfigError> {
        match self.value(key).as_i64().and_then(|i| u64::try_from(i).ok()) {
            Some(n) if n >= min => Ok(n),
            _ => Err(self.invalid(
                key,
                format!("expected an integer >= {min}, found `{}`", self.value(key)),
            )),
        }
    }

    fn usize(&self, key: &str, min: u64) -> Result<usize, ConfigError> {
        let n = self.count(key, min)?;
        usize::try_from(n).map_err(|_| self.invalid(key, format!("`{n}` is too large")))
    }

    fn positive(&self, key: &str, allow_zero: bool) -> Result<f64, ConfigError> {
        match self.value(key).as_f64() {
            Some(x) if x.is_finite() && (x > 0.0 || (allow_zero && x == 0.0)) => Ok(x),
            _ => Err(self.invalid(
                key,
                format!(
                    "expected a finite number {} 0, found `{}`",
                    if allow_zero { ">=" } else { ">" },
                    self.value(key)
                ),
            )),
        }
    }

    fn text(&self, key: &str) -> &str {
        self.value(key).as_str().unwrap_or_default()
    }
}

fn fixed_section<'a>(
    name: &'a str,
    fields: &BTreeMap<&str, &Field>,
) -> Result<Section<'a>, ConfigError> {
    let specs = section_schema(name).unwrap_or_default();
    let values = check_fixed(name, fields.get(name).map(|f| &f.value), &specs)?;
    Ok(Section { name, values })
}

/// A registered section as written: its id, the parameters it sets (typed) and the specs they
/// were checked against.
struct RegisteredFields {
    id: String,
    given: BTreeMap<String, Value>,
    specs: Vec<ParamSpec>,
}

/// Checks an `env` or `algorithm` section against the registry's parameter specs.
fn registered_fields(
    section: &str,
    node: &Node,
    discriminator: &str,
    what: &str,
    specs_of: impl Fn(&str) -> Result<Vec<ParamSpec>, String>,
) -> Result<RegisteredFields, ConfigError> {
    let fields = as_struct(node, section)?;
    let Some(id_field) = fields.iter().find(|f| f.key == discriminator) else {
        return Err(ConfigError::MissingKey {
            location: node.location.clone(),
            key: format!("{section}.{discriminator}"),
            reason: format!("the {section} section must name the registered {what}"),
        });
    };
    let id_key = format!("{section}.{discriminator}");
    let NodeValue::Str(id) = &id_field.value.value else {
        return Err(ConfigError::WrongType {
            location: id_field.value.location.clone(),
            key: id_key,
            reason: format!("expected string, found {}", id_field.value.type_name()),
        });
    };
    let specs = specs_of(id).map_err(|reason| ConfigError::InvalidValue {
        location: id_field.value.location.clone(),
        key: id_key.clone(),
        reason: format!("{reason}; `a2perf list` shows what is registered"),
    })?;
    let mut given = BTreeMap::new();
    for field in fields.iter().filter(|f| f.key != discriminator) {
        let prefix = format!("{section}.");
        let Some(spec) = specs.iter().find(|s| s.name == field.key) else {
            let known = std::iter::once(discriminator).chain(specs.iter().map(|s| s.name));
            return Err(unknown_key(field, &prefix, known));
        };
        let key = format!("{prefix}{}", field.key);
        given.insert(
            field.key.clone(),
            check_kind(spec, &field.value, &key, true)?,
        );
    }
    Ok(RegisteredFields {
        id: id.clone(),
        given,
        specs,
    })
}

/// [`registered_fields`] with the registry's defaults filled in.
fn registered_params(
    section: &str,
    node: &Node,
    discriminator: &str,
    what: &str,
    specs_of: impl Fn(&str) -> Result<Vec<ParamSpec>, String>,
) -> Result<(String, Params), ConfigError> {
    let f = registered_fields(section, node, discriminator, what, specs_of)?;
    let params = resolve(section, what, &f.id, &f.specs, &f.given)?;
    Ok((f.id, params))
}

fn resolve(
    section: &str,
    what: &str,
    id: &str,
    specs: &[ParamSpec],
    given: &BTreeMap<String, Value>,
) -> Result<Params, ConfigError> {
    // Only a registry default that fails its own kind can make this fail: a bug in the domain
    // crate, reported rather than hidden.
    Params::resolve(specs, given).map_err(|e| ConfigError::InvalidValue {
        location: Location::Default,
        key: section.to_string(),
        reason: format!("{what} `{id}`: {e}"),
    })
}

impl Experiment {
    /// Checks a merged config tree against the schema and `registry`.
    ///
    /// Unknown top-level keys are reported before anything else, so a typo is named even when
    /// the rest of the file is also wrong.
    pub(crate) fn from_tree(
        tree: &Node,
        default_name: &str,
        registry: &Registry,
    ) -> Result<Self, ConfigError> {
        let mut expanded = tree.clone();
        super::expand::expand_tree(&mut expanded)?;
        let tree = &expanded;
        let fields = as_struct(tree, "(top level)")?;
        let mut by_key: BTreeMap<&str, &Field> = BTreeMap::new();
        for field in fields {
            if !TOP_KEYS.contains(&field.key.as_str()) {
                let known = TOP_KEYS.iter().copied().chain(["include"]);
                return Err(unknown_key(field, "", known));
            }
            by_key.insert(field.key.as_str(), field);
        }

        let name = match by_key.get("name") {
            None => default_name.to_string(),
            Some(f) => match &f.value.value {
                NodeValue::Str(s) if !s.trim().is_empty() => s.clone(),
                NodeValue::Str(_) => {
                    return Err(ConfigError::InvalidValue {
                        location: f.value.location.clone(),
                        key: "name".into(),
                        reason: "the name must not be empty".into(),
                    });
                }
                _ => {
                    return Err(ConfigError::WrongType {
                        location: f.value.location.clone(),
                        key: "name".into(),
                        reason: format!("expected string, found {}", f.value.type_name()),
                    });
                }
            },
        };

        let profile = match by_key.get("profile") {
            None => None,
            Some(f) => parse_profile(&f.value, registry)?,
        };
        let env = match by_key.get("env") {
            None => None,
            Some(f) => {
                let RegisteredFields {
                    id,
                    mut given,
                    specs,
                } = registered_fields("env", &f.value, "id", "environment", |id| {
                    registry
                        .env(id)
                        .map(|e| e.params.clone())
                        .map_err(|e| e.to_string())
                })?;
                // The profile fills in what no layer sets; a layer that sets a switched
                // parameter itself wins (and the run records the switch as overridden).
                let profile_switches = match (&profile, registry.env(&id)) {
                    (Some(p), Ok(entry)) => p.switches_for(entry),
                    _ => BTreeMap::new(),
                };
                for (k, v) in &profile_switches {
                    given.entry(k.clone()).or_insert_with(|| v.clone());
                }
                let params = resolve("env", "environment", &id, &specs, &given)?;
                Some(EnvConfig {
                    id,
                    params,
                    profile_switches,
                })
            }
        };
        let algorithm = match by_key.get("algorithm") {
            None => None,
            Some(f) => {
                let (name, params) =
                    registered_params("algorithm", &f.value, "name", "algorithm", |name| {
                        registry
                            .algorithm(name)
                            .map(|a| a.params.clone())
                            .map_err(|e| e.to_string())
                    })?;
                Some(AlgorithmConfig { name, params })
            }
        };

        let seeds = match by_key.get("seeds") {
            None => vec![0],
            Some(f) => seeds(&f.value)?,
        };

        // Check every fixed section's keys before interpreting any of them.
        for section in FIXED_SECTIONS {
            fixed_section(section, &by_key)?;
        }
        let t = fixed_section("training", &by_key)?;
        let training = TrainingSettings {
            total_env_steps: t.count("total_env_steps", 1)?,
            eval_interval: t.count("eval_interval", 0)?,
            eval_episodes: t.usize("eval_episodes", 0)?,
            checkpoint_interval: t.count("checkpoint_interval", 0)?,
            num_envs: t.usize("num_envs", 1)?,
        };
        let i = fixed_section("inference", &by_key)?;
        let inference = InferenceSettings {
            rollouts: i.usize("rollouts", 0)?,
            timing_samples: i.usize("timing_samples", 0)?,
            observation_source: match i.text("observation_source") {
                "random" => ObservationSource::Random,
                _ => ObservationSource::Rollouts,
            },
        };
        let g = fixed_section("generalization", &by_key)?;
        let tasks = match by_key
            .get("generalization")
            .and_then(|f| f.value.field("tasks"))
        {
            None => None,
            Some(f) if f.value.value == NodeValue::Null => None,
            Some(f) => Some(parse_tasks(
                &f.value,
                "generalization.tasks",
                registry,
                None,
            )?),
        };
        let generalization = GeneralizationSettings {
            episodes: g.usize("episodes", 0)?,
            tasks,
        };
        let m = fixed_section("metrics", &by_key)?;
        let metrics = MetricSettings {
            ram_sample_interval_s: m.positive("ram_sample_interval_s", false)?,
            carbon_intensity_g_per_kwh: m.positive("carbon_intensity_g_per_kwh", true)?,
            energy_method: match m.text("energy_method") {
                "rapl" => EnergyMethod::Rapl,
                "estimate" => EnergyMethod::Estimate,
                _ => EnergyMethod::Auto,
            },
            reliability_definition: match m.text("reliability_definition") {
                "chan2019" => ReliabilityDefinition::Chan2019,
                _ => ReliabilityDefinition::A2Perf,
            },
            bootstrap_reps: m.usize("bootstrap_reps", 1)?,
        };
        let o = fixed_section("output", &by_key)?;
        let dir = o.text("dir");
        if dir.is_empty() {
            return Err(o.invalid("dir", "the output directory must not be empty".into()));
        }
        let output = OutputSettings {
            dir: PathBuf::from(dir),
        };

        Ok(Self {
            name,
            profile,
            env,
            algorithm,
            seeds,
            training,
            inference,
            generalization,
            metrics,
            output,
        })
    }

    /// The environment, or an error naming the experiment when it has none.
    pub fn require_env(&self) -> Result<&EnvConfig, ConfigError> {
        self.env
            .as_ref()
            .ok_or_else(|| ConfigError::MissingSection {
                experiment: self.name.clone(),
                section: "env".into(),
                reason: "add `env: (id: \"...\")` naming a registered environment (`a2perf list`)"
                    .into(),
            })
    }

    /// The algorithm, or an error naming the experiment when it has none.
    pub fn require_algorithm(&self) -> Result<&AlgorithmConfig, ConfigError> {
        self.algorithm
            .as_ref()
            .ok_or_else(|| ConfigError::MissingSection {
                experiment: self.name.clone(),
                section: "algorithm".into(),
                reason:
                    "add `algorithm: (name: \"...\")` naming a registered algorithm (`a2perf list`)"
                        .into(),
            })
    }

    /// The operative config as ordered sections: (key, value) where a section is a list of
    /// (key, value) pairs in schema order.
    fn sections(&self) -> Vec<(&'static str, Rendered)> {
        let mut out = vec![("name", Rendered::Value(Value::Str(self.name.clone())))];
        if let Some(profile) = &self.profile {
            out.push(("profile", Rendered::Struct(profile.fields())));
        }
        if let Some(env) = &self.env {
            let mut fields = vec![("id".to_string(), Value::Str(env.id.clone()))];
            fields.extend(
                env.params
                    .values()
                    .iter()
                    .map(|(k, v)| (k.clone(), v.clone())),
            );
            out.push(("env", Rendered::Struct(fields)));
        }
        if let Some(alg) = &self.algorithm {
            let mut fields = vec![("name".to_string(), Value::Str(alg.name.clone()))];
            fields.extend(
                alg.params
                    .values()
                    .iter()
                    .map(|(k, v)| (k.clone(), v.clone())),
            );
            out.push(("algorithm", Rendered::Struct(fields)));
        }
        out.push((
            "seeds",
            Rendered::Value(Value::List(
                self.seeds
                    .iter()
                    .map(|&s| Value::Int(i64::try_from(s).unwrap_or(i64::MAX)))
                    .collect(),
            )),
        ));
        let int = |v: u64| Value::Int(i64::try_from(v).unwrap_or(i64::MAX));
        let t = &self.training;
        out.push((
            "training",
            Rendered::structure([
                ("total_env_steps", int(t.total_env_steps)),
                ("eval_interval", int(t.eval_interval)),
                ("eval_episodes", int(t.eval_episodes as u64)),
                ("checkpoint_interval", int(t.checkpoint_interval)),
                ("num_envs", int(t.num_envs as u64)),
            ]),
        ));
        let i = &self.inference;
        out.push((
            "inference",
            Rendered::structure([
                ("rollouts", int(i.rollouts as u64)),
                ("timing_samples", int(i.timing_samples as u64)),
                (
                    "observation_source",
                    Value::Str(
                        match i.observation_source {
                            ObservationSource::Rollouts => "rollouts",
                            ObservationSource::Random => "random",
                        }
                        .into(),
                    ),
                ),
            ]),
        ));
        let mut generalization = vec![(
            "episodes".to_string(),
            int(self.generalization.episodes as u64),
        )];
        if let Some(tasks) = &self.generalization.tasks {
            generalization.push(("tasks".to_string(), tasks_to_value(tasks)));
        }
        out.push(("generalization", Rendered::Struct(generalization)));
        let m = &self.metrics;
        out.push((
            "metrics",
            Rendered::structure([
                (
                    "ram_sample_interval_s",
                    Value::Float(m.ram_sample_interval_s),
                ),
                (
                    "carbon_intensity_g_per_kwh",
                    Value::Float(m.carbon_intensity_g_per_kwh),
                ),
                (
                    "energy_method",
                    Value::Str(
                        match m.energy_method {
                            EnergyMethod::Auto => "auto",
                            EnergyMethod::Rapl => "rapl",
                            EnergyMethod::Estimate => "estimate",
                        }
                        .into(),
                    ),
                ),
                (
                    "reliability_definition",
                    Value::Str(
                        match m.reliability_definition {
                            ReliabilityDefinition::A2Perf => "a2perf",
                            ReliabilityDefinition::Chan2019 => "chan2019",
                        }
                        .into(),
                    ),
                ),
                ("bootstrap_reps", int(m.bootstrap_reps as u64)),
            ]),
        ));
        out.push((
            "output",
            Rendered::structure([(
                "dir",
                Value::Str(self.output.dir.to_string_lossy().into_owned()),
            )]),
        ));
        out
    }

    /// The operative config as a plain value (a map per section), e.g. for JSON reports.
    pub fn to_value(&self) -> Value {
        Value::Map(
            self.sections()
                .into_iter()
                .map(|(k, r)| {
                    let v = match r {
                        Rendered::Value(v) => v,
                        Rendered::Struct(fields) => Value::Map(fields.into_iter().collect()),
                    };
                    (k.to_string(), v)
                })
                .collect(),
        )
    }

    /// The operative config as RON text: every value in force, defaults included. Loading the
    /// text again (with the same registry) gives an identical experiment.
    pub fn to_ron_string(&self) -> String {
        let mut s =
            String::from("// Operative config: every value in force, defaults included.\n(\n");
        for (key, section) in self.sections() {
            match section {
                Rendered::Value(v) => {
                    let _ = writeln!(s, "    {key}: {},", ron_value_pretty(&v, 4));
                }
                Rendered::Struct(fields) => {
                    let _ = writeln!(s, "    {key}: (");
                    for (k, v) in fields {
                        let _ = writeln!(s, "        {k}: {},", ron_value_pretty(&v, 8));
                    }
                    s.push_str("    ),\n");
                }
            }
        }
        s.push_str(")\n");
        s
    }

    /// Writes the operative config to `dir/operative_config.ron` (atomically, creating `dir`)
    /// and returns the file's path.
    pub fn write_operative(&self, dir: &Path) -> Result<PathBuf, ConfigError> {
        let path = dir.join(OPERATIVE_CONFIG_FILE);
        std::fs::create_dir_all(dir)
            .and_then(|()| crate::results::write_atomic(&path, self.to_ron_string().as_bytes()))
            .map_err(|source| ConfigError::Write {
                path: path.clone(),
                source,
            })?;
        Ok(path)
    }
}

enum Rendered {
    Value(Value),
    Struct(Vec<(String, Value)>),
}

impl Rendered {
    fn structure<const N: usize>(fields: [(&str, Value); N]) -> Self {
        Rendered::Struct(
            fields
                .into_iter()
                .map(|(k, v)| (k.to_string(), v))
                .collect(),
        )
    }
}

fn seeds(node: &Node) -> Result<Vec<u64>, ConfigError> {
    let wrong = |location: &Location, found: &str| ConfigError::WrongType {
        location: location.clone(),
        key: "seeds".into(),
        reason: format!("expected a list of integers, e.g. `[0, 1, 2]`, found {found}"),
    };
    let NodeValue::List(items) = &node.value else {
        return Err(wrong(&node.location, node.type_name()));
    };
    if items.is_empty() {
        return Err(ConfigError::InvalidValue {
            location: node.location.clone(),
            key: "seeds".into(),
            reason: "at least one seed is needed".into(),
        });
    }
    let mut out: Vec<u64> = Vec::with_capacity(items.len());
    for item in items {
        let seed = match item.value {
            NodeValue::Int(i) => u64::try_from(i).map_err(|_| ConfigError::InvalidValue {
                location: item.location.clone(),
                key: "seeds".into(),
                reason: format!("seeds are non-negative, found `{i}`"),
            })?,
            _ => {
                return Err(wrong(
                    &item.location,
                    &format!("a {} item", item.type_name()),
                ));
            }
        };
        if out.contains(&seed) {
            return Err(ConfigError::InvalidValue {
                location: item.location.clone(),
                key: "seeds".into(),
                reason: format!("seed `{seed}` is listed twice"),
            });
        }
        out.push(seed);
    }
    Ok(out)
}

/// Renders a value as RON that this module's parser reads back to the same value.
pub(crate) fn ron_value(v: &Value) -> String {
    match v {
        Value::Null => "None".into(),
        Value::Bool(b) => b.to_string(),
        Value::Int(i) => i.to_string(),
        Value::Float(x) => ron_float(*x),
        // Strings are expanded when loaded (`${VAR}`), so a literal `${` is written escaped.
        Value::Str(s) => ron_string(&super::expand::escape(s)),
        Value::List(items) => {
            let inner: Vec<String> = items.iter().map(ron_value).collect();
            format!("[{}]", inner.join(", "))
        }
        Value::Map(m) => {
            let inner: Vec<String> = m
                .iter()
                .map(|(k, v)| format!("{}: {}", ron_string(k), ron_value(v)))
                .collect();
            format!("{{{}}}", inner.join(", "))
        }
    }
}

/// [`ron_value`] with maps, and lists holding maps, spread over indented lines (profiles and
/// task lists would otherwise make one very long line). `indent` is the column of the line the
/// value starts on.
fn ron_value_pretty(v: &Value, indent: usize) -> String {
    let pad = " ".repeat(indent);
    let inner = " ".repeat(indent + 4);
    match v {
        Value::Map(m) if !m.is_empty() => {
            // Identifier keys read as a struct `(key: v)`; others (environment ids) need the
            // map form `{"Id-v0": v}`. Both parse to the same value.
            let identifiers = m.keys().all(|k| {
                k.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
                    && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                    && !["true", "false", "None", "Some", "inf", "NaN"].contains(&k.as_str())
            });
            let (open, close) = if identifiers { ('(', ')') } else { ('{', '}') };
            let mut s = format!("{open}\n");
            for (k, v) in m {
                let key = if identifiers {
                    k.clone()
                } else {
                    ron_string(k)
                };
                let _ = writeln!(s, "{inner}{key}: {},", ron_value_pretty(v, indent + 4));
            }
            s.push_str(&pad);
            s.push(close);
            s
        }
        Value::List(items) if items.iter().any(|i| matches!(i, Value::Map(_))) => {
            let mut s = String::from("[\n");
            for item in items {
                let _ = writeln!(s, "{inner}{},", ron_value_pretty(item, indent + 4));
            }
            s.push_str(&pad);
            s.push(']');
            s
        }
        _ => ron_value(v),
    }
}

fn ron_float(x: f64) -> String {
    if x.is_nan() {
        "NaN".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf".into() } else { "-inf".into() }
    } else if x.fract() == 0.0 && x.abs() < 1e15 {
        format!("{x:.1}")
    } else {
        // Debug prints the shortest text that parses back to the same f64.
        let s = format!("{x:?}");
        if s.contains(['.', 'e', 'E']) {
            s
        } else {
            format!("{s}.0")
        }
    }
}

fn ron_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{{{:x}}}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

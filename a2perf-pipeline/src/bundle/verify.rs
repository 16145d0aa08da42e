//! Checking a bundle: its manifest, then every stated return against a replay of its logged
//! actions in a freshly made environment, every stated statistic against the replayed returns,
//! and for built-in algorithms the logged actions against the bundled checkpoint's own.
//!
//! No code from the bundle runs: the environments come from the local registry (their
//! identities are compared with the bundle's), a built-in checkpoint is data read by the
//! benchmark's own loader, and an external agent's files are never opened.

use std::fmt;
use std::path::{Path, PathBuf};

use a2perf_core::replay::{EpisodeLog, Recorder, replay};
use a2perf_core::{ActMode, Env, Registry};
use serde::de::DeserializeOwned;

use super::archive::{Archive, ArchiveLimits};
use super::error::{BundleError, RUNS_DIR};
use super::pack::{IdentityFile, env_hashes};
use crate::error::io_err;
use crate::generalize::{generalization_episode_seed, generalization_suite};
use crate::infer::inference_episode_seed;
use crate::plan::RunJob;
use crate::run_dir::{
    GENERALIZATION_FILE, GeneralizationResults, IDENTITY_FILE, INFERENCE_EPISODES_FILE,
    INFERENCE_FILE, InferenceResults, LoadedRun, OPERATIVE_FILE, POLICY_FILE, RUN_FILE, RunRecord,
    generalization_episodes_file, parse_episode_logs, policy_from_checkpoint_bytes,
};
use crate::stats::Summary;

/// Options of [`Bundle::verify`].
#[derive(Clone, Debug, Default)]
pub struct VerifyOptions {
    /// Also retrain every built-in run from its operative config and seed (in a temporary
    /// directory) and check that the final policy is byte-identical.
    pub retrain: bool,
}

/// The outcome of one check.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// It holds (with what was checked).
    Holds(String),
    /// It does not (with the first difference).
    Fails(String),
    /// It could not be checked for this run (and does not count as a failure).
    Skipped(String),
}

/// One check of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// The run's folder in the bundle (`runs/<experiment>/<run>`), or `bundle`.
    pub run: String,
    /// What was checked.
    pub what: String,
    /// Whether it holds.
    pub outcome: Outcome,
}

impl fmt::Display for Check {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (word, detail) = match &self.outcome {
            Outcome::Holds(d) => ("holds", d),
            Outcome::Fails(d) => ("FAILS", d),
            Outcome::Skipped(d) => ("skipped", d),
        };
        write!(f, "{word:7} {}: {}: {detail}", self.run, self.what)
    }
}

/// Every check of a bundle.
#[derive(Clone, Debug)]
pub struct Verification {
    /// The bundle file.
    pub bundle: PathBuf,
    /// The checks, run by run.
    pub checks: Vec<Check>,
}

impl Verification {
    /// Whether no check failed.
    pub fn holds(&self) -> bool {
        !self
            .checks
            .iter()
            .any(|c| matches!(c.outcome, Outcome::Fails(_)))
    }

    /// The failed checks.
    pub fn failures(&self) -> impl Iterator<Item = &Check> {
        self.checks
            .iter()
            .filter(|c| matches!(c.outcome, Outcome::Fails(_)))
    }
}

/// A bundle read into memory: its manifest checked, nothing written anywhere.
#[derive(Clone, Debug)]
pub struct Bundle {
    path: PathBuf,
    archive: Archive,
    runs: Vec<String>,
}

impl Bundle {
    /// Reads `path` under `limits` (see [`Archive::read`]): a truncated, edited, swapped,
    /// oversized or unsafe archive is an error here.
    pub fn read(path: &Path, limits: &ArchiveLimits) -> Result<Self, BundleError> {
        Self::from_archive(path, Archive::read(path, limits)?)
    }

    /// A bundle made of `archive`'s members (`path` names it in messages).
    pub fn from_archive(path: &Path, archive: Archive) -> Result<Self, BundleError> {
        let suffix = format!("/{RUN_FILE}");
        let runs: Vec<String> = archive
            .names()
            .filter_map(|n| n.strip_suffix(&suffix))
            .filter(|f| f.starts_with(&format!("{RUNS_DIR}/")) && f.split('/').count() == 3)
            .map(String::from)
            .collect();
        if runs.is_empty() {
            return Err(BundleError::Invalid(format!(
                "{}: holds no run (no {RUNS_DIR}/<experiment>/<run>/{RUN_FILE})",
                path.display()
            )));
        }
        Ok(Self {
            path: path.to_path_buf(),
            archive,
            runs,
        })
    }

    /// The runs' folders (`runs/<experiment>/<run>`).
    pub fn runs(&self) -> &[String] {
        &self.runs
    }

    /// The members.
    pub fn archive(&self) -> &Archive {
        &self.archive
    }

    /// Runs every check (see the module's documentation).
    pub fn verify(&self, registry: &Registry, opts: &VerifyOptions) -> Verification {
        let mut checks = vec![Check {
            run: "bundle".into(),
            what: "manifest".into(),
            outcome: Outcome::Holds(format!(
                "{} members, each of the size and SHA-256 listed",
                self.archive.len()
            )),
        }];
        for folder in &self.runs {
            let mut c = Checker {
                bundle: self,
                folder,
                checks: &mut checks,
            };
            c.run(registry, opts);
        }
        Verification {
            bundle: self.path.clone(),
            checks,
        }
    }

    /// Writes the runs' files into `dest` (`dest/<experiment>/<run>/…`) and returns the run
    /// directories, for a report. Member paths were checked when the bundle was read (relative,
    /// no `..`), so nothing lands outside `dest`.
    pub fn extract(&self, dest: &Path) -> Result<Vec<PathBuf>, BundleError> {
        let prefix = format!("{RUNS_DIR}/");
        for (name, bytes) in self.archive.iter() {
            let Some(rel) = name.strip_prefix(&prefix) else {
                continue;
            };
            let p = dest.join(rel);
            if let Some(parent) = p.parent() {
                std::fs::create_dir_all(parent).map_err(io_err(parent))?;
            }
            std::fs::write(&p, bytes).map_err(io_err(&p))?;
        }
        Ok(self
            .runs
            .iter()
            .map(|f| dest.join(f.strip_prefix(&prefix).unwrap_or(f)))
            .collect())
    }
}

/// Reads and verifies the bundle at `path` with the default limits.
///
/// ```no_run
/// use a2perf_pipeline::bundle::{VerifyOptions, verify};
/// let reg = a2perf_pipeline::registry::full_registry();
/// let v = verify(&reg, "run.a2perf".as_ref(), &VerifyOptions::default()).unwrap();
/// for c in &v.checks {
///     println!("{c}");
/// }
/// assert!(v.holds());
/// ```
pub fn verify(
    registry: &Registry,
    path: &Path,
    opts: &VerifyOptions,
) -> Result<Verification, BundleError> {
    Ok(Bundle::read(path, &ArchiveLimits::default())?.verify(registry, opts))
}

/// The checks of one run.
struct Checker<'a> {
    bundle: &'a Bundle,
    folder: &'a str,
    checks: &'a mut Vec<Check>,
}

/// A failed check's text.
type Failure = String;

/// The reason for a failure at `episode`, `step`.
fn at(
    episode: usize,
    step: usize,
    what: &str,
    expected: impl fmt::Debug,
    found: impl fmt::Debug,
) -> Failure {
    format!("episode {episode}, step {step}: {what}: expected {expected:?}, found {found:?}")
}

impl Checker<'_> {
    fn record(&mut self, what: &str, outcome: Outcome) {
        self.checks.push(Check {
            run: self.folder.to_string(),
            what: what.into(),
            outcome,
        });
    }

    fn check(&mut self, what: &str, result: Result<String, Failure>) {
        let outcome = match result {
            Ok(d) => Outcome::Holds(d),
            Err(d) => Outcome::Fails(d),
        };
        self.record(what, outcome);
    }

    fn member(&self, rel: &str) -> Option<&[u8]> {
        self.bundle.archive.get(&format!("{}/{rel}", self.folder))
    }

    fn path(&self, rel: &str) -> PathBuf {
        self.bundle.path.join(self.folder).join(rel)
    }

    fn parse<T: DeserializeOwned>(&self, rel: &str) -> Result<Option<T>, Failure> {
        self.member(rel)
            .map(|b| serde_json::from_slice(b).map_err(|e| format!("{rel} is unreadable: {e}")))
            .transpose()
    }

    fn logs(&self, rel: &str) -> Result<Vec<EpisodeLog>, Failure> {
        let bytes = self
            .member(rel)
            .ok_or_else(|| format!("no episode log {rel} for the results it states"))?;
        parse_episode_logs(bytes, &self.path(rel)).map_err(|e| e.to_string())
    }

    fn run(&mut self, registry: &Registry, opts: &VerifyOptions) {
        let record: RunRecord = match self.parse(RUN_FILE) {
            Ok(Some(r)) => r,
            Ok(None) => return self.check("run record", Err(format!("no {RUN_FILE}"))),
            Err(e) => return self.check("run record", Err(e)),
        };
        let run = LoadedRun {
            dir: self.path(""),
            record,
        };
        let identity = self.identity(registry, &run);
        self.check("environment identity", identity);
        let logs = match self.parse::<InferenceResults>(INFERENCE_FILE) {
            Ok(Some(results)) => {
                let (outcome, logs) = self.inference(registry, &run, &results);
                self.check("inference returns (replayed)", outcome);
                logs
            }
            Ok(None) => {
                self.record(
                    "inference returns (replayed)",
                    Outcome::Skipped(format!(
                        "the run states no inference results ({INFERENCE_FILE})"
                    )),
                );
                None
            }
            Err(e) => {
                self.check("inference returns (replayed)", Err(e));
                None
            }
        };
        match self.parse::<GeneralizationResults>(GENERALIZATION_FILE) {
            Ok(Some(results)) => {
                let outcome = self.generalization(registry, &run, &results);
                self.check("generalization returns (replayed)", outcome);
            }
            Ok(None) => self.record(
                "generalization returns (replayed)",
                Outcome::Skipped(format!(
                    "the run states no generalization results ({GENERALIZATION_FILE})"
                )),
            ),
            Err(e) => self.check("generalization returns (replayed)", Err(e)),
        }
        if run.record.external.is_some() {
            self.record(
                "checkpoint re-run",
                Outcome::Skipped(
                    "an external agent's checkpoint is in its own format and its code is never \
                     run: the replays prove the returns, not which agent chose the actions"
                        .into(),
                ),
            );
        } else if let Some(logs) = logs {
            let outcome = self.rerun(registry, &run, &logs);
            self.check("checkpoint re-run (greedy actions)", outcome);
        }
        if opts.retrain {
            if run.record.external.is_some() || run.record.dataset.is_some() {
                self.record(
                    "retrain",
                    Outcome::Skipped(
                        "only built-in online algorithms are retrained (an external agent's code \
                         never runs; an offline run needs its dataset)"
                            .into(),
                    ),
                );
            } else {
                let outcome = self.retrain(registry, &run);
                self.check("retrain (final policy byte-identical)", outcome);
            }
        }
    }

    /// The bundled environment hashes against the ones the local registry's environments give.
    fn identity(&self, registry: &Registry, run: &LoadedRun) -> Result<String, Failure> {
        let file: IdentityFile = self
            .parse(IDENTITY_FILE)?
            .ok_or_else(|| format!("no {IDENTITY_FILE}"))?;
        let task = &run.record.task;
        let first = file.environments.first();
        if first.is_none_or(|e| e.env_id != task.env_id || e.params != task.env_params) {
            return Err(format!(
                "{IDENTITY_FILE} does not start with the run's task {}",
                task.env_id
            ));
        }
        for env in &file.environments {
            let local = env_hashes(registry, &env.env_id, &env.params)
                .map_err(|e| format!("{} ({}): cannot be made here: {e}", env.role, env.env_id))?;
            if local != env.hashes {
                let key = env
                    .hashes
                    .keys()
                    .chain(local.keys())
                    .find(|k| env.hashes.get(*k) != local.get(*k))
                    .cloned()
                    .unwrap_or_default();
                return Err(format!(
                    "{} ({}): {key}: the bundle says {:?}, the local data gives {:?}",
                    env.role,
                    env.env_id,
                    env.hashes.get(&key),
                    local.get(&key)
                ));
            }
        }
        Ok(format!(
            "{} environments; every content hash matches the local data",
            file.environments.len()
        ))
    }

    /// Replays the inference logs; on success also returns them for the checkpoint re-run.
    fn inference(
        &self,
        registry: &Registry,
        run: &LoadedRun,
        results: &InferenceResults,
    ) -> (Result<String, Failure>, Option<Vec<EpisodeLog>>) {
        let outcome = (|| {
            let logs = self.logs(INFERENCE_EPISODES_FILE)?;
            let task = &run.record.task;
            let mut env = registry
                .make_env(&task.env_id, &task.env_params)
                .map_err(|e| format!("{}: {e}", task.env_id))?;
            let seed_of = |i| inference_episode_seed(run.record.seed, i);
            let returns = replay_all(
                env.as_mut(),
                &logs,
                &seed_of,
                &results.rollout_returns,
                Some(&results.episode_lengths),
                results.episodes,
            )?;
            let _ = env.close();
            let summary = Summary::of(&returns);
            if summary != results.returns {
                return Err(format!(
                    "the stated summary of the returns {:?} is not the replayed returns' {:?}",
                    results.returns, summary
                ));
            }
            Ok((
                format!(
                    "{} episodes of {}; each return and the summary (mean {}) recomputed",
                    logs.len(),
                    task.env_id,
                    summary.mean
                ),
                logs,
            ))
        })();
        match outcome {
            Ok((d, logs)) => (Ok(d), Some(logs)),
            Err(e) => (Err(e), None),
        }
    }

    fn generalization(
        &self,
        registry: &Registry,
        run: &LoadedRun,
        results: &GeneralizationResults,
    ) -> Result<String, Failure> {
        let suite = generalization_suite(registry, run).1;
        let stated: Vec<_> = results
            .tasks
            .iter()
            .map(|t| (&t.name, &t.env_id, &t.params))
            .collect();
        let recorded: Vec<_> = suite
            .iter()
            .map(|t| (&t.name, &t.env_id, &t.params))
            .collect();
        if stated != recorded {
            return Err(format!(
                "the results' tasks {:?} are not the run's generalization suite {:?}",
                stated.iter().map(|t| t.0).collect::<Vec<_>>(),
                recorded.iter().map(|t| t.0).collect::<Vec<_>>()
            ));
        }
        let mut means = Vec::new();
        let mut episodes = 0;
        for task in &results.tasks {
            let Some(stated_mean) = task.mean_return else {
                means.push(None);
                continue;
            };
            let in_task = |e: Failure| format!("task {}: {e}", task.name);
            let logs = self
                .logs(&generalization_episodes_file(&task.name))
                .map_err(in_task)?;
            let mut env = registry
                .make_env(&task.env_id, &task.params)
                .map_err(|e| in_task(format!("{}: {e}", task.env_id)))?;
            let seed_of = |i| generalization_episode_seed(run.record.seed, &task.name, i);
            let returns = replay_all(
                env.as_mut(),
                &logs,
                &seed_of,
                &task.returns,
                None,
                results.episodes,
            )
            .map_err(in_task)?;
            let _ = env.close();
            // The same arithmetic as `generalize`.
            let mean = returns.iter().sum::<f64>() / returns.len() as f64;
            if mean.to_bits() != stated_mean.to_bits() {
                return Err(in_task(format!(
                    "mean return: expected {stated_mean:?}, found {mean:?}"
                )));
            }
            episodes += returns.len();
            means.push(Some(mean));
        }
        let sum = means.iter().copied().sum::<Option<f64>>();
        if sum.map(f64::to_bits) != results.sum_of_mean_returns.map(f64::to_bits) {
            return Err(format!(
                "sum of mean returns: expected {:?}, found {sum:?}",
                results.sum_of_mean_returns
            ));
        }
        Ok(format!(
            "{} tasks, {episodes} episodes; each return, mean and the sum {sum:?} recomputed",
            results.tasks.len()
        ))
    }

    /// Rolls the bundled checkpoint out greedily on every logged inference seed and compares
    /// its actions with the logged ones.
    fn rerun(
        &self,
        registry: &Registry,
        run: &LoadedRun,
        logs: &[EpisodeLog],
    ) -> Result<String, Failure> {
        let bytes = self
            .member(POLICY_FILE)
            .ok_or_else(|| format!("no {POLICY_FILE} for a built-in algorithm"))?;
        let task = &run.record.task;
        let mut env = registry
            .make_env(&task.env_id, &task.env_params)
            .map_err(|e| format!("{}: {e}", task.env_id))?;
        let spec = env.spec().clone();
        let mut policy =
            policy_from_checkpoint_bytes(registry, bytes, &self.path(POLICY_FILE), &spec)
                .map_err(|e| e.to_string())?;
        let mut recorder = Recorder::new(env.as_mut());
        for (i, log) in logs.iter().enumerate() {
            a2perf_core::rollout(
                &mut recorder,
                policy.as_mut(),
                log.seed,
                ActMode::Greedy,
                false,
            )
            .map_err(|e| format!("episode {i}: the checkpoint's rollout failed: {e}"))?;
            let ours = &recorder.logs()[i];
            let n = ours.actions.len().max(log.actions.len());
            if let Some(step) = (0..n).find(|&s| ours.actions.get(s) != log.actions.get(s)) {
                return Err(at(
                    i,
                    step,
                    "action",
                    log.actions.get(step),
                    ours.actions.get(step),
                ));
            }
        }
        Ok(format!(
            "the checkpoint's greedy policy takes every logged action of the {} episodes",
            logs.len()
        ))
    }

    /// Retrains the run from its operative config and seed in a temporary directory.
    fn retrain(&self, registry: &Registry, run: &LoadedRun) -> Result<String, Failure> {
        let config = self
            .member(OPERATIVE_FILE)
            .ok_or_else(|| format!("no {OPERATIVE_FILE} to retrain from"))?;
        let stated = self
            .member(POLICY_FILE)
            .ok_or_else(|| format!("no {POLICY_FILE} to compare with"))?;
        let tmp = tempfile::tempdir().map_err(|e| format!("temporary directory: {e}"))?;
        let path = tmp.path().join(OPERATIVE_FILE);
        std::fs::write(&path, config).map_err(|e| format!("{}: {e}", path.display()))?;
        let out = tmp.path().join("out");
        let seed = run.record.seed;
        let loaded = crate::load_plans(
            &[path],
            &[format!("output.dir={}", out.display())],
            Some(&[seed]),
            registry,
        )
        .map_err(|e| format!("the operative config does not load: {e}"))?;
        let [plan] = <[_; 1]>::try_from(loaded.plans)
            .map_err(|p| format!("the operative config holds {} experiments, not 1", p.len()))?;
        let dir = plan.run_dir(seed);
        let job = RunJob {
            index: 0,
            plan,
            seed,
        };
        crate::train::train_one(registry, &job, &crate::TrainOptions::default())
            .map_err(|e| format!("retraining failed: {e}"))?;
        let p = dir.join(POLICY_FILE);
        let ours = std::fs::read(&p).map_err(|e| format!("{}: {e}", p.display()))?;
        if ours != stated {
            let byte = ours
                .iter()
                .zip(stated)
                .position(|(a, b)| a != b)
                .unwrap_or(ours.len().min(stated.len()));
            return Err(format!(
                "{POLICY_FILE} differs from byte {byte} (retrained: {} bytes, bundled: {} bytes)",
                ours.len(),
                stated.len()
            ));
        }
        Ok(format!(
            "retrained from seed {seed}: {POLICY_FILE} identical ({} bytes)",
            ours.len()
        ))
    }
}

/// Replays `logs` in `env` in order, checking each against its expected seed, the stated
/// returns (bit for bit) and lengths, and the logged rewards; returns the replayed returns.
fn replay_all(
    env: &mut dyn Env,
    logs: &[EpisodeLog],
    seed_of: &dyn Fn(usize) -> u64,
    stated: &[f64],
    lengths: Option<&[usize]>,
    episodes: usize,
) -> Result<Vec<f64>, Failure> {
    if logs.len() != episodes || stated.len() != episodes {
        return Err(format!(
            "{episodes} episodes stated, {} returns stated, {} episodes logged",
            stated.len(),
            logs.len()
        ));
    }
    let mut returns = Vec::with_capacity(logs.len());
    for (i, log) in logs.iter().enumerate() {
        if log.seed != seed_of(i) {
            return Err(format!(
                "episode {i}: reset seed: expected {} (the run's seed stream), found {}",
                seed_of(i),
                log.seed
            ));
        }
        let replayed = replay(env, log).map_err(|e| format!("episode {i}: {e}"))?;
        if let Some(d) = replayed.first_difference(log) {
            return Err(at(i, d.step, "reward", d.expected, d.found));
        }
        if replayed.episode_return.to_bits() != stated[i].to_bits() {
            return Err(format!(
                "episode {i}: return: expected {:?} (stated), found {:?} (replayed)",
                stated[i], replayed.episode_return
            ));
        }
        if let Some(len) = lengths.and_then(|l| l.get(i))
            && *len != replayed.length
        {
            return Err(format!(
                "episode {i}: length: expected {len} (stated), found {} (replayed)",
                replayed.length
            ));
        }
        returns.push(replayed.episode_return);
    }
    Ok(returns)
}

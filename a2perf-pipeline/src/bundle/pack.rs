//! Making a bundle: the files of complete runs, the identity of their environments, the
//! binary's version and the episode logs, packed into one [`Archive`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::{Registry, Value};
use serde::{Deserialize, Serialize};

use super::archive::Archive;
use super::error::{BundleError, INFO_FILE, RUNS_DIR};
use crate::error::io_err;
use crate::generalize::generalization_suite;
use crate::run_dir::{
    BUNDLED_FILES, CHECKPOINT_DIR, EPISODES_DIR, GENERALIZATION_EPISODES_DIR, GENERALIZATION_FILE,
    IDENTITY_FILE, INFERENCE_EPISODES_FILE, INFERENCE_FILE, LoadedRun, PARTICIPANT_DIR,
    POLICY_FILE,
};
use crate::sysinfo::SystemInfo;

/// `bundle.json`: who made the bundle, and which runs it holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BundleInfo {
    /// Version of the `a2perf` binary that packed it.
    pub a2perf_version: String,
    /// Git commit of that binary (`-dirty` when built from a changed tree, or `unknown`).
    pub git_commit: String,
    /// Each run's member folder (`runs/<experiment>/<run>`), in order.
    pub runs: Vec<String>,
}

/// One environment a run used, named by what it is made of.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvIdentity {
    /// What it was used for: `task`, or `generalization/<task name>`.
    pub role: String,
    /// Environment id.
    pub env_id: String,
    /// Its parameters as the run recorded them.
    pub params: BTreeMap<String, Value>,
    /// The environment's content hashes (`netlist_hash`, `clip_hash`, `pool_hash`, …): SHA-256
    /// of the netlist or motion-clip file, or a hash of the generated website pool.
    pub hashes: BTreeMap<String, String>,
}

/// `env_identity.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IdentityFile {
    /// The run's task first, then each generalization task.
    pub environments: Vec<EnvIdentity>,
}

/// The content hashes an environment reports in its spec's metadata (the entries named
/// `*_hash`), made from the registry with `params`.
pub(crate) fn env_hashes(
    registry: &Registry,
    env_id: &str,
    params: &BTreeMap<String, Value>,
) -> crate::Result<BTreeMap<String, String>> {
    let mut env = registry.make_env(env_id, params)?;
    let hashes = env
        .spec()
        .metadata
        .iter()
        .filter(|(k, _)| k.ends_with("_hash"))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let _ = env.close();
    Ok(hashes)
}

/// The environments `run` used: its task, then its generalization suite's tasks.
pub(crate) fn identities(registry: &Registry, run: &LoadedRun) -> crate::Result<IdentityFile> {
    let task = &run.record.task;
    let mut environments = vec![EnvIdentity {
        role: "task".into(),
        env_id: task.env_id.clone(),
        params: task.env_params.clone(),
        hashes: env_hashes(registry, &task.env_id, &task.env_params)?,
    }];
    for t in generalization_suite(registry, run).1 {
        environments.push(EnvIdentity {
            role: format!("generalization/{}", t.name),
            hashes: env_hashes(registry, &t.env_id, &t.params)?,
            env_id: t.env_id,
            params: t.params,
        });
    }
    Ok(IdentityFile { environments })
}

/// What [`pack`] put in the bundle.
#[derive(Clone, Debug)]
pub struct PackSummary {
    /// The bundle's description.
    pub info: BundleInfo,
    /// Members, the manifest included.
    pub members: usize,
    /// Size of the written file in bytes.
    pub bytes: u64,
}

/// Packs the complete runs at or below `dirs` (run directories or experiment directories) into
/// the bundle file `out`. Every run must be complete, and a run with inference or
/// generalization results must have their episode logs (runs rolled out before logs were
/// recorded are refused: roll them out again).
///
/// ```no_run
/// use std::path::{Path, PathBuf};
/// let reg = a2perf_pipeline::registry::full_registry();
/// let s = a2perf_pipeline::bundle::pack(&reg, &[PathBuf::from("results/quickstart")],
///     Path::new("quickstart.a2perf")).unwrap();
/// println!("{} runs, {} bytes", s.info.runs.len(), s.bytes);
/// ```
pub fn pack(registry: &Registry, dirs: &[PathBuf], out: &Path) -> Result<PackSummary, BundleError> {
    let runs = crate::run_dir::expand_runs(dirs)?;
    let mut archive = Archive::default();
    let mut names = Vec::new();
    for dir in &runs {
        let run = LoadedRun::open(dir)?;
        run.require_complete()?;
        let folder = format!(
            "{RUNS_DIR}/{}/{}",
            crate::plan::path_safe(&run.record.experiment),
            crate::plan::path_safe(&run.name())
        );
        if names.contains(&folder) {
            return Err(BundleError::Invalid(format!(
                "{}: a second run named {folder} (bundle each experiment once)",
                dir.display()
            )));
        }
        add_run(registry, &run, &folder, &mut archive)?;
        names.push(folder);
    }
    let info = BundleInfo {
        a2perf_version: env!("CARGO_PKG_VERSION").into(),
        git_commit: SystemInfo::current().git_commit,
        runs: names,
    };
    archive.insert(INFO_FILE, json(&info)?)?;
    archive.write(out)?;
    let bytes = std::fs::metadata(out).map_err(io_err(out))?.len();
    Ok(PackSummary {
        members: archive.len() + 1,
        info,
        bytes,
    })
}

fn json<T: Serialize>(value: &T) -> Result<Vec<u8>, BundleError> {
    serde_json::to_vec_pretty(value).map_err(|e| BundleError::Invalid(e.to_string()))
}

/// Adds one run's members under `folder`.
fn add_run(
    registry: &Registry,
    run: &LoadedRun,
    folder: &str,
    archive: &mut Archive,
) -> Result<(), BundleError> {
    let dir = &run.dir;
    let add = |rel: &str, archive: &mut Archive| -> Result<(), BundleError> {
        let p = dir.join(rel);
        let bytes = std::fs::read(&p).map_err(io_err(&p))?;
        archive.insert(&format!("{folder}/{rel}"), bytes)?;
        Ok(())
    };
    for rel in BUNDLED_FILES {
        if dir.join(rel).is_file() {
            add(rel, archive)?;
        }
    }
    let needs_logs = |results: &str, logs: &str| -> Result<(), BundleError> {
        if dir.join(results).is_file() && !dir.join(logs).exists() {
            return Err(BundleError::Invalid(format!(
                "{}: has {results} but no episode logs ({logs}): it was rolled out before \
                 episodes were recorded; run `a2perf infer` / `a2perf generalize` on it again",
                dir.display()
            )));
        }
        Ok(())
    };
    needs_logs(INFERENCE_FILE, INFERENCE_EPISODES_FILE)?;
    needs_logs(GENERALIZATION_FILE, GENERALIZATION_EPISODES_DIR)?;
    for rel in files_below(dir, EPISODES_DIR)? {
        add(&rel, archive)?;
    }
    if run.record.external.is_none() {
        add(POLICY_FILE, archive)?;
    } else {
        // An external agent's checkpoints are in its own format: carried, never loaded.
        for rel in files_below(dir, CHECKPOINT_DIR)? {
            add(&rel, archive)?;
        }
        for rel in files_below(dir, PARTICIPANT_DIR)? {
            add(&rel, archive)?;
        }
    }
    archive.insert(
        &format!("{folder}/{IDENTITY_FILE}"),
        json(&identities(registry, run)?)?,
    )?;
    Ok(())
}

/// Regular files below `dir/sub`, as `/`-separated paths relative to `dir`, sorted. Links are
/// left out (a bundle holds regular files only).
fn files_below(dir: &Path, sub: &str) -> Result<Vec<String>, BundleError> {
    fn walk(root: &Path, rel: &str, out: &mut Vec<String>) -> Result<(), BundleError> {
        let here = root.join(rel);
        let entries = std::fs::read_dir(&here).map_err(io_err(&here))?;
        for e in entries {
            let e = e.map_err(io_err(&here))?;
            let name = e.file_name().to_string_lossy().into_owned();
            let child = format!("{rel}/{name}");
            let kind = e.file_type().map_err(io_err(&e.path()))?;
            if kind.is_dir() {
                walk(root, &child, out)?;
            } else if kind.is_file() && !name.starts_with('.') {
                out.push(child);
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    if dir.join(sub).is_dir() {
        walk(dir, sub, &mut out)?;
    }
    out.sort();
    Ok(out)
}

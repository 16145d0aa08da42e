//! deploy/k8s and deploy/Dockerfile, checked without a cluster or a container engine.
//!
//! Each manifest is read into the Kubernetes API types of `k8s-openapi` (Kubernetes 1.33) and
//! written back: a field the API does not know, or a value of the wrong type, makes the two
//! differ. Then the fields a sweep depends on are checked against each other and against the
//! Dockerfile: one shard per completion index, exit 75 retried, a grace period longer than the
//! checkpoint bound, one results volume, and paths that exist in the image.

use std::path::{Path, PathBuf};
use std::process::Command;

use k8s_openapi::api::batch::v1::Job;
use k8s_openapi::api::core::v1::{Container, PersistentVolumeClaim, PodSpec};
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

/// Seconds a2perf takes at most to checkpoint after SIGTERM (its default bound).
const CHECKPOINT_BOUND_S: i64 = 30;
/// Exit status of a run stopped by a signal and left resumable.
const RESUMABLE: i32 = 75;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("a2perf-cli sits in the workspace root")
        .to_path_buf()
}

fn read(path: &str) -> String {
    let p = repo().join(path);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Paths where `a` has something that `b` lacks or holds differently.
fn differences(a: &Value, b: &Value, at: &str, out: &mut Vec<String>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for (k, v) in x {
                match y.get(k) {
                    Some(w) => differences(v, w, &format!("{at}.{k}"), out),
                    None => out.push(format!("{at}.{k}: not a field of the API type")),
                }
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (v, w)) in x.iter().zip(y).enumerate() {
                differences(v, w, &format!("{at}[{i}]"), out);
            }
        }
        _ if a != b => out.push(format!("{at}: {a} read back as {b}")),
        _ => {}
    }
}

/// The manifest at `path` as the API type `T`, failing on anything the type does not hold.
fn manifest<T: DeserializeOwned + Serialize>(path: &str) -> T {
    let yaml: Value =
        serde_norway::from_str(&read(path)).unwrap_or_else(|e| panic!("{path}: not YAML: {e}"));
    let typed: T = serde_json::from_value(yaml.clone())
        .unwrap_or_else(|e| panic!("{path}: not a valid object: {e}"));
    let back = serde_json::to_value(&typed).expect("API types serialize");
    let mut diff = Vec::new();
    differences(&yaml, &back, "", &mut diff);
    assert!(diff.is_empty(), "{path}:\n{}", diff.join("\n"));
    typed
}

fn pod(job: &Job) -> &PodSpec {
    job.spec
        .as_ref()
        .and_then(|s| s.template.spec.as_ref())
        .expect("a pod template")
}

fn container(job: &Job) -> &Container {
    let containers = &pod(job).containers;
    assert_eq!(containers.len(), 1, "one container");
    &containers[0]
}

fn args(job: &Job) -> &[String] {
    container(job).args.as_deref().unwrap_or_default()
}

/// The value after `flag` in the container's arguments.
fn arg_after<'a>(job: &'a Job, flag: &str) -> &'a str {
    let a = args(job);
    a.iter()
        .position(|x| x == flag)
        .and_then(|i| a.get(i + 1))
        .unwrap_or_else(|| panic!("no {flag} argument in {a:?}"))
}

fn env<'a>(c: &'a Container, name: &str) -> &'a k8s_openapi::api::core::v1::EnvVar {
    c.env
        .iter()
        .flatten()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no {name} environment variable"))
}

/// The `--set output.dir=` of the container.
fn output_dir(job: &Job) -> String {
    let a = args(job);
    a.windows(2)
        .find_map(|w| {
            (w[0] == "--set")
                .then(|| w[1].strip_prefix("output.dir="))
                .flatten()
        })
        .unwrap_or_else(|| panic!("no --set output.dir= in {a:?}"))
        .to_string()
}

/// Checks what keeps a pod's runs safe across preemption: exit 75 is retried without counting
/// as a failure, and the grace period covers the checkpoint.
fn assert_preemption_safe(name: &str, job: &Job) {
    let spec = job.spec.as_ref().expect("a job spec");
    let rules = &spec
        .pod_failure_policy
        .as_ref()
        .unwrap_or_else(|| panic!("{name}: no podFailurePolicy"))
        .rules;
    let container_name = &container(job).name;
    let retried = rules.iter().any(|r| {
        r.action == "Ignore"
            && r.on_exit_codes.as_ref().is_some_and(|c| {
                c.operator == "In"
                    && c.values.contains(&RESUMABLE)
                    && c.container_name.as_ref() == Some(container_name)
            })
    });
    assert!(
        retried,
        "{name}: exit {RESUMABLE} is not retried: {rules:?}"
    );
    let p = pod(job);
    assert_eq!(p.restart_policy.as_deref(), Some("Never"), "{name}");
    let grace = p
        .termination_grace_period_seconds
        .unwrap_or_else(|| panic!("{name}: no terminationGracePeriodSeconds"));
    assert!(
        grace >= 2 * CHECKPOINT_BOUND_S,
        "{name}: a grace period of {grace} s leaves the {CHECKPOINT_BOUND_S} s checkpoint too little margin"
    );
}

/// The volume mounted at a prefix of `output` and the claim it comes from.
fn results_claim(job: &Job, output: &str) -> String {
    let c = container(job);
    let mount = c
        .volume_mounts
        .iter()
        .flatten()
        .find(|m| output.starts_with(&m.mount_path))
        .unwrap_or_else(|| panic!("{output} is on no mounted volume"));
    pod(job)
        .volumes
        .iter()
        .flatten()
        .find(|v| v.name == mount.name)
        .and_then(|v| v.persistent_volume_claim.as_ref())
        .map(|c| c.claim_name.clone())
        .unwrap_or_else(|| panic!("volume {} is not a persistent volume claim", mount.name))
}

/// `COPY SRC DEST` lines of the Dockerfile's final stage that copy from the build context.
fn dockerfile_copies() -> Vec<(String, String)> {
    read("deploy/Dockerfile")
        .lines()
        .filter_map(|l| l.strip_prefix("COPY "))
        .filter(|rest| !rest.starts_with("--from"))
        .filter_map(|rest| {
            let parts: Vec<&str> = rest.split_whitespace().collect();
            (parts.len() == 2).then(|| (parts[0].to_string(), parts[1].to_string()))
        })
        .collect()
}

/// The file of the repository that the image holds at `path`, if it holds one.
fn image_source(path: &str) -> Option<PathBuf> {
    dockerfile_copies().into_iter().find_map(|(src, dest)| {
        let rest = path.strip_prefix(&dest)?.trim_start_matches('/');
        let source = repo().join(src);
        Some(if rest.is_empty() {
            source
        } else {
            source.join(rest)
        })
    })
}

#[test]
fn manifests_are_valid_kubernetes_objects() {
    let _: PersistentVolumeClaim = manifest("deploy/k8s/pvc.yaml");
    let _: Job = manifest("deploy/k8s/sweep-job.yaml");
    let _: Job = manifest("deploy/k8s/report-job.yaml");
}

#[test]
fn the_validation_catches_a_misspelt_field() {
    let text = read("deploy/k8s/sweep-job.yaml").replace("completionMode:", "completionMod:");
    let yaml: Value = serde_norway::from_str(&text).expect("still YAML");
    let back = serde_json::to_value(
        serde_json::from_value::<Job>(yaml.clone()).expect("unknown fields are dropped"),
    )
    .expect("serializes");
    let mut diff = Vec::new();
    differences(&yaml, &back, "", &mut diff);
    assert_eq!(
        diff,
        vec![".spec.completionMod: not a field of the API type".to_string()]
    );
}

#[test]
fn the_sweep_job_runs_one_shard_per_completion_index() {
    let job: Job = manifest("deploy/k8s/sweep-job.yaml");
    let spec = job.spec.as_ref().expect("a job spec");
    assert_eq!(spec.completion_mode.as_deref(), Some("Indexed"));
    let c = container(&job);
    assert_eq!(args(&job).first().map(String::as_str), Some("a2perf"));
    assert_eq!(args(&job).get(1).map(String::as_str), Some("train"));
    assert_eq!(
        arg_after(&job, "--shard"),
        "$(JOB_COMPLETION_INDEX)/$(SHARDS)"
    );
    let shards: i32 = env(c, "SHARDS")
        .value
        .as_deref()
        .and_then(|v| v.parse().ok())
        .expect("SHARDS is a number");
    assert_eq!(
        spec.completions,
        Some(shards),
        "completions must equal SHARDS"
    );
    assert!(spec.parallelism.is_some_and(|p| (1..=shards).contains(&p)));
    let index = env(c, "JOB_COMPLETION_INDEX")
        .value_from
        .as_ref()
        .and_then(|v| v.field_ref.as_ref())
        .map(|f| f.field_path.as_str());
    assert_eq!(
        index,
        Some("metadata.annotations['batch.kubernetes.io/job-completion-index']")
    );
    assert_preemption_safe("sweep-job.yaml", &job);
}

#[test]
fn the_report_job_reads_what_the_sweep_wrote() {
    let sweep: Job = manifest("deploy/k8s/sweep-job.yaml");
    let report: Job = manifest("deploy/k8s/report-job.yaml");
    let pvc: PersistentVolumeClaim = manifest("deploy/k8s/pvc.yaml");
    let claim = pvc.metadata.name.expect("the claim has a name");
    assert!(
        pvc.spec
            .and_then(|s| s.access_modes)
            .is_some_and(|m| m.iter().any(|m| m == "ReadWriteMany")),
        "pods of a sweep on several nodes share the volume"
    );
    let output = output_dir(&sweep);
    assert_eq!(output_dir(&report), output, "same output directory");
    assert_eq!(results_claim(&sweep, &output), claim);
    assert_eq!(results_claim(&report, &output), claim);
    assert_eq!(args(&report).get(1).map(String::as_str), Some("run"));
    assert_eq!(arg_after(&report, "-o"), format!("{output}/report"));
    assert_eq!(args(&report).get(2), args(&sweep).get(2), "same config");
    assert_eq!(container(&report).image, container(&sweep).image);
    assert_preemption_safe("report-job.yaml", &report);
}

#[test]
fn the_image_holds_what_the_manifests_use() {
    for (src, _) in dockerfile_copies() {
        assert!(
            repo().join(&src).exists(),
            "deploy/Dockerfile copies {src}, which does not exist"
        );
    }
    for file in ["deploy/k8s/sweep-job.yaml", "deploy/k8s/report-job.yaml"] {
        let job: Job = manifest(file);
        let config = &args(&job)[2];
        let source = image_source(config)
            .unwrap_or_else(|| panic!("{file}: {config} is not copied into the image"));
        assert!(
            source.is_file(),
            "{file}: {config} comes from {}, missing",
            source.display()
        );
    }
    let dockerfile = read("deploy/Dockerfile");
    // The binary the manifests call is the one the build stage builds, on the PATH.
    assert!(dockerfile.contains("cargo build --release --locked -p a2perf-cli"));
    assert!(read("a2perf-cli/Cargo.toml").contains("name = \"a2perf\""));
    assert!(dockerfile.contains("COPY --from=builder /out/a2perf /usr/local/bin/a2perf"));
    assert!(dockerfile.contains("ENTRYPOINT [\"/usr/bin/tini\", \"--\"]"));
}

#[test]
fn the_image_build_commands_work_here() {
    // `cargo build --locked` fails if Cargo.lock is out of date; check it the cheap way.
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--locked",
            "--offline",
            "--format-version",
            "1",
            "--no-deps",
        ])
        .current_dir(repo())
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo metadata --locked: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The runtime stage's packages exist in this machine's Debian release (the image's).
    let dockerfile = read("deploy/Dockerfile");
    let packages: Vec<&str> = dockerfile
        .split("apt-get install -y --no-install-recommends")
        .skip(1)
        .flat_map(|rest| {
            rest.split(['&', ';', '\\', '\n'])
                .next()
                .unwrap_or_default()
                .split_whitespace()
        })
        .collect();
    assert!(
        packages.contains(&"tini") && packages.contains(&"chromium"),
        "{packages:?}"
    );
    // One call for all: `apt-cache show` succeeds when any one package is found, so read
    // which ones it printed.
    let out = Command::new("apt-cache")
        .args(["show", "--no-all-versions"])
        .args(&packages)
        .output();
    let found: Vec<String> = out
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default()
        .lines()
        .filter_map(|l| l.strip_prefix("Package: "))
        .map(str::to_string)
        .collect();
    if found.is_empty() {
        eprintln!("skipped the package check: apt-cache has no package lists here");
        return;
    }
    let missing: Vec<&&str> = packages
        .iter()
        .filter(|p| !found.iter().any(|f| f == *p))
        .collect();
    assert!(
        missing.is_empty(),
        "not in this Debian release: {missing:?}"
    );
}

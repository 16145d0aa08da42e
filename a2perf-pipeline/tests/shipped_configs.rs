//! Every experiment file shipped in `configs/` loads through the config system against the full
//! registry: environment ids and parameters, algorithm names and hyperparameters, includes and
//! value types all check out, and the operative config round-trips.

use std::path::{Path, PathBuf};

use a2perf_core::Experiment;
use a2perf_pipeline::load_plans;
use a2perf_pipeline::registry::full_registry;

fn ron_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            ron_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "ron") {
            out.push(p);
        }
    }
}

#[test]
fn every_shipped_config_loads_against_the_full_registry() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
    let mut files = Vec::new();
    ron_files(&root, &mut files);
    assert!(
        files.len() >= 30,
        "expected the shipped configs, found {}",
        files.len()
    );
    let registry = full_registry();
    let mut experiments = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        if text.contains("experiments:") {
            // A suite (the quickstart): every entry must load as a runnable plan.
            let plans = load_plans(std::slice::from_ref(file), &[], None, &registry)
                .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            assert!(plans.plans.len() >= 6, "{}", file.display());
            continue;
        }
        let none: [&str; 0] = [];
        let exp = Experiment::load(file, &none, &registry)
            .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        if exp.env.is_some() {
            let alg = exp.require_algorithm().unwrap();
            registry.algorithm(&alg.name).unwrap();
            experiments += 1;
        }
        // The operative config is itself a valid config describing the same experiment.
        let dir = tempfile::tempdir().unwrap();
        exp.write_operative(dir.path()).unwrap();
        let again = Experiment::load(&dir.path().join("operative_config.ron"), &none, &registry)
            .unwrap_or_else(|e| panic!("operative config of {}: {e}", file.display()));
        assert_eq!(
            again.to_ron_string(),
            exp.to_ron_string(),
            "{}",
            file.display()
        );
    }
    // Per-domain algorithm files, their paper budgets and the per-task files.
    assert!(experiments >= 30, "only {experiments} experiment files");
}

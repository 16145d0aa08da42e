//! The shipped `configs/<domain>/<algo>.ron` files name registered algorithms and only their
//! declared hyperparameters, with values of the right types.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::{Params, Registry, Value};

fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

fn to_value(v: &ron::Value) -> Value {
    match v {
        ron::Value::Bool(b) => Value::Bool(*b),
        ron::Value::Number(n) => match n {
            ron::value::Number::F32(f) => Value::Float(f64::from(f.get())),
            ron::value::Number::F64(f) => Value::Float(f.get()),
            other => Value::Int((*other).into_f64() as i64),
        },
        ron::Value::String(s) => Value::Str(s.clone()),
        ron::Value::Seq(items) => Value::List(items.iter().map(to_value).collect()),
        ron::Value::Map(m) => Value::Map(
            m.iter()
                .filter_map(|(k, v)| match k {
                    ron::Value::String(s) => Some((s.clone(), to_value(v))),
                    _ => None,
                })
                .collect(),
        ),
        ron::Value::Option(Some(v)) => to_value(v),
        _ => Value::Null,
    }
}

/// The file's top-level map with its includes merged in (structs merge key by key).
fn load(path: &Path) -> BTreeMap<String, Value> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let raw: ron::Value =
        ron::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let Value::Map(mut top) = to_value(&raw) else {
        panic!("{}: not a struct", path.display())
    };
    let mut merged = BTreeMap::new();
    if let Some(Value::List(incs)) = top.remove("include") {
        for inc in incs {
            let Value::Str(rel) = inc else {
                panic!("bad include")
            };
            merge(&mut merged, load(&path.parent().unwrap().join(rel)));
        }
    }
    merge(&mut merged, top);
    merged
}

fn merge(into: &mut BTreeMap<String, Value>, from: BTreeMap<String, Value>) {
    for (k, v) in from {
        match (into.get_mut(&k), v) {
            (Some(Value::Map(a)), Value::Map(b)) => merge(a, b),
            (_, v) => {
                into.insert(k, v);
            }
        }
    }
}

#[test]
fn every_config_names_valid_hyperparameters() {
    let mut reg = Registry::new();
    a2perf_baselines::register(&mut reg);
    let expected = [
        ("circuit_training", &["ppo", "ddqn", "bc"][..]),
        ("web_navigation", &["ppo", "ddqn", "bc"][..]),
        ("quadruped_locomotion", &["ppo", "sac", "bc"][..]),
    ];
    let dir = configs_dir();
    if !dir.join("base.ron").exists() {
        println!("skipping: {} has no base.ron", dir.display());
        return;
    }
    for (domain, algos) in expected {
        for algo in algos {
            for file in [format!("{algo}.ron"), format!("{algo}.paper.ron")] {
                let path = dir.join(domain).join(&file);
                let cfg = load(&path);
                let Some(Value::Map(alg)) = cfg.get("algorithm") else {
                    panic!("{}: no algorithm", path.display())
                };
                assert_eq!(
                    alg.get("name"),
                    Some(&Value::Str(algo.to_string())),
                    "{}",
                    path.display()
                );
                let mut hp = alg.clone();
                hp.remove("name");
                let entry = reg.algorithm(algo).unwrap();
                let params = Params::resolve(&entry.params, &hp)
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                (entry.make)(&params).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                let Some(Value::Map(t)) = cfg.get("training") else {
                    panic!("{}: no training", path.display())
                };
                for key in [
                    "total_env_steps",
                    "eval_interval",
                    "eval_episodes",
                    "checkpoint_interval",
                    "num_envs",
                ] {
                    assert!(
                        matches!(t.get(key), Some(Value::Int(_))),
                        "{}: training.{key}",
                        path.display()
                    );
                }
                let Some(Value::Map(env)) = cfg.get("env") else {
                    panic!("{}: no env", path.display())
                };
                assert!(
                    matches!(env.get("id"), Some(Value::Str(_))),
                    "{}",
                    path.display()
                );
            }
        }
    }
}

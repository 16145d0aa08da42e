//! Tests of the config system: syntax, includes, overrides, every error kind, and proptest
//! properties (merge order, override-then-show round trip, last override wins, unknown keys).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use proptest::prelude::*;

use super::*;
use crate::env::EnvError;
use crate::error::{PolicyError, RunError};
use crate::registry::{AlgorithmEntry, EnvEntry};
use crate::value::{ParamKind, ParamSpec, Value};

/// A registry with two dummy environments and two dummy algorithms; nothing can be built from it,
/// only configs checked against it.
fn registry() -> Registry {
    let mut reg = Registry::new();
    let env = |id: &str, params: Vec<ParamSpec>| EnvEntry {
        id: id.into(),
        domain: "test".into(),
        summary: "dummy".into(),
        params,
        make: Arc::new(|_| Err(EnvError::Backend("the test registry builds nothing".into()))),
    };
    reg.register_env(env(
        "Dummy-v0",
        vec![
            ParamSpec::new("size", ParamKind::Int, Value::Int(4), "grid size"),
            ParamSpec::new("noise", ParamKind::Float, Value::Float(0.1), "noise"),
            ParamSpec::new(
                "mode",
                ParamKind::Choice(&["easy", "hard"]),
                Value::Str("easy".into()),
                "mode",
            ),
            ParamSpec::new("layout", ParamKind::Path, Value::Null, "optional file"),
        ],
    ));
    reg.register_env(env(
        "Dummy-v1",
        vec![ParamSpec::new(
            "difficulty",
            ParamKind::Int,
            Value::Int(1),
            "difficulty",
        )],
    ));
    let algo = |name: &str, params: Vec<ParamSpec>| AlgorithmEntry {
        name: name.into(),
        summary: "dummy".into(),
        params,
        make: Arc::new(|_| {
            Err(RunError::InvalidHyperparameter {
                name: "any".into(),
                reason: "the test registry builds nothing".into(),
            })
        }),
        load_policy: |_, _| {
            Err(PolicyError::BadCheckpoint(
                "the test registry loads nothing".into(),
            ))
        },
    };
    reg.register_algorithm(algo(
        "dummy_algo",
        vec![
            ParamSpec::new("learning_rate", ParamKind::Float, Value::Float(3e-4), "lr"),
            ParamSpec::new(
                "hidden",
                ParamKind::IntList,
                Value::List(vec![Value::Int(64), Value::Int(64)]),
                "layer sizes",
            ),
            ParamSpec::new("use_gae", ParamKind::Bool, Value::Bool(true), "gae"),
            ParamSpec::new("clip", ParamKind::Float, Value::Float(0.2), "clip"),
        ],
    ));
    reg.register_algorithm(algo(
        "other_algo",
        vec![ParamSpec::new(
            "epsilon",
            ParamKind::Float,
            Value::Float(0.1),
            "eps",
        )],
    ));
    reg
}

const FULL: &str = r#"// a complete experiment
(
    name: "full",
    env: (id: "Dummy-v0", size: 8, mode: "hard"),
    algorithm: (name: "dummy_algo", learning_rate: 1e-3, hidden: [32, 16],),
    seeds: [0, 1, 2],
    training: (total_env_steps: 100_000, num_envs: 2),
    /* block /* nested */ comment */
    metrics: (energy_method: "estimate"),
)
"#;

fn sets(list: &[&str]) -> Vec<Override> {
    list.iter()
        .map(|s| Override::parse(s).unwrap_or_else(|e| panic!("{s}: {e}")))
        .collect()
}

fn load_text(text: &str, overrides: &[&str]) -> Result<Experiment, ConfigError> {
    load_str(text, Path::new("exp.ron"), &sets(overrides), &registry())
}

fn err_text(text: &str, overrides: &[&str]) -> String {
    match load_text(text, overrides) {
        Ok(exp) => panic!("expected an error, loaded {exp:?}"),
        Err(e) => e.to_string(),
    }
}

/// Writes `files` (name, text) into a fresh temporary directory.
fn write_files(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        let path = dir.path().join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    dir
}

/// Follows a dotted path through [`Experiment::to_value`].
fn lookup(exp: &Experiment, path: &str) -> Value {
    let mut v = exp.to_value();
    for part in path.split('.') {
        v = match v {
            Value::Map(mut m) => m.remove(part).unwrap_or(Value::Null),
            _ => Value::Null,
        };
    }
    v
}

// ---------------------------------------------------------------- syntax

#[test]
fn parses_every_value_form_with_locations() {
    let text = "(\n  a: 1, b: -2.5e-3, c: true, d: None, e: Some(3),\n  f: \"x\\\"y\\u{e9}\\n\", g: r#\"raw \"q\"\"#,\n  h: [1, [2,], ], i: {\"k\": (z: inf)}, j: -inf, k: (),\n)";
    let node = parse_str(text, Path::new("t.ron")).unwrap();
    let v = node.to_value();
    let Value::Map(m) = v else { panic!() };
    assert_eq!(m["a"], Value::Int(1));
    assert_eq!(m["b"], Value::Float(-2.5e-3));
    assert_eq!(m["c"], Value::Bool(true));
    assert_eq!(m["d"], Value::Null);
    assert_eq!(m["e"], Value::Int(3));
    assert_eq!(m["f"], Value::Str("x\"y\u{e9}\n".into()));
    assert_eq!(m["g"], Value::Str("raw \"q\"".into()));
    assert_eq!(
        m["h"],
        Value::List(vec![Value::Int(1), Value::List(vec![Value::Int(2)])])
    );
    assert_eq!(m["j"], Value::Float(f64::NEG_INFINITY));
    assert_eq!(m["k"], Value::Map(Default::default()));
    let f = node.field("f").unwrap();
    assert_eq!(f.key_location.to_string(), "t.ron:3:3");
    assert_eq!(f.value.location.to_string(), "t.ron:3:6");
}

#[test]
fn syntax_errors_name_file_line_and_column() {
    let cases = [
        (
            "(a: 1,\n b: \"open)",
            "exp.ron:2:5: syntax error: unterminated string",
        ),
        (
            "(a: 1\n b: 2)",
            "exp.ron:2:2: syntax error: expected `,` or `)`, found `b`",
        ),
        (
            "(a 1)",
            "exp.ron:1:4: syntax error: expected `:`, found `1`",
        ),
        (
            "(a: ppo)",
            "exp.ron:1:5: syntax error: unexpected identifier `ppo`",
        ),
        ("(a: (1, 2))", "exp.ron:1:6: syntax error: expected a key"),
        (
            "(a: 99999999999999999999)",
            "exp.ron:1:5: syntax error: integer `99999999999999999999` out of range",
        ),
        (
            "(a: 1) x",
            "exp.ron:1:8: syntax error: unexpected `x` after the value",
        ),
        (
            "/* never closed\n(a: 1)",
            "exp.ron:1:1: syntax error: unterminated `/*` comment",
        ),
        (
            "(a: 12ab)",
            "exp.ron:1:7: syntax error: unexpected `a` in number",
        ),
        (
            "(a: \"\\q\")",
            "exp.ron:1:6: syntax error: unknown escape `\\q`",
        ),
        (
            "",
            "exp.ron:1:1: syntax error: expected a value, found end of input",
        ),
    ];
    for (text, want) in cases {
        let got = err_text(text, &[]);
        assert!(
            got.starts_with(want),
            "{text:?}: got {got:?}, want prefix {want:?}"
        );
    }
}

#[test]
fn crlf_line_endings_and_a_byte_order_mark_are_fine() {
    let got = err_text("\u{feff}(\r\n  seeds: [1],\r\n  sedz: 1,\r\n)", &[]);
    assert!(got.starts_with("exp.ron:3:3: unknown key `sedz`"), "{got}");
}

#[test]
fn deep_nesting_is_an_error_not_a_stack_overflow() {
    let text = format!("(a: {}{})", "[".repeat(10_000), "]".repeat(10_000));
    let got = err_text(&text, &[]);
    assert!(got.contains("nested more than"), "{got}");
}

#[test]
fn duplicate_keys_are_rejected_with_both_locations() {
    let got = err_text("(\n  seeds: [1],\n  seeds: [2],\n)", &[]);
    assert_eq!(
        got,
        "exp.ron:3:3: duplicate key `seeds` (first set at exp.ron:2:3)"
    );
}

// ---------------------------------------------------------------- resolution

#[test]
fn full_experiment_resolves_with_defaults_filled_in() {
    let exp = load_text(FULL, &[]).unwrap();
    assert_eq!(exp.name, "full");
    let env = exp.require_env().unwrap();
    assert_eq!(env.id, "Dummy-v0");
    assert_eq!(env.params.i64("size").unwrap(), 8);
    assert_eq!(env.params.f64("noise").unwrap(), 0.1);
    assert_eq!(env.params.str("mode").unwrap(), "hard");
    assert_eq!(env.params.values()["layout"], Value::Null);
    let alg = exp.require_algorithm().unwrap();
    assert_eq!(alg.params.f64("learning_rate").unwrap(), 1e-3);
    assert_eq!(
        alg.params.values()["hidden"],
        Value::List(vec![Value::Int(32), Value::Int(16)])
    );
    assert!(alg.params.bool("use_gae").unwrap());
    assert_eq!(exp.seeds, [0, 1, 2]);
    assert_eq!(exp.training.total_env_steps, 100_000);
    assert_eq!(exp.training.num_envs, 2);
    assert_eq!(
        exp.training.eval_episodes,
        crate::TrainingSettings::default().eval_episodes
    );
    assert_eq!(exp.metrics.energy_method, EnergyMethod::Estimate);
    assert_eq!(exp.metrics.bootstrap_reps, 50_000);
    assert_eq!(
        exp.inference.observation_source,
        ObservationSource::Rollouts
    );
    assert_eq!(exp.output.dir, PathBuf::from("results"));
}

#[test]
fn empty_config_is_all_defaults_and_named_after_the_file() {
    let exp = load_text("()", &[]).unwrap();
    assert_eq!(exp.name, "exp");
    assert_eq!(exp.env, None);
    assert_eq!(exp.seeds, [0]);
    assert_eq!(
        exp.require_env().unwrap_err().to_string(),
        "experiment `exp` has no `env` section: add `env: (id: \"...\")` naming a registered environment (`a2perf list`)"
    );
    assert!(
        exp.require_algorithm()
            .unwrap_err()
            .to_string()
            .contains("`algorithm`")
    );
}

#[test]
fn operative_config_lists_every_value() {
    let text = load_text(FULL, &[]).unwrap().to_ron_string();
    for needle in [
        "name: \"full\"",
        "id: \"Dummy-v0\"",
        "noise: 0.1",
        "layout: None",
        "learning_rate: 0.001",
        "clip: 0.2",
        "hidden: [32, 16]",
        "seeds: [0, 1, 2]",
        "eval_interval: 1000",
        "timing_samples: 1000",
        "carbon_intensity_g_per_kwh: 475.0",
        "reliability_definition: \"a2perf\"",
        "dir: \"results\"",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in\n{text}");
    }
}

#[test]
fn write_operative_writes_a_file_that_loads_back() {
    let dir = tempfile::tempdir().unwrap();
    let exp = load_text(FULL, &["algorithm.clip=0.3"]).unwrap();
    let path = exp.write_operative(&dir.path().join("run")).unwrap();
    assert_eq!(path.file_name().unwrap(), OPERATIVE_CONFIG_FILE);
    let again = load(&path, &[], &registry()).unwrap();
    assert_eq!(again, exp);
}

#[test]
fn overrides_are_typed_and_accept_bare_strings() {
    let exp = load_text(
        FULL,
        &[
            "algorithm.learning_rate=1e-4",
            "env.size=5",
            "seeds=[0,1]",
            "env.mode=easy",
            "env.layout=\"a b.txt\"",
            "name=renamed run",
            "training=(eval_interval: 7)",
            "algorithm.learning_rate=2",
        ],
    )
    .unwrap();
    let alg = exp.require_algorithm().unwrap();
    assert_eq!(alg.params.f64("learning_rate").unwrap(), 2.0);
    let env = exp.require_env().unwrap();
    assert_eq!(env.params.i64("size").unwrap(), 5);
    assert_eq!(env.params.str("mode").unwrap(), "easy");
    assert_eq!(env.params.str("layout").unwrap(), "a b.txt");
    assert_eq!(exp.seeds, [0, 1]);
    assert_eq!(exp.name, "renamed run");
    assert_eq!(exp.training.eval_interval, 7);
    assert_eq!(
        exp.training.num_envs, 2,
        "struct overrides merge, not replace"
    );
}

#[test]
fn switching_algorithm_drops_the_old_hyperparameters() {
    let exp = load_text(FULL, &["algorithm.name=other_algo"]).unwrap();
    let alg = exp.require_algorithm().unwrap();
    assert_eq!(alg.name, "other_algo");
    assert_eq!(alg.params.f64("epsilon").unwrap(), 0.1);
    // Setting a hyperparameter of the new algorithm works in either order.
    for order in [
        ["algorithm.epsilon=0.5", "algorithm.name=other_algo"],
        ["algorithm.name=other_algo", "algorithm.epsilon=0.5"],
    ] {
        let exp = load_text(FULL, &order).unwrap();
        assert_eq!(
            exp.require_algorithm()
                .unwrap()
                .params
                .f64("epsilon")
                .unwrap(),
            0.5
        );
    }
    let exp = load_text(FULL, &["env.id=Dummy-v1", "env.difficulty=3"]).unwrap();
    assert_eq!(
        exp.require_env().unwrap().params.i64("difficulty").unwrap(),
        3
    );
}

// ---------------------------------------------------------------- includes

#[test]
fn includes_merge_in_order_and_the_including_file_wins() {
    let dir = write_files(&[
        (
            "base.ron",
            "(seeds: [9], training: (num_envs: 2, eval_interval: 10), env: (id: \"Dummy-v0\", size: 3))",
        ),
        ("more.ron", "(training: (num_envs: 3), env: (noise: 0.5))"),
        (
            "sub/exp.ron",
            "(include: [\"../base.ron\", \"../more.ron\"], training: (eval_interval: 20))",
        ),
    ]);
    let exp = load(&dir.path().join("sub/exp.ron"), &[], &registry()).unwrap();
    assert_eq!(exp.seeds, [9]);
    assert_eq!(exp.training.num_envs, 3);
    assert_eq!(exp.training.eval_interval, 20);
    let env = exp.require_env().unwrap();
    assert_eq!(
        (
            env.params.i64("size").unwrap(),
            env.params.f64("noise").unwrap()
        ),
        (3, 0.5)
    );
}

#[test]
fn diamond_includes_are_not_cycles() {
    let dir = write_files(&[
        ("root.ron", "(seeds: [1])"),
        ("a.ron", "(include: [\"root.ron\"])"),
        ("b.ron", "(include: [\"root.ron\"])"),
        ("top.ron", "(include: [\"a.ron\", \"b.ron\"])"),
    ]);
    assert_eq!(
        load(&dir.path().join("top.ron"), &[], &registry())
            .unwrap()
            .seeds,
        [1]
    );
}

#[test]
fn errors_in_included_files_point_into_them() {
    let dir = write_files(&[
        ("base.ron", "(\n  training: (num_env: 2),\n)"),
        ("exp.ron", "(include: [\"base.ron\"])"),
    ]);
    let err = load(&dir.path().join("exp.ron"), &[], &registry()).unwrap_err();
    let base = dir.path().join("base.ron");
    assert_eq!(
        err.to_string(),
        format!(
            "{}:2:14: unknown key `training.num_env` (did you mean `num_envs`?)",
            base.display()
        )
    );
}

#[test]
fn missing_include_names_the_include_and_the_chain() {
    let dir = write_files(&[
        ("exp.ron", "(include: [\"mid.ron\"])"),
        ("mid.ron", "(\n  include: [\"nope.ron\"],\n)"),
    ]);
    let err = load(&dir.path().join("exp.ron"), &[], &registry()).unwrap_err();
    assert!(matches!(err, ConfigError::Read { .. }));
    let msg = err.to_string();
    let mid = dir.path().join("mid.ron").display().to_string();
    let nope = dir.path().join("nope.ron").display().to_string();
    assert!(
        msg.starts_with(&format!("{mid}:2:13: include: cannot read `{nope}`")),
        "{msg}"
    );
    assert!(
        msg.contains("include chain:") && msg.contains("exp.ron` -> "),
        "{msg}"
    );
}

#[test]
fn missing_top_level_file_names_it() {
    let err = load(Path::new("/no/such/dir/exp.ron"), &[], &registry()).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("cannot read `/no/such/dir/exp.ron`"),
        "{err}"
    );
}

#[test]
fn include_cycles_name_the_chain_and_the_include() {
    let dir = write_files(&[
        ("a.ron", "(include: [\"b.ron\"])"),
        ("b.ron", "(seeds: [1],\n include: [\"./a.ron\"])"),
    ]);
    let err = load(&dir.path().join("a.ron"), &[], &registry()).unwrap_err();
    let a = dir.path().join("a.ron").display().to_string();
    let b = dir.path().join("b.ron").display().to_string();
    assert_eq!(
        err.to_string(),
        format!("{b}:2:12: include cycle: `{a}` -> `{b}` -> `{a}`")
    );
    let selfie = write_files(&[("s.ron", "(include: [\"s.ron\"])")]);
    let err = load(&selfie.path().join("s.ron"), &[], &registry()).unwrap_err();
    assert!(matches!(err, ConfigError::IncludeCycle { .. }), "{err}");
}

#[test]
fn include_must_be_a_list_of_strings() {
    let got = err_text("(include: \"base.ron\")", &[]);
    assert!(
        got.starts_with("exp.ron:1:11: `include`: expected a list of file paths"),
        "{got}"
    );
    let got = err_text("(include: [1])", &[]);
    assert!(
        got.starts_with("exp.ron:1:12: `include`: expected a list"),
        "{got}"
    );
}

// ---------------------------------------------------------------- error kinds

#[test]
fn unknown_keys_in_files_name_key_location_and_suggestion() {
    let cases = [
        (
            "(\n  seds: [1],\n)",
            "exp.ron:2:3: unknown key `seds` (did you mean `seeds`?)",
        ),
        (
            "(training: (total_env_step: 5))",
            "exp.ron:1:13: unknown key `training.total_env_step` (did you mean `total_env_steps`?)",
        ),
        (
            "(env: (id: \"Dummy-v0\", sise: 5))",
            "exp.ron:1:24: unknown key `env.sise` (did you mean `size`?)",
        ),
        (
            "(algorithm: (name: \"dummy_algo\",\n   lerning_rate: 0.1))",
            "exp.ron:2:4: unknown key `algorithm.lerning_rate` (did you mean `learning_rate`?)",
        ),
        (
            "(metrics: (zzz: 1))",
            "exp.ron:1:12: unknown key `metrics.zzz`; known keys: `ram_sample_interval_s`",
        ),
    ];
    for (text, want) in cases {
        let got = err_text(text, &[]);
        assert!(got.starts_with(want), "got {got:?}, want prefix {want:?}");
    }
}

#[test]
fn unknown_keys_in_overrides_name_the_override() {
    let got = err_text(FULL, &["no_such_key=1"]);
    assert!(
        got.starts_with("--set no_such_key=1: unknown key `no_such_key`"),
        "{got}"
    );
    let got = err_text(FULL, &["algorithm.learning_rat=1e-4"]);
    assert_eq!(
        got,
        "--set algorithm.learning_rat=1e-4: unknown key `algorithm.learning_rat` (did you mean `learning_rate`?)"
    );
}

#[test]
fn wrong_types_name_key_location_and_types() {
    let cases: [(&str, &[&str], &str); 9] = [
        (
            "(training: (num_envs: \"four\"))",
            &[],
            "exp.ron:1:23: `training.num_envs`: expected integer, found string",
        ),
        (
            "(seeds: 3)",
            &[],
            "exp.ron:1:9: `seeds`: expected a list of integers",
        ),
        (
            "(seeds: [1, 2.5])",
            &[],
            "exp.ron:1:13: `seeds`: expected a list of integers",
        ),
        (
            "(training: 5)",
            &[],
            "exp.ron:1:12: `training`: expected a struct",
        ),
        (
            "(env: (id: \"Dummy-v0\", size: 2.5))",
            &[],
            "exp.ron:1:30: `env.size`: expected integer, found float `2.5`",
        ),
        (
            FULL,
            &["algorithm.use_gae=3"],
            "--set algorithm.use_gae=3: `algorithm.use_gae`: expected bool, found integer",
        ),
        (
            FULL,
            &["training.num_envs=4x"],
            "--set training.num_envs=4x: `training.num_envs`: expected integer, found string",
        ),
        (
            FULL,
            &["name=true"],
            "--set name=true: `name`: expected string, found bool",
        ),
        (
            FULL,
            &["env.mode=har"],
            "--set env.mode=har: `env.mode`: `har` is not one of easy, hard (did you mean `hard`?)",
        ),
    ];
    for (text, overrides, want) in cases {
        let got = err_text(text, overrides);
        assert!(got.starts_with(want), "got {got:?}, want prefix {want:?}");
    }
    let got = err_text(FULL, &["output.dir=3"]);
    assert!(got.contains("quote it"), "{got}");
    let got = err_text("(training: (num_envs: None))", &[]);
    assert!(
        got.starts_with("exp.ron:1:23: `training.num_envs`: expected integer, found none"),
        "{got}"
    );
}

#[test]
fn invalid_values_name_key_and_location() {
    let cases = [
        (
            "(seeds: [1, -2])",
            "exp.ron:1:13: `seeds`: seeds are non-negative",
        ),
        (
            "(seeds: [1, 1])",
            "exp.ron:1:13: `seeds`: seed `1` is listed twice",
        ),
        ("(seeds: [])", "exp.ron:1:9: `seeds`: at least one seed"),
        (
            "(training: (num_envs: 0))",
            "exp.ron:1:23: `training.num_envs`: expected an integer >= 1",
        ),
        (
            "(inference: (rollouts: -1))",
            "exp.ron:1:24: `inference.rollouts`: expected an integer >= 0",
        ),
        (
            "(metrics: (ram_sample_interval_s: 0))",
            "exp.ron:1:35: `metrics.ram_sample_interval_s`: expected a finite number > 0",
        ),
        (
            "(name: \" \")",
            "exp.ron:1:8: `name`: the name must not be empty",
        ),
        (
            "(env: (id: \"Dumy-v0\"))",
            "exp.ron:1:12: `env.id`: unknown environment `Dumy-v0` (did you mean `Dummy-v0`?)",
        ),
        (
            "(algorithm: (name: \"dumy_algo\"))",
            "exp.ron:1:20: `algorithm.name`: unknown algorithm `dumy_algo` (did you mean `dummy_algo`?)",
        ),
    ];
    for (text, want) in cases {
        let got = err_text(text, &[]);
        assert!(got.starts_with(want), "got {got:?}, want prefix {want:?}");
    }
}

#[test]
fn missing_env_id_is_named() {
    let got = err_text("(\n env: (size: 3),\n)", &[]);
    assert_eq!(
        got,
        "exp.ron:2:7: missing key `env.id`: the env section must name the registered environment"
    );
    let got = err_text("(algorithm: (learning_rate: 3e-4))", &[]);
    assert!(
        got.starts_with("exp.ron:1:13: missing key `algorithm.name`"),
        "{got}"
    );
}

#[test]
fn malformed_overrides_are_rejected() {
    for (text, want) in [
        ("seeds", "--set seeds: expected `dotted.path=value`"),
        ("=1", "--set =1: the key must be a dotted path"),
        ("a..b=1", "--set a..b=1: the key must be a dotted path"),
        ("seeds=", "--set seeds=: missing value"),
        (
            "include=[\"x.ron\"]",
            "--set include=[\"x.ron\"]: `include` can only be used in files",
        ),
        (
            "seeds=[1, 2",
            "--set seeds=[1, 2: syntax error: unterminated list",
        ),
    ] {
        let got = Override::parse(text).unwrap_err().to_string();
        assert!(got.starts_with(want), "got {got:?}, want prefix {want:?}");
    }
}

#[test]
fn top_level_must_be_a_struct() {
    let got = err_text("[1, 2]", &[]);
    assert!(
        got.starts_with("exp.ron:1:1: `(top level)`: an experiment file is a struct"),
        "{got}"
    );
}

#[test]
fn errors_expose_key_and_location() {
    let err = load_text(FULL, &["training.nope=1"]).unwrap_err();
    assert_eq!(err.key(), Some("training.nope"));
    assert_eq!(
        err.location(),
        Some(&Location::Override(Arc::from("training.nope=1")))
    );
}

// ---------------------------------------------------------------- profiles and suites

const PROFILED: &str = r#"(
    profile: (
        name: "orig",
        env: {
            "test": (noise: 0, difficulty: 3),
            "Dummy-v0": (mode: "hard"),
        },
        generalization: {
            "test": [
                (env: "Dummy-v0", params: (size: 2)),
                (env: "Dummy-v1", name: "hardest", params: {"difficulty": 9}),
            ],
        },
    ),
    env: (id: "Dummy-v0", size: 6),
)"#;

#[test]
fn a_profile_fills_in_unset_parameters_and_records_its_switches() {
    let exp = load_text(PROFILED, &[]).unwrap();
    let env = exp.require_env().unwrap();
    // Domain switches apply where the environment declares the parameter (not `difficulty`),
    // id switches on top; the int `0` is a float for the float parameter `noise`.
    assert_eq!(env.params.get("noise"), Some(&Value::Float(0.0)));
    assert_eq!(env.params.get("mode"), Some(&Value::Str("hard".into())));
    assert_eq!(env.params.get("size"), Some(&Value::Int(6)));
    assert_eq!(
        env.profile_switches,
        [
            ("mode".to_string(), Value::Str("hard".into())),
            ("noise".to_string(), Value::Float(0.0)),
        ]
        .into()
    );
    let profile = exp.profile.as_ref().unwrap();
    assert_eq!(profile.name, "orig");
    let suite = &profile.generalization["test"];
    assert_eq!(
        suite.iter().map(|t| t.name.as_str()).collect::<Vec<_>>(),
        ["Dummy-v0[size=2]", "hardest"]
    );
    assert_eq!(suite[1].params["difficulty"], Value::Int(9));

    // A layer that sets a switched parameter wins; the switch stays recorded, so a pipeline can
    // tell it was overridden.
    let exp = load_text(PROFILED, &["env.mode=easy"]).unwrap();
    let env = exp.require_env().unwrap();
    assert_eq!(env.params.get("mode"), Some(&Value::Str("easy".into())));
    assert_eq!(env.profile_switches["mode"], Value::Str("hard".into()));

    // Switching to another environment of the domain takes the domain's switches it declares.
    let exp = load_text(PROFILED, &["env.id=Dummy-v1"]).unwrap();
    let env = exp.require_env().unwrap();
    assert_eq!(env.params.get("difficulty"), Some(&Value::Int(3)));
}

// An unset variable no test sets: its default is taken; the error names it without one.
const UNSET_VAR: &str = "A2PERF_CONFIG_TEST_SURELY_UNSET_1";

#[test]
fn string_values_expand_environment_variables_in_every_section() {
    // Cargo sets CARGO_MANIFEST_DIR for the test process; reading it avoids `set_var`, which is
    // unsound while other test threads read the environment.
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap();
    assert!(
        std::env::var(UNSET_VAR).is_err(),
        "{UNSET_VAR} must not be set"
    );
    let text = format!(
        r#"(
    profile: (
        name: "p",
        env: {{"Dummy-v0": (layout: "${{{UNSET_VAR}:-/fallback}}/switch.txt")}},
        generalization: {{"test": [(env: "Dummy-v0", name: "g", params: (layout: "${{CARGO_MANIFEST_DIR}}/g.txt"))]}},
    ),
    env: (id: "Dummy-v0"),
    generalization: (tasks: [(env: "Dummy-v0", name: "own", params: (layout: "$${{literal}}/${{CARGO_MANIFEST_DIR}}"))]),
    output: (dir: "${{{UNSET_VAR}:-out}}/results"),
)"#
    );
    let exp = load_text(&text, &[]).unwrap();
    let env = exp.require_env().unwrap();
    assert_eq!(
        env.params.get("layout"),
        Some(&Value::Str("/fallback/switch.txt".into()))
    );
    assert_eq!(
        env.profile_switches["layout"],
        Value::Str("/fallback/switch.txt".into())
    );
    let profile = exp.profile.as_ref().unwrap();
    assert_eq!(
        profile.generalization["test"][0].params["layout"],
        Value::Str(format!("{manifest}/g.txt"))
    );
    let own = exp.generalization.tasks.as_ref().unwrap();
    assert_eq!(
        own[0].params["layout"],
        Value::Str(format!("${{literal}}/{manifest}"))
    );
    assert_eq!(exp.output.dir, PathBuf::from("out/results"));

    // `--set` values expand too, and every string, not only paths.
    let exp = load_text(
        &text,
        &[
            "env.layout=${CARGO_MANIFEST_DIR}/set.txt",
            &format!("name=run_${{{UNSET_VAR}:-x}}"),
        ],
    )
    .unwrap();
    assert_eq!(
        exp.require_env().unwrap().params.get("layout"),
        Some(&Value::Str(format!("{manifest}/set.txt")))
    );
    assert_eq!(exp.name, "run_x");

    // The operative config holds the expanded paths, so it loads back to the same experiment
    // whatever the environment is later.
    let exp = load_text(&text, &[]).unwrap();
    let operative = exp.to_ron_string();
    assert!(
        !operative.contains("CARGO_MANIFEST_DIR") && !operative.contains(UNSET_VAR),
        "{operative}"
    );
    assert!(operative.contains("/fallback/switch.txt"), "{operative}");
    // A literal `${` in a value is written escaped, so it stays literal when loaded again.
    assert!(operative.contains("$${literal}"), "{operative}");
    let again = load_str(
        &operative,
        Path::new("operative_config.ron"),
        &[],
        &registry(),
    )
    .unwrap();
    assert_eq!(again, exp);
}

#[test]
fn an_unset_variable_without_a_default_names_the_variable_key_and_place() {
    let err = err_text(
        &format!("(env: (id: \"Dummy-v0\",\n  layout: \"${{{UNSET_VAR}}}/netlist.pb.txt\"))"),
        &[],
    );
    assert_eq!(
        err,
        format!(
            "exp.ron:2:11: `env.layout`: environment variable `{UNSET_VAR}` is not set (set it, \
             or give a default: `${{{UNSET_VAR}:-DEFAULT}}`)"
        )
    );
    let err = err_text(
        r#"(env: (id: "Dummy-v0"))"#,
        &[&format!("env.layout=${{{UNSET_VAR}}}/x")],
    );
    assert!(
        err.starts_with(&format!(
            "--set env.layout=${{{UNSET_VAR}}}/x: `env.layout`: environment variable `{UNSET_VAR}`"
        )),
        "{err}"
    );
    let err = err_text(
        &format!(r#"(profile: (name: "p", env: {{"test": (layout: "${{{UNSET_VAR}}}")}}))"#),
        &[],
    );
    assert!(
        err.contains("`profile.env.test.layout`") && err.contains(UNSET_VAR),
        "{err}"
    );
    let err = err_text(r#"(env: (id: "Dummy-v0", layout: "${oops"))"#, &[]);
    assert!(
        err.contains("`env.layout`") && err.contains("without a closing"),
        "{err}"
    );
}

#[test]
fn a_profile_is_a_name_or_a_struct_and_can_be_dropped_by_a_later_layer() {
    let exp = load_text(r#"(profile: "orig", env: (id: "Dummy-v0"))"#, &[]).unwrap();
    assert_eq!(exp.profile.as_ref().unwrap().name, "orig");
    assert!(exp.require_env().unwrap().profile_switches.is_empty());
    let exp = load_text(PROFILED, &["profile=None"]).unwrap();
    assert!(exp.profile.is_none());
    assert_eq!(
        exp.require_env().unwrap().params.get("mode"),
        Some(&Value::Str("easy".into()))
    );
    let dir = write_files(&[
        ("profile.ron", PROFILED),
        (
            "exp.ron",
            r#"(include: ["profile.ron"], env: (size: 3), seeds: [1])"#,
        ),
    ]);
    let exp = load(&dir.path().join("exp.ron"), &[], &registry()).unwrap();
    assert_eq!(exp.profile.as_ref().unwrap().name, "orig");
    assert_eq!(
        exp.require_env().unwrap().params.get("mode"),
        Some(&Value::Str("hard".into()))
    );
}

#[test]
fn profiles_and_suites_round_trip_through_the_operative_config() {
    for overrides in [
        &[][..],
        &["generalization.tasks=[(env: \"Dummy-v1\", params: (difficulty: 2))]"][..],
        &[
            "env.noise=0.5",
            "profile.env={\"Dummy-v1\": (difficulty: 4)}",
        ][..],
    ] {
        let exp = load_text(PROFILED, overrides).unwrap();
        let text = exp.to_ron_string();
        assert!(
            text.contains("    profile: (\n        name: \"orig\",\n"),
            "{text}"
        );
        let again = load_str(&text, Path::new("operative_config.ron"), &[], &registry())
            .unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(again, exp, "{text}");
        assert_eq!(again.to_ron_string(), text);
    }
}

#[test]
fn a_config_lists_its_own_generalization_suite() {
    let exp = load_text(
        r#"(env: (id: "Dummy-v0"), generalization: (episodes: 3, tasks: [
            (env: "Dummy-v0", name: "small", params: (size: 1, mode: "hard")),
            (env: "Dummy-v1"),
        ]))"#,
        &[],
    )
    .unwrap();
    let tasks = exp.generalization.tasks.as_ref().unwrap();
    assert_eq!(exp.generalization.episodes, 3);
    assert_eq!(
        tasks
            .iter()
            .map(|t| (t.name.as_str(), t.env_id.as_str()))
            .collect::<Vec<_>>(),
        [("small", "Dummy-v0"), ("Dummy-v1", "Dummy-v1")]
    );
    assert_eq!(tasks[0].params["mode"], Value::Str("hard".into()));
    assert!(load_text(FULL, &[]).unwrap().generalization.tasks.is_none());
}

#[test]
fn bad_profiles_and_suites_name_the_key_and_the_problem() {
    let cases: [(&str, &[&str], &str); 11] = [
        (
            r#"(profile: (env: {}))"#,
            &[],
            "exp.ron:1:11: missing key `profile.name`",
        ),
        (
            r#"(profile: (name: "p", envs: {}))"#,
            &[],
            "exp.ron:1:23: unknown key `profile.envs` (did you mean `env`?)",
        ),
        (
            r#"(profile: 3)"#,
            &[],
            "exp.ron:1:11: `profile`: expected a name",
        ),
        (
            r#"(profile: (name: "p", env: {"tesst": (size: 1)}))"#,
            &[],
            "exp.ron:1:29: `profile.env.tesst`: `tesst` is neither a registered domain nor an environment id (did you mean `test`?)",
        ),
        (
            r#"(profile: (name: "p", env: {"test": (sise: 1)}))"#,
            &[],
            "exp.ron:1:38: unknown key `profile.env.test.sise` (did you mean `size`?)",
        ),
        (
            r#"(profile: (name: "p", env: {"Dummy-v1": (size: 1)}))"#,
            &[],
            "unknown key `profile.env.Dummy-v1.size`; known keys: `difficulty`",
        ),
        (
            r#"(profile: (name: "p", env: {"test": (mode: "medium")}))"#,
            &[],
            "`profile.env.test.mode`: `medium` is not one of easy, hard",
        ),
        (
            r#"(profile: (name: "p", generalization: {"test": []}))"#,
            &[],
            "`profile.generalization.test`: a generalization suite needs at least one task",
        ),
        (
            r#"(generalization: (tasks: [(env: "Dummy-v0"), (env: "Dummy-v0")]))"#,
            &[],
            "`generalization.tasks[1]`: task name `Dummy-v0` is listed twice",
        ),
        (
            r#"(generalization: (tasks: [(env: "Dumy-v0")]))"#,
            &[],
            "`generalization.tasks[0].env`: unknown environment `Dumy-v0` (did you mean `Dummy-v0`?)",
        ),
        (
            r#"(generalization: (tasks: [(env: "Dummy-v0", params: (size: "big"))]))"#,
            &[],
            "`generalization.tasks[0].params.size`: expected integer, found string",
        ),
    ];
    for (text, overrides, expected) in cases {
        let err = err_text(text, overrides);
        assert!(
            err.contains(expected),
            "{text}\n got: {err}\nwant: {expected}"
        );
    }
    // A profile's suite for a domain must hold that domain's environments.
    let mut reg = registry();
    let mut other = reg.env("Dummy-v1").unwrap().clone();
    other.id = "Other-v0".into();
    other.domain = "other".into();
    reg.register_env(other);
    let err = load_str(
        r#"(profile: (name: "p", generalization: {"test": [(env: "Other-v0")]}))"#,
        Path::new("exp.ron"),
        &[],
        &reg,
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("`Other-v0` belongs to domain `other`, not `test`"),
        "{err}"
    );
}

// ---------------------------------------------------------------- properties

/// Keys the merge-order property sets, with a value generator each (all integers, so a layer's
/// value is recognisable).
const LAYER_KEYS: [&str; 6] = [
    "training.total_env_steps",
    "training.eval_interval",
    "training.num_envs",
    "generalization.episodes",
    "inference.rollouts",
    "env.size",
];

fn layer_text(layer: &[(usize, i64)], include: &[String]) -> String {
    let mut sections: std::collections::BTreeMap<&str, Vec<String>> = Default::default();
    for &(k, v) in layer {
        let (section, key) = LAYER_KEYS[k].split_once('.').unwrap();
        sections
            .entry(section)
            .or_default()
            .push(format!("{key}: {v}"));
    }
    let mut out = String::from("(\n");
    if !include.is_empty() {
        let list: Vec<String> = include.iter().map(|i| format!("{i:?}")).collect();
        out.push_str(&format!("  include: [{}],\n", list.join(", ")));
    }
    for (section, fields) in sections {
        let id = if section == "env" {
            "id: \"Dummy-v0\", "
        } else {
            ""
        };
        out.push_str(&format!("  {section}: ({id}{}),\n", fields.join(", ")));
    }
    out.push(')');
    out
}

fn layer() -> impl Strategy<Value = Vec<(usize, i64)>> {
    proptest::collection::btree_map(0..LAYER_KEYS.len(), 1i64..1_000_000, 0..4)
        .prop_map(|m| m.into_iter().collect())
}

/// Simple identifiers for unknown keys (filtered against the known ones in the test).
fn ident() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_]{0,12}"
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Includes merge in the order listed, the including file last, overrides after that: each
    /// key ends up with the value of the last layer that sets it, or its default.
    #[test]
    fn merge_order(
        includes in proptest::collection::vec(layer(), 0..4),
        top in layer(),
        over in layer(),
    ) {
        let names: Vec<String> = (0..includes.len()).map(|i| format!("inc{i}.ron")).collect();
        let mut files: Vec<(String, String)> = includes
            .iter()
            .zip(&names)
            .map(|(l, n)| (n.clone(), layer_text(l, &[])))
            .collect();
        files.push(("top.ron".into(), layer_text(&top, &names)));
        let refs: Vec<(&str, &str)> = files.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
        let dir = write_files(&refs);
        let overrides: Vec<Override> = over
            .iter()
            .map(|&(k, v)| Override::parse(&format!("{}={v}", LAYER_KEYS[k])).unwrap())
            .collect();
        // The env section needs an id even when only overrides mention it.
        let mut overrides = overrides;
        overrides.push(Override::parse("env.id=Dummy-v0").unwrap());
        let exp = load(&dir.path().join("top.ron"), &overrides, &registry()).unwrap();
        for (k, path) in LAYER_KEYS.iter().enumerate() {
            let expected = includes
                .iter()
                .chain([&top, &over])
                .filter_map(|l| l.iter().find(|(key, _)| *key == k).map(|(_, v)| *v))
                .next_back();
            let got = lookup(&exp, path);
            match expected {
                Some(v) => prop_assert_eq!(got, Value::Int(v), "{}", path),
                None => {
                    let (section, key) = path.split_once('.').unwrap();
                    let default = match section_schema(section) {
                        Some(specs) => specs.into_iter().find(|s| s.name == key).unwrap().default,
                        None => Value::Int(4), // Dummy-v0 `size`
                    };
                    prop_assert_eq!(got, default, "{}", path);
                }
            }
        }
    }

    /// Rendering the operative config and loading it again gives the same experiment, and
    /// rendering that gives the same text.
    #[test]
    fn override_then_show_round_trips(
        lr in proptest::num::f64::NORMAL | proptest::num::f64::ZERO,
        hidden in proptest::collection::vec(-5i64..5000, 0..4),
        use_gae in any::<bool>(),
        size in any::<i64>(),
        layout in proptest::option::of("[ -~\\t\\n\u{e9}\u{1F600}]{0,12}"),
        name in "[ -~\u{e9}]{0,8}[!-~]",
        seeds in proptest::collection::btree_set(0u64..(i64::MAX as u64), 1..4),
        steps in 1u64..(i64::MAX as u64),
        interval in 1e-9f64..1e9,
        source in prop_oneof![Just("rollouts"), Just("random")],
        switch_env in any::<bool>(),
    ) {
        let overrides = [
            format!("algorithm.learning_rate={}", experiment::ron_value(&Value::Float(lr))),
            format!("algorithm.hidden={}", experiment::ron_value(&Value::List(hidden.iter().map(|&h| Value::Int(h)).collect()))),
            format!("algorithm.use_gae={use_gae}"),
            format!("env.size={size}"),
            format!("env.layout={}", experiment::ron_value(&layout.clone().map_or(Value::Null, Value::Str))),
            format!("name={}", experiment::ron_value(&Value::Str(name.clone()))),
            format!("seeds={}", experiment::ron_value(&Value::List(seeds.iter().map(|&s| Value::Int(s as i64)).collect()))),
            format!("training.total_env_steps={steps}"),
            format!("metrics.ram_sample_interval_s={}", experiment::ron_value(&Value::Float(interval))),
            format!("inference.observation_source={source}"),
        ];
        let mut refs: Vec<&str> = overrides.iter().map(String::as_str).collect();
        if switch_env {
            refs.retain(|o| !o.starts_with("env."));
            refs.push("env.id=Dummy-v1");
        }
        let exp = load_text(FULL, &refs).unwrap();
        prop_assert_eq!(exp.require_algorithm().unwrap().params.f64("learning_rate").unwrap(), lr);
        prop_assert_eq!(&exp.name, &name);
        let text = exp.to_ron_string();
        let again = load_str(&text, Path::new("operative_config.ron"), &[], &registry()).unwrap();
        prop_assert_eq!(&again, &exp);
        prop_assert_eq!(again.to_ron_string(), text);
    }

    /// The parser returns an error, never panics, on any text (RON-like or not).
    #[test]
    fn parser_never_panics(
        ron_like in "[()\\[\\]{}:,\"a-zA-Z0-9_.+/*#' \n\\\\-]{0,80}",
        any_text in "\\PC{0,80}",
    ) {
        for text in [&ron_like, &any_text] {
            let _ = parse_str(text, Path::new("f.ron"));
            let _ = Override::parse(&format!("seeds={text}"));
        }
    }

    /// When a key is overridden twice, the last value is in force.
    #[test]
    fn overriding_twice_keeps_the_last(
        key in prop_oneof![
            Just("training.eval_episodes"),
            Just("generalization.episodes"),
            Just("env.size"),
            Just("metrics.bootstrap_reps"),
        ],
        first in 1i64..1_000_000,
        second in 1i64..1_000_000,
        between in proptest::option::of(Just("seeds=[5]")),
    ) {
        let a = format!("{key}={first}");
        let b = format!("{key}={second}");
        let mut list = vec![a.as_str()];
        list.extend(between);
        list.push(b.as_str());
        let exp = load_text(FULL, &list).unwrap();
        prop_assert_eq!(lookup(&exp, key), Value::Int(second));
    }

    /// A key that neither the schema nor the registry declares is rejected wherever it appears,
    /// and the error names it and where it was written.
    #[test]
    fn unknown_keys_are_always_rejected(
        section in prop_oneof![
            Just(""), Just("training"), Just("inference"), Just("generalization"),
            Just("metrics"), Just("output"), Just("env"), Just("algorithm"),
        ],
        key in ident(),
        via_override in any::<bool>(),
    ) {
        let known: Vec<String> = match section {
            "" => ["name", "profile", "env", "algorithm", "seeds", "training", "inference",
                   "generalization", "metrics", "output", "include"].map(String::from).to_vec(),
            "env" => ["id", "size", "noise", "mode", "layout"].map(String::from).to_vec(),
            "algorithm" => ["name", "learning_rate", "hidden", "use_gae", "clip"].map(String::from).to_vec(),
            // `generalization.tasks` is a list of structs, checked outside the flat schema.
            "generalization" => ["episodes", "tasks"].map(String::from).to_vec(),
            s => section_schema(s).unwrap().iter().map(|p| p.name.to_string()).collect(),
        };
        prop_assume!(!known.contains(&key));
        let dotted = if section.is_empty() { key.clone() } else { format!("{section}.{key}") };
        let err = if via_override {
            load_text(FULL, &[&format!("{dotted}=1")]).unwrap_err()
        } else {
            let text = if section.is_empty() {
                format!("(\n  {key}: 1,\n)")
            } else {
                let id = match section {
                    "env" => "id: \"Dummy-v0\", ",
                    "algorithm" => "name: \"dummy_algo\", ",
                    _ => "",
                };
                format!("(\n  {section}: ({id}{key}: 1),\n)")
            };
            load_text(&text, &[]).unwrap_err()
        };
        prop_assert!(matches!(err, ConfigError::UnknownKey { .. }), "{}", err);
        prop_assert_eq!(err.key(), Some(dotted.as_str()));
        let msg = err.to_string();
        prop_assert!(msg.contains(&format!("`{dotted}`")), "{}", msg);
        let location = if via_override { format!("--set {dotted}=1") } else { "exp.ron:2:".into() };
        prop_assert!(msg.starts_with(&location), "{}", msg);
    }
}

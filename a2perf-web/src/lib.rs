//! # a2perf-web
//!
//! A2Perf's web-navigation domain: generated gMiniWoB-style form websites that an agent fills in
//! from a user profile, with two backends that share one semantics:
//!
//! - [`Primitive`]: the 40 design primitives (24 active with a profile field, 16 passive, of
//!   which 8 are distractors that end the episode with −1) plus `#next_page#` / `#none#`;
//! - [`Design`], [`generate`], [`load_designs`]: A2Perf's seeded sampling process, its difficulty
//!   formula (`−ln(1/k!·(1 − passive/all) + 1e-8)` per page, summed) and level bins, a
//!   solvability check at generation (step budget, observation size) and the original design files;
//! - [`Website`]: the element tree of a design with one episode's random content, rendered as real
//!   HTML with a stylesheet that imposes a font-independent block layout;
//! - [`DomState`]: the dynamic DOM, the simulated backend's action semantics and its layout;
//! - [`ChromiumBackend`]: headless Chromium through chromedriver (W3C WebDriver over a keep-alive
//!   HTTP/1.1 client), pages served from an in-process 127.0.0.1 server, one round trip per step;
//!   Debian's `chromium-headless-shell` when installed (a lone environment under 200 MiB, see
//!   [`TreeMemory`] for how that is measured), else the full `chromium`;
//! - [`WebNavEnv`]: the environment, registered as `WebNavigation-Difficulty-0{1,2,3}-v0`.
//!
//! ## Observation and action contract
//!
//! With F profile fields (default 25), E elements (250) and T tokens (10); token ids are `int32`
//! (as in A2Perf), 0 = padding, 1 = out of vocabulary ([`VOCAB_SIZE`] ids); every other tensor is
//! `float32`:
//!
//! | tensor | shape | content |
//! |---|---|---|
//! | `profile_keys`, `profile_values` | [F, T] | int32 token ids; field 0: A2Perf's `_dummy` (key `_dummy`, no value); fields 1..: the profile, sorted by key |
//! | `profile_mask` | \[F\] | 1 = field present (`_dummy` always) |
//! | `dom_tokens` | [E, 5, T] | int32 token ids per visible element (document order): tag, value, text, placeholder, classes |
//! | `dom_features` | [E, 8] | focused, tampered (acted on), new (not visible before), is_div, x, y, w, h |
//! | `dom_mask` | \[E\] | 1 = element present |
//! | `time_step` | \[1\] | steps taken / step limit (A2Perf's `time_step`) |
//!
//! Geometry is divided by the largest right / bottom edge of the page, so it lies in [0, 1].
//! The action is `Discrete(E·F·2)`, flat index `(element·F + field)·2 + kind`, kind 0 = click,
//! 1 = type the field's profile value into the element ([`WebNavEnv::a2perf_action`] maps it to
//! the original's index). The action mask allows clicks only with field 0 (`_dummy`: the field
//! does not matter to a click) and typing only into inputs/selects with a present field ≥ 1.
//!
//! Reward per step: `ΔΦ − 0.05 − 0.5·[page unchanged]` while running, where Φ is the share of
//! fields that were acted on and hold their gold value; at submit `ΔΦ ± 1` (+1 iff every field is
//! correct); a distractor click gives `ΔΦ − 1` and ends the episode; 25 steps truncate.
//!
//! ## The original's behaviour, on request
//!
//! By default the environment corrects the original's bugs (the unselectable `cc` radio group,
//! unsolvable step budgets, shuffled level files, an empty placeholder slot, run-time vocabulary
//! growth, unseeded episode draws). Each difference that changes what an agent sees or gets has a
//! switch (an environment parameter) that reproduces A2Perf; [`WebNavConfig::a2perf`] turns them
//! all on:
//!
//! | parameter | default | A2Perf |
//! |---|---|---|
//! | `pool` (+ `designs`) | `generated`: solvable websites of the id's level | `a2perf`: the original's 0N.json as it is, drawn like numpy's `RandomState(seed)` |
//! | `cc_bug` | `false` | `true`: the `cc` radio group can never be selected |
//! | `duplicate_fields` | `false` | `true`: an active primitive repeated on a later page is rendered (inputs dead, radio groups working) |
//! | `placeholders` | `true` | `false`: the placeholder slot is always empty |
//! | `limit_terminates` | `false` | `true`: the step limit sets `terminated` too |
//! | `actions` | `masked` | `a2perf`: `visitGroup` semantics, the joint mask, the stale reward |
//!
//! ```
//! use a2perf_core::{Action, Env};
//! use a2perf_web::{WebNavConfig, WebNavEnv};
//! let mut env = WebNavEnv::new(WebNavConfig::new(1)).unwrap();
//! env.reset(Some(3)).unwrap();
//! let mut ret = 0.0;
//! while let Some(a) = env.oracle_action() {
//!     let step = env.step(&Action::Discrete(a)).unwrap();
//!     ret += step.reward;
//!     if step.done() {
//!         assert_eq!(step.info.get("success"), Some(1.0));
//!         break;
//!     }
//! }
//! assert!(ret > 1.0);
//! ```
//!
//! It does not reproduce the original's Bootstrap/jQuery look (pages are plain HTML with a
//! layout chosen so geometry is exact in both backends), its wall-clock episode timer or its
//! run-time vocabulary. It does not learn; agents live in `a2perf-baselines`.

#![warn(missing_docs)]

pub mod chromium;
pub mod design;
pub mod dom;
pub mod env;
pub mod error;
pub mod generator;
pub mod legacy_random;
pub mod primitives;
pub mod site;
pub mod vocab;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use a2perf_core::{EnvEntry, EnvError, ParamKind, ParamSpec, Params, Registry, TaskRef, Value};

pub use chromium::{
    ChromiumBackend, ChromiumOptions, SnapshotElement, TreeMemory, chromium_available,
    chromium_for_tests, other_browser_processes,
};
pub use design::{Design, level_of_probability, load_designs, page_difficulty, parse_designs};
pub use dom::{ActionKind, DomState, Event, Quirks};
pub use env::{ActionSemantics, BackendKind, PoolKind, WebNavConfig, WebNavEnv};
pub use error::WebError;
pub use generator::{
    DesignReport, Generated, Limits, Unsolvable, check_solvable, generate, report, sample_design,
};
pub use primitives::{PRIMITIVES, Primitive, PrimitiveInfo};
pub use site::Website;
pub use vocab::{OOV_ID, PAD_ID, VOCAB_SIZE, Vocabulary, tokenize, vocab_size};

/// Domain name used in the registry.
pub const DOMAIN: &str = "web_navigation";

/// The registered id of a difficulty level.
pub fn env_id(level: u8) -> String {
    format!("WebNavigation-Difficulty-0{level}-v0")
}

fn params() -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            "num_websites",
            ParamKind::Int,
            Value::Int(10),
            "size of the website pool (paper: 1, 5, 10)",
        ),
        ParamSpec::new(
            "seed",
            ParamKind::Int,
            Value::Int(0),
            "seed of the pool and episodes",
        ),
        ParamSpec::new(
            "backend",
            ParamKind::Choice(&["simulated", "chromium"]),
            Value::Str("simulated".into()),
            "in-process DOM model or headless Chromium",
        ),
        ParamSpec::new(
            "num_fields",
            ParamKind::Int,
            Value::Int(env::DEFAULT_FIELDS as i64),
            "profile fields in the observation (F), field 0 being A2Perf's `_dummy`",
        ),
        ParamSpec::new(
            "num_elements",
            ParamKind::Int,
            Value::Int(env::DEFAULT_ELEMENTS as i64),
            "DOM elements in the observation (E)",
        ),
        ParamSpec::new(
            "num_tokens",
            ParamKind::Int,
            Value::Int(env::DEFAULT_TOKENS as i64),
            "tokens per attribute (T)",
        ),
        ParamSpec::new(
            "step_limit",
            ParamKind::Int,
            Value::Int(env::STEP_LIMIT as i64),
            "episode step limit",
        ),
        ParamSpec::new(
            "designs",
            ParamKind::Path,
            Value::Null,
            "A2Perf design JSON (its 01/02/03.json): with pool = generated, its solvable designs \
             of the id's recomputed level; with pool = a2perf, all of them",
        ),
        ParamSpec::new(
            "pool",
            ParamKind::Choice(&["generated", "a2perf"]),
            Value::Str("generated".into()),
            "generated: solvable websites of the id's level; a2perf: the `designs` file as it is, \
             drawn like A2Perf (same designs for the same seed)",
        ),
        ParamSpec::new(
            "cc_bug",
            ParamKind::Bool,
            Value::Bool(false),
            "true: A2Perf's cc (credit-card type) radio group can never be selected",
        ),
        ParamSpec::new(
            "duplicate_fields",
            ParamKind::Bool,
            Value::Bool(false),
            "true: render an active primitive repeated on a later page, as A2Perf did (inputs \
             dead, radio groups working)",
        ),
        ParamSpec::new(
            "placeholders",
            ParamKind::Bool,
            Value::Bool(true),
            "fill the observation's placeholder slot (false: always empty, as in A2Perf)",
        ),
        ParamSpec::new(
            "limit_terminates",
            ParamKind::Bool,
            Value::Bool(false),
            "true: the step limit sets terminated as well as truncated, as in A2Perf",
        ),
        ParamSpec::new(
            "actions",
            ParamKind::Choice(&["masked", "a2perf"]),
            Value::Str("masked".into()),
            "masked: click/type, meaningful actions only; a2perf: A2Perf's visitGroup, every \
             (element, field) allowed, stale reward on a missing element",
        ),
    ]
}

fn config_from(level: u8, p: &Params) -> Result<WebNavConfig, EnvError> {
    let e = |err: a2perf_core::ParamError| EnvError::InvalidParameter {
        name: "params".into(),
        reason: err.to_string(),
    };
    let mut c = WebNavConfig::new(level);
    c.num_websites = p.usize("num_websites").map_err(e)?;
    c.seed = p.u64("seed").map_err(e)?;
    c.backend = match p.str("backend").map_err(e)? {
        "chromium" => BackendKind::Chromium,
        _ => BackendKind::Simulated,
    };
    c.num_fields = p.usize("num_fields").map_err(e)?;
    c.num_elements = p.usize("num_elements").map_err(e)?;
    c.num_tokens = p.usize("num_tokens").map_err(e)?;
    c.step_limit = p.usize("step_limit").map_err(e)?;
    c.designs_file = p.opt_str("designs").map_err(e)?.map(PathBuf::from);
    c.pool = match p.str("pool").map_err(e)? {
        "a2perf" => PoolKind::A2Perf,
        _ => PoolKind::Generated,
    };
    c.cc_bug = p.bool("cc_bug").map_err(e)?;
    c.duplicate_fields = p.bool("duplicate_fields").map_err(e)?;
    c.placeholders = p.bool("placeholders").map_err(e)?;
    c.limit_terminates = p.bool("limit_terminates").map_err(e)?;
    c.actions = match p.str("actions").map_err(e)? {
        "a2perf" => ActionSemantics::A2Perf,
        _ => ActionSemantics::Masked,
    };
    Ok(c)
}

/// Registers the three web-navigation environments and the domain's generalization suite
/// (difficulty 1 with 1, 5 and 10 websites, and levels 2 and 3 with 10 websites).
///
/// ```
/// let mut reg = a2perf_core::Registry::new();
/// a2perf_web::register(&mut reg);
/// let env = reg.make_env("WebNavigation-Difficulty-02-v0", &Default::default()).unwrap();
/// assert_eq!(env.spec().metadata["vocab_size"], a2perf_web::VOCAB_SIZE.to_string());
/// assert_eq!(reg.generalization("web_navigation").len(), 5);
/// ```
pub fn register(reg: &mut Registry) {
    for level in 1..=3u8 {
        reg.register_env(EnvEntry {
            id: env_id(level),
            domain: DOMAIN.into(),
            summary: format!(
                "fill gMiniWoB web forms from a profile, difficulty level {level} (generated, solvable websites; pool = a2perf plays A2Perf's design files)"
            ),
            params: params(),
            make: Arc::new(move |p: &Params| {
                let cfg = config_from(level, p)?;
                Ok(Box::new(WebNavEnv::new(cfg)?) as Box<dyn a2perf_core::Env>)
            }),
        });
    }
    let task = |name: &str, level: u8, n: i64| {
        let mut params = BTreeMap::new();
        params.insert("num_websites".to_string(), Value::Int(n));
        TaskRef {
            name: name.into(),
            env_id: env_id(level),
            params,
        }
    };
    reg.register_generalization(
        DOMAIN,
        vec![
            task("difficulty_level_1_num_websites_1", 1, 1),
            task("difficulty_level_1_num_websites_5", 1, 5),
            task("difficulty_level_1_num_websites_10", 1, 10),
            task("difficulty_level_2_num_websites_10", 2, 10),
            task("difficulty_level_3_num_websites_10", 3, 10),
        ],
    );
}

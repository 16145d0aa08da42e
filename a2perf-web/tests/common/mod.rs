//! Helpers shared by the integration tests.

#![allow(dead_code)]

use std::path::PathBuf;

use a2perf_core::{Action, Env, Observation, Step};
use a2perf_web::site::Node;
use a2perf_web::{Design, Primitive, WebNavConfig, WebNavEnv};

/// `../shared/data/web/a2perf_designs/<name>` (A2Perf's design files), or `None` with a printed
/// reason when absent — unless `A2PERF_REQUIRE_SHARED=1`, then absence fails.
pub fn shared(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/web/a2perf_designs/"
    ))
    .join(name);
    if p.exists() {
        return Some(p);
    }
    if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
        panic!("{} is missing and A2PERF_REQUIRE_SHARED=1", p.display());
    }
    println!("SKIP: {} not found", p.display());
    None
}

/// A design from primitive names, one list per page.
pub fn design(pages: &[&[&str]]) -> Design {
    Design {
        pages: pages
            .iter()
            .map(|p| p.iter().map(|n| Primitive::from_name(n).unwrap()).collect())
            .collect(),
    }
}

/// An environment playing only `pages`, with `cfg`.
pub fn env_on(pages: &[&[&str]], cfg: WebNavConfig) -> WebNavEnv {
    WebNavEnv::with_pool(vec![design(pages)], cfg, "t").unwrap()
}

/// Observation slot of the first visible element matching `pred`.
pub fn slot(env: &WebNavEnv, pred: impl Fn(&Node) -> bool) -> usize {
    env.dom()
        .order
        .iter()
        .position(|&n| pred(&env.website().nodes[n as usize]))
        .expect("element present")
}

/// Plays the oracle on pool website `index` (episode content from `seed`) until the episode ends
/// or the oracle has no action: (success, steps, return). Asserts the oracle stays in the mask.
pub fn oracle_episode(env: &mut WebNavEnv, index: usize, seed: u64) -> (bool, usize, f64) {
    let mut obs = Observation::default();
    env.reset_to_website(index, seed, &mut obs).unwrap();
    let mut step = Step::default();
    let (mut steps, mut ret) = (0, 0.0);
    while let Some(a) = env.oracle_action() {
        assert!(obs.is_legal(a), "oracle chose a masked action");
        env.step_into(&Action::Discrete(a), &mut step).unwrap();
        obs.copy_from(&step.observation);
        steps += 1;
        ret += step.reward;
        if step.done() {
            return (step.info.get("success") == Some(1.0), steps, ret);
        }
    }
    (false, steps, ret)
}

//! The registry of everything the benchmark ships: every domain's environments and every
//! built-in algorithm.

use a2perf_core::Registry;

/// All environments and algorithms shipped with the benchmark.
///
/// ```
/// let reg = a2perf_pipeline::registry::full_registry();
/// assert!(reg.envs().any(|e| e.id == "QuadrupedLocomotion-DogPace-v0"));
/// assert!(reg.algorithms().any(|a| a.name == "ppo"));
/// ```
pub fn full_registry() -> Registry {
    let mut reg = Registry::new();
    a2perf_web::register(&mut reg);
    a2perf_locomotion::register(&mut reg);
    a2perf_circuit::register(&mut reg);
    a2perf_baselines::register(&mut reg);
    reg
}

//! The registry the binary uses: every domain's environments and every built-in algorithm.

use a2perf_core::Registry;

/// All environments and algorithms shipped with the benchmark.
pub fn full_registry() -> Registry {
    #[allow(unused_mut)]
    let mut reg = Registry::new();
    // DOMAIN-REGISTER (helpers add `a2perf_<domain>::register(&mut reg);` above this line)
    reg
}

/// Prints environments and algorithms with their parameters.
pub fn print_list(reg: &Registry) {
    println!("Environments:");
    for e in reg.envs() {
        println!("  {:<44} [{}] {}", e.id, e.domain, e.summary);
        for p in &e.params {
            println!(
                "      {:<24} {:<18} default {:<12} {}",
                p.name,
                p.kind.describe(),
                p.default.to_string(),
                p.doc
            );
        }
    }
    println!("Algorithms:");
    for a in reg.algorithms() {
        println!("  {:<12} {}", a.name, a.summary);
        for p in &a.params {
            println!(
                "      {:<24} {:<18} default {:<12} {}",
                p.name,
                p.kind.describe(),
                p.default.to_string(),
                p.doc
            );
        }
    }
}

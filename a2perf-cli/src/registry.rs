//! The registry the binary uses: every domain's environments and every built-in algorithm.

use a2perf_core::Registry;

/// All environments and algorithms shipped with the benchmark.
pub fn full_registry() -> Registry {
    let mut reg = Registry::new();
    a2perf_web::register(&mut reg);
    a2perf_locomotion::register(&mut reg);
    a2perf_circuit::register(&mut reg);
    a2perf_baselines::register(&mut reg);
    // DOMAIN-REGISTER (helpers add `a2perf_<domain>::register(&mut reg);` above this line)
    reg
}

/// Prints environments and algorithms with their parameters. A closed pipe (`a2perf list | head`)
/// ends the listing quietly.
pub fn print_list(reg: &Registry) -> std::io::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let result = (|| -> std::io::Result<()> {
        writeln!(out, "Environments:")?;
        for e in reg.envs() {
            writeln!(out, "  {:<44} [{}] {}", e.id, e.domain, e.summary)?;
            write_params(&mut out, &e.params)?;
        }
        writeln!(out, "Algorithms:")?;
        for a in reg.algorithms() {
            writeln!(out, "  {:<12} {}", a.name, a.summary)?;
            write_params(&mut out, &a.params)?;
        }
        out.flush()
    })();
    match result {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

fn write_params(
    out: &mut impl std::io::Write,
    params: &[a2perf_core::ParamSpec],
) -> std::io::Result<()> {
    for p in params {
        writeln!(
            out,
            "      {:<24} {:<18} default {:<12} {}",
            p.name,
            p.kind.describe(),
            p.default.to_string(),
            p.doc
        )?;
    }
    Ok(())
}

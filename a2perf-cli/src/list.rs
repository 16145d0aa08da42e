//! `a2perf list`: every registered environment and algorithm with its typed parameters.

use a2perf_core::Registry;

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

//! scripts/copy-profile (a development tool): it counts a command's large copies per call site
//! and flags those in glibc's slow case. Checked on a small C program whose copies are known.
//! Needs gcc and addr2line, as the script does; skipped with a printed reason without them.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("a2perf-cli sits in the workspace root")
        .to_path_buf()
}

fn have(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// 40 copies of 64 KiB with the destination 16 bytes past the source modulo 4 KiB (glibc's slow
/// case), 25 of 64 KiB page-aligned apart, 1,000 of 100 bytes (under the threshold), exit 3.
const PROGRAM: &str = r#"
#include <stdlib.h>
#include <string.h>
void *(*volatile copy)(void *, const void *, size_t) = memcpy;
__attribute__((noinline)) void slow(char *d, const char *s) { copy(d, s, 65536); }
__attribute__((noinline)) void fine(char *d, const char *s) { copy(d, s, 65536); }
int main(void) {
    char *buf = aligned_alloc(4096, 4 * 65536);
    memset(buf, 1, 4 * 65536);
    for (int i = 0; i < 40; i++) slow(buf + 65536 + 16, buf);
    for (int i = 0; i < 25; i++) fine(buf + 2 * 65536, buf);
    for (int i = 0; i < 1000; i++) copy(buf + 3 * 65536, buf, 100);
    return 3;
}
"#;

#[test]
fn copy_profile_counts_copies_per_site_and_flags_the_slow_case() {
    for tool in ["gcc", "addr2line"] {
        if !have(tool) {
            eprintln!("skipped: {tool} not found (scripts/copy-profile needs it)");
            return;
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("copies.c");
    std::fs::write(&src, PROGRAM).unwrap();
    let exe = dir.path().join("copies");
    let cc = Command::new("gcc")
        .args(["-O1", "-g", "-o"])
        .arg(&exe)
        .arg(&src)
        .output()
        .unwrap();
    assert!(
        cc.status.success(),
        "{}",
        String::from_utf8_lossy(&cc.stderr)
    );
    let out = Command::new("bash")
        .arg(repo().join("scripts/copy-profile"))
        .arg("--")
        .arg(&exe)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(3),
        "the command's exit status passes through\n{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Rows: bytes, calls, slow, call site.
    let rows: Vec<(u64, u64, u64, String)> = text
        .lines()
        .skip(1)
        .filter_map(|l| {
            let mut f = l.split_whitespace();
            let b = f.next()?.parse().ok()?;
            let c = f.next()?.parse().ok()?;
            let s = f.next()?.parse().ok()?;
            Some((b, c, s, f.collect::<Vec<_>>().join(" ")))
        })
        .collect();
    let counts = |name: &str| {
        rows.iter()
            .find(|r| r.3.contains(name))
            .map(|r| (r.0, r.1, r.2))
            .unwrap_or_else(|| panic!("no row for {name}:\n{text}"))
    };
    assert_eq!(counts("slow"), (40 * 65536, 40, 40), "{text}");
    assert_eq!(counts("fine"), (25 * 65536, 25, 0), "{text}");
    assert!(
        rows.iter().all(|r| r.1 != 1000),
        "copies under --min-bytes are not counted:\n{text}"
    );
    if have("shellcheck") {
        let sc = Command::new("shellcheck")
            .arg(repo().join("scripts/copy-profile"))
            .output()
            .unwrap();
        assert!(
            sc.status.success(),
            "{}",
            String::from_utf8_lossy(&sc.stdout)
        );
    }
}

//! Which processes belong to a browser session and how much memory they hold, read from
//! Linux's `/proc` (on other systems every list is empty and every figure 0).

/// The pids listed in `/proc` (none where it is missing).
fn all_pids() -> impl Iterator<Item = u32> {
    std::fs::read_dir("/proc")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()))
}

/// Live processes whose command line contains `needle` (zombies have none).
pub(crate) fn processes_with(needle: &str) -> Vec<u32> {
    let mut out = Vec::new();
    for pid in all_pids() {
        if let Ok(cmd) = std::fs::read(format!("/proc/{pid}/cmdline"))
            && String::from_utf8_lossy(&cmd).contains(needle)
        {
            out.push(pid);
        }
    }
    out
}

/// Parent pid and start time (clock ticks after boot) of a live process; `None` for zombies and
/// processes that are gone.
pub(crate) fn proc_stat(pid: u32) -> Option<(u32, u64)> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the parenthesised command name: state, ppid, ..., starttime (20th).
    let mut f = s.rsplit_once(')')?.1.split_whitespace();
    if matches!(f.next(), Some("Z" | "X") | None) {
        return None;
    }
    let ppid = f.next()?.parse().ok()?;
    let start = f.nth(17)?.parse().ok()?;
    Some((ppid, start))
}

/// `roots` and every live descendant of theirs. The process tree matters because not every
/// Chromium child carries the profile directory on its command line (the headless shell's
/// renderer and GPU processes do not).
pub(crate) fn with_descendants(roots: &[u32]) -> Vec<u32> {
    let table: Vec<(u32, u32)> = all_pids()
        .filter_map(|pid| proc_stat(pid).map(|(ppid, _)| (pid, ppid)))
        .collect();
    let mut out: Vec<u32> = roots
        .iter()
        .copied()
        .filter(|&r| table.iter().any(|&(p, _)| p == r))
        .collect();
    let mut k = 0;
    while k < out.len() {
        let parent = out[k];
        for &(p, pp) in &table {
            if pp == parent && !out.contains(&p) {
                out.push(p);
            }
        }
        k += 1;
    }
    out
}

fn proc_status_kb(pid: u32, key: &str) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse().ok()))
        })
        .unwrap_or(0)
}

/// The `smaps_rollup` fields of one process, in kB.
#[derive(Clone, Copy, Default)]
struct Rollup {
    pss: u64,
    pss_anon: u64,
    pss_file: u64,
    pss_shmem: u64,
    private: u64,
}

fn rollup(pid: u32) -> Rollup {
    let mut r = Rollup::default();
    let Ok(text) = std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup")) else {
        return r;
    };
    for l in text.lines() {
        let mut it = l.split_whitespace();
        let (Some(key), Some(v)) = (it.next(), it.next().and_then(|v| v.parse::<u64>().ok()))
        else {
            continue;
        };
        match key {
            "Pss:" => r.pss += v,
            "Pss_Anon:" => r.pss_anon += v,
            "Pss_File:" => r.pss_file += v,
            "Pss_Shmem:" => r.pss_shmem += v,
            "Private_Clean:" | "Private_Dirty:" => r.private += v,
            _ => {}
        }
    }
    r
}

/// Memory of one environment's browser: chromedriver plus every Chromium process of its
/// session, read from `/proc/<pid>/status` and `/proc/<pid>/smaps_rollup`.
///
/// **The figure we report as "RAM of an environment" is [`pss_bytes`](Self::pss_bytes)**: the
/// proportional set size summed over that whole process tree. A page mapped by k processes counts
/// 1/k in each, so the sum over the tree is what the tree holds, with the pages it shares with
/// processes *outside* the tree (other environments' Chromium code, libc) split fairly. For a
/// **lone** environment — the case of a user running one — nothing else maps Chromium's binary,
/// so the tree pays for every code page it touched; that is the figure the < 200 MB target is
/// about. With N environments side by side, the binary's pages are split N ways and the
/// per-environment PSS is lower. [`uss_bytes`](Self::uss_bytes) (private pages only) is a lower
/// bound that stays the same however many environments run; summed RSS counts a page once per
/// process that maps it and overstates the tree. The breakdown into anonymous (heaps, JS),
/// file-backed (mostly the Chromium binary's code and data) and shared-memory pages says where
/// the memory goes. Measure only when no unrelated Chromium runs on the machine
/// ([`other_browser_processes`]), else the lone figure comes out too low.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TreeMemory {
    /// Number of processes (chromedriver + Chromium's).
    pub processes: usize,
    /// Sum of resident set sizes, bytes (counts shared pages once per process).
    pub rss_bytes: u64,
    /// Sum of proportional set sizes, bytes (shared pages split between sharers): the reported
    /// "RAM of the environment".
    pub pss_bytes: u64,
    /// Anonymous part of [`pss_bytes`](Self::pss_bytes) (heaps, JS, stacks).
    pub pss_anon_bytes: u64,
    /// File-backed part of [`pss_bytes`](Self::pss_bytes) (binary and library pages).
    pub pss_file_bytes: u64,
    /// Shared-memory part of [`pss_bytes`](Self::pss_bytes) (Chromium's IPC buffers between
    /// its processes).
    pub pss_shmem_bytes: u64,
    /// Sum of unique (private clean + dirty) set sizes, bytes: what this session alone holds;
    /// pages shared with any other process, inside or outside the tree, are excluded.
    pub uss_bytes: u64,
}

impl TreeMemory {
    /// The per-environment average of several environments' figures (integer division; the
    /// default for an empty slice).
    ///
    /// ```
    /// use a2perf_web::TreeMemory;
    /// let a = TreeMemory { processes: 2, pss_bytes: 100, ..TreeMemory::default() };
    /// let b = TreeMemory { processes: 2, pss_bytes: 300, ..TreeMemory::default() };
    /// assert_eq!(TreeMemory::mean(&[a, b]).pss_bytes, 200);
    /// ```
    pub fn mean(all: &[TreeMemory]) -> Self {
        let n = all.len().max(1);
        let per = |f: fn(&TreeMemory) -> u64| all.iter().map(f).sum::<u64>() / n as u64;
        TreeMemory {
            processes: all.iter().map(|m| m.processes).sum::<usize>() / n,
            rss_bytes: per(|m| m.rss_bytes),
            pss_bytes: per(|m| m.pss_bytes),
            pss_anon_bytes: per(|m| m.pss_anon_bytes),
            pss_file_bytes: per(|m| m.pss_file_bytes),
            pss_shmem_bytes: per(|m| m.pss_shmem_bytes),
            uss_bytes: per(|m| m.uss_bytes),
        }
    }

    /// The memory of the processes `pids` (those that have exited count 0).
    pub fn of(pids: &[u32]) -> Self {
        let mut m = TreeMemory {
            processes: pids.len(),
            ..Self::default()
        };
        for &p in pids {
            let r = rollup(p);
            m.rss_bytes += proc_status_kb(p, "VmRSS:") * 1024;
            m.pss_bytes += r.pss * 1024;
            m.pss_anon_bytes += r.pss_anon * 1024;
            m.pss_file_bytes += r.pss_file * 1024;
            m.pss_shmem_bytes += r.pss_shmem * 1024;
            m.uss_bytes += r.private * 1024;
        }
        m
    }
}

/// Live Chromium or chromedriver processes on this machine (their pids), whichever session they
/// belong to. Used to warn that a lone environment's PSS is being measured next to other
/// browsers that share its code pages.
pub fn other_browser_processes() -> Vec<u32> {
    let me = std::process::id();
    let mut out = Vec::new();
    for pid in all_pids() {
        if pid == me {
            continue;
        }
        if let Ok(exe) = std::fs::read_link(format!("/proc/{pid}/exe")) {
            let name = exe
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            if name.starts_with("chrom") || name == "headless_shell" {
                out.push(pid);
            }
        }
    }
    out
}

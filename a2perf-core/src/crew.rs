//! Worker threads for lockstep jobs: each runs one fixed part of every job beside the calling
//! thread, and between jobs spins for a short while before sleeping. The Python package's vector
//! environment steps its environments with it.
//!
//! Why not rayon's pool: a vector environment steps a few slow environments in lockstep, once
//! per Python `step()`. Between two steps the caller spends tens of microseconds in Python, long
//! enough for a rayon worker to fall asleep, and on a virtual machine waking a sleeping vCPU
//! costs tens of microseconds more per step. Measured on DogPace (N = 2, 2 vCPUs), keeping the
//! worker spinning through that gap gave 5–12% more env steps/s than rayon's pool with the same
//! pinning. The spin is bounded by [`SPIN`], so an agent that thinks longer between steps costs
//! one core that long and no more.
//!
//! Threads do not survive `fork()`: in a child process the crew has no workers, so
//! [`Crew::run`] notices the new process ([`Crew::forked`]) and runs every part on the calling
//! thread instead of waiting forever for workers that do not exist there.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::{self, JoinHandle, Thread};
use std::time::{Duration, Instant};

/// How long an idle thread spins before it sleeps: a worker waiting for the next job, the caller
/// waiting for the workers.
pub const SPIN: Duration = Duration::from_micros(200);

/// A job as the workers see it: part `k` (1-based; the caller runs part 0), its lifetime erased.
type Job = dyn Fn(usize) + Sync + 'static;

/// A job pointer with its lifetime erased; valid while the job's [`Crew::run`] call lasts.
#[derive(Clone, Copy)]
struct JobPtr(*const Job);

// SAFETY: the pointee is `Sync`, and `Crew::run` does not return (or unwind) before every worker
// has finished with it.
unsafe impl Send for JobPtr {}

/// What a worker and the caller share.
struct Shared {
    /// Jobs posted to this worker so far.
    posted: AtomicU64,
    /// Jobs this worker has finished.
    finished: AtomicU64,
    /// The current job and the thread to wake when it is done.
    job: Mutex<Option<(JobPtr, Thread)>>,
    /// The current job panicked on this worker.
    panicked: AtomicBool,
    /// The crew is being dropped.
    stop: AtomicBool,
}

/// Threads that run parts `1..=workers()` of each job while the caller runs part 0.
///
/// ```
/// use std::sync::atomic::{AtomicUsize, Ordering};
/// use a2perf_core::crew::Crew;
///
/// let crew = Crew::new(1, "example").unwrap();
/// let parts = [AtomicUsize::new(0), AtomicUsize::new(0)];
/// for _ in 0..3 {
///     // Part 0 runs on this thread, part 1 on the worker.
///     assert!(crew.run(&|k| { parts[k].fetch_add(1, Ordering::Relaxed); }));
/// }
/// assert_eq!(parts.map(AtomicUsize::into_inner), [3, 3]);
/// ```
pub struct Crew {
    workers: Vec<(Arc<Shared>, Option<JoinHandle<()>>)>,
    /// The process the workers were started in.
    pid: u32,
}

impl Crew {
    /// Starts `n` worker threads named `{name}-1` …
    pub fn new(n: usize, name: &str) -> std::io::Result<Self> {
        let mut workers = Vec::with_capacity(n);
        for k in 1..=n {
            let shared = Arc::new(Shared {
                posted: AtomicU64::new(0),
                finished: AtomicU64::new(0),
                job: Mutex::new(None),
                panicked: AtomicBool::new(false),
                stop: AtomicBool::new(false),
            });
            let mine = Arc::clone(&shared);
            let handle = thread::Builder::new()
                .name(format!("{name}-{k}"))
                .spawn(move || work(k, &mine))?;
            workers.push((shared, Some(handle)));
        }
        Ok(Self {
            workers,
            pid: std::process::id(),
        })
    }

    /// Whether this crew was started in another process (it was inherited through `fork()`),
    /// where its worker threads do not exist: [`Crew::run`] then runs every part itself.
    pub fn forked(&self) -> bool {
        std::process::id() != self.pid
    }

    /// Number of worker threads (parts run beside the caller's).
    pub fn workers(&self) -> usize {
        self.workers.len()
    }

    /// Runs `job(0)` on this thread and `job(k)` on worker `k`, returning when all are done.
    /// Returns `false` when a worker's part panicked (the panic is not propagated).
    ///
    /// In a process forked from the one that started the crew, every part runs on this thread,
    /// one after another (a panic in a part `k ≥ 1` is still caught and reported as `false`).
    pub fn run<'a>(&self, job: &'a (dyn Fn(usize) + Sync + 'a)) -> bool {
        if self.forked() {
            job(0);
            // Every part runs, also after one has panicked, as on the workers.
            let mut all_ok = true;
            for k in 1..=self.workers.len() {
                all_ok &= catch_unwind(AssertUnwindSafe(|| job(k))).is_ok();
            }
            return all_ok;
        }
        let short: *const (dyn Fn(usize) + Sync + 'a) = job;
        // SAFETY: only the lifetime is erased; `Wait` below keeps this call from returning or
        // unwinding before every worker has finished the job.
        let ptr = JobPtr(unsafe {
            std::mem::transmute::<*const (dyn Fn(usize) + Sync + 'a), *const Job>(short)
        });
        let me = thread::current();
        for (shared, handle) in &self.workers {
            *shared.job.lock().unwrap_or_else(PoisonError::into_inner) = Some((ptr, me.clone()));
            shared.posted.fetch_add(1, Ordering::Release);
            if let Some(h) = handle {
                h.thread().unpark();
            }
        }
        let wait = Wait(self);
        job(0);
        drop(wait);
        self.workers
            .iter()
            .all(|(s, _)| !s.panicked.swap(false, Ordering::AcqRel))
    }
}

/// Waits for every worker to finish the current job, also while the caller unwinds.
struct Wait<'a>(&'a Crew);

impl Drop for Wait<'_> {
    fn drop(&mut self) {
        for (shared, _) in &self.0.workers {
            let target = shared.posted.load(Ordering::Relaxed);
            idle_until(|| shared.finished.load(Ordering::Acquire) >= target);
        }
    }
}

impl Drop for Crew {
    fn drop(&mut self) {
        if self.forked() {
            // The workers live in the parent process: nothing to stop or join here, and no
            // thread call on their handles (they name threads of another process).
            for (_, handle) in &mut self.workers {
                std::mem::forget(handle.take());
            }
            return;
        }
        for (shared, handle) in &mut self.workers {
            shared.stop.store(true, Ordering::Release);
            if let Some(h) = handle.take() {
                h.thread().unpark();
                // A worker's panics are caught per job; joining cannot fail otherwise.
                let _ = h.join();
            }
        }
    }
}

/// Spins until `ready()` for up to [`SPIN`], then sleeps until woken (`unpark`) and checks again.
fn idle_until(ready: impl Fn() -> bool) {
    let start = Instant::now();
    let mut spins = 0u32;
    while !ready() {
        spins = spins.wrapping_add(1);
        if !spins.is_multiple_of(64) || start.elapsed() < SPIN {
            std::hint::spin_loop();
        } else {
            // The other side sets the condition, then unparks: an unpark between the check and
            // this park leaves a token, so no wake-up is lost. The timeout is a safety net that
            // an idle worker pays ten times a second.
            thread::park_timeout(Duration::from_millis(100));
        }
    }
}

/// A worker's loop: wait for a job, run part `k`, report, repeat.
fn work(k: usize, shared: &Shared) {
    let mut done = 0u64;
    loop {
        idle_until(|| {
            shared.posted.load(Ordering::Acquire) > done || shared.stop.load(Ordering::Acquire)
        });
        if shared.stop.load(Ordering::Acquire) {
            return;
        }
        done = shared.posted.load(Ordering::Acquire);
        let current = shared
            .job
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some((JobPtr(job), caller)) = current {
            // SAFETY: the caller is inside `Crew::run` until `finished` reaches `done`.
            let job = unsafe { &*job };
            if catch_unwind(AssertUnwindSafe(|| job(k))).is_err() {
                shared.panicked.store(true, Ordering::Release);
            }
            shared.finished.store(done, Ordering::Release);
            caller.unpark();
        } else {
            shared.finished.store(done, Ordering::Release);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn every_part_runs_once_per_job_on_its_own_thread() {
        let crew = Crew::new(3, "test-crew").unwrap();
        assert_eq!(crew.workers(), 3);
        let names = Mutex::new(vec![String::new(); 4]);
        let count = AtomicUsize::new(0);
        for _ in 0..200 {
            assert!(crew.run(&|k| {
                count.fetch_add(1, Ordering::Relaxed);
                let name = thread::current().name().unwrap_or("").to_string();
                let mut n = names.lock().unwrap();
                assert!(n[k].is_empty() || n[k] == name, "part {k} moved thread");
                n[k] = name;
            }));
            // Sleep past the spin sometimes, so that workers are woken from sleep too.
            if count.load(Ordering::Relaxed).is_multiple_of(40) {
                thread::sleep(SPIN * 2);
            }
        }
        assert_eq!(count.into_inner(), 800);
        let names = names.into_inner().unwrap();
        assert_eq!(&names[1..], ["test-crew-1", "test-crew-2", "test-crew-3"]);
    }

    #[test]
    fn a_crew_inherited_by_a_forked_process_runs_every_part_on_the_caller() {
        let mut crew = Crew::new(2, "test-crew").unwrap();
        assert!(!crew.forked());
        // What a child process sees: the workers belong to another process id.
        crew.pid = crew.pid.wrapping_add(1);
        assert!(crew.forked());
        let me = thread::current().id();
        let ran = Mutex::new(Vec::new());
        assert!(crew.run(&|k| {
            assert_eq!(
                thread::current().id(),
                me,
                "part {k} left the caller's thread"
            );
            ran.lock().unwrap().push(k);
        }));
        assert_eq!(ran.into_inner().unwrap(), [0, 1, 2]);
        assert!(!crew.run(&|k| assert_ne!(k, 2, "part 2 fails")));
        // Dropping must not wait for the (parent's) workers; give them back their pid so that
        // this test's real threads are stopped and joined.
        crew.pid = std::process::id();
    }

    #[test]
    fn the_parts_borrow_the_callers_data_and_a_worker_panic_is_reported() {
        let crew = Crew::new(1, "test-crew").unwrap();
        let mut data = vec![0u64; 2];
        for round in 1..=50u64 {
            let cells: Vec<Mutex<&mut u64>> = data.iter_mut().map(Mutex::new).collect();
            assert!(crew.run(&|k| **cells[k].lock().unwrap() += round));
        }
        assert_eq!(data, [1275, 1275]);
        assert!(!crew.run(&|k| assert_eq!(k, 0, "worker part fails")));
        // The crew is still usable after a worker's panic.
        assert!(crew.run(&|_| {}));
    }
}

//! The worker pool every `--jobs` phase runs in: tasks with dependencies on a fixed number of
//! threads.
//!
//! A worker takes the first task, in the order given, whose dependencies have all succeeded, so
//! that with one worker the tasks start in a fixed order, and with more the order of starts
//! follows the order of completions. Results never depend on that order (every run is seeded by
//! itself); the order only decides how well the workers are kept busy. A task whose dependency
//! did not succeed is not run: it is [`Slot::Blocked`] by the task that failed. Once `cancel`
//! fires no task starts, and the ones not started are [`Slot::NotRun`]; the ones running finish
//! (they watch the token themselves).
//!
//! The calling thread does no task: it hands the pool's [`Event`]s, in the order they happened,
//! to an observer, so that a front end's callback (which need not be `Send`) sees the schedule
//! as it unfolds.

use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::mpsc::{Sender, channel};
use std::sync::{Condvar, Mutex, MutexGuard};

use a2perf_core::CancelToken;

/// What happened to one task.
#[derive(Debug)]
pub(crate) enum Slot<R> {
    /// It ran, with this result.
    Done(R),
    /// It did not run: task `by` (one of its dependencies, or theirs) ran and did not succeed.
    Blocked {
        /// The task that failed.
        by: usize,
    },
    /// It did not run: cancelled before it could start (or its dependencies form a cycle).
    NotRun,
}

/// A change in the pool, in the order the workers made it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Event {
    /// A worker took task `i`.
    Started(usize),
    /// Task `i` ended (its result is in its [`Slot`]).
    Finished(usize),
}

/// Worker threads for `jobs` (0 = one per logical CPU).
pub(crate) fn workers(jobs: usize) -> usize {
    match jobs {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
}

/// Where a task stands.
#[derive(Clone, Copy, PartialEq)]
enum State {
    Waiting,
    Running,
    Succeeded,
    Failed,
    Blocked(usize),
}

/// What the workers share.
struct Board<R> {
    states: Vec<State>,
    results: Vec<Option<std::thread::Result<R>>>,
    running: usize,
}

impl<R> Board<R> {
    /// Marks every waiting task behind a failed or blocked dependency as blocked by the task
    /// that failed (dependencies may point forward, so this runs to a fixed point).
    fn block_dependents(&mut self, deps: &[Vec<usize>]) {
        loop {
            let mut changed = false;
            for (i, after) in deps.iter().enumerate() {
                if self.states[i] != State::Waiting {
                    continue;
                }
                let by = after.iter().find_map(|&d| match self.states.get(d) {
                    Some(State::Failed) => Some(d),
                    Some(State::Blocked(root)) => Some(*root),
                    _ => None,
                });
                if let Some(by) = by {
                    self.states[i] = State::Blocked(by);
                    changed = true;
                }
            }
            if !changed {
                return;
            }
        }
    }

    /// The first waiting task whose dependencies have all succeeded.
    fn next_ready(&self, deps: &[Vec<usize>]) -> Option<usize> {
        (0..deps.len()).find(|&i| {
            self.states[i] == State::Waiting
                && deps[i]
                    .iter()
                    .all(|&d| self.states.get(d) == Some(&State::Succeeded))
        })
    }
}

/// Runs `work(i)` for every `i < n` on `jobs` threads (0 = one per logical CPU), starting the
/// items in order; once `cancel` fires no further item starts (the running ones finish).
/// Returns each item's result in order, `None` for an item that never started. A front end's
/// seeds or runs that need no dependencies between them (`a2perf submit --jobs`).
///
/// ```
/// use a2perf_pipeline::{CancelToken, for_each};
/// let cancel = CancelToken::new();
/// let squares = for_each(4, 2, &cancel, |i| i * i);
/// assert_eq!(squares, [Some(0), Some(1), Some(4), Some(9)]);
/// // One at a time, an item that cancels leaves the later ones unstarted.
/// let stopped = for_each(4, 1, &cancel, |i| {
///     if i == 1 {
///         cancel.cancel();
///     }
///     i
/// });
/// assert_eq!(stopped, [Some(0), Some(1), None, None]);
/// ```
pub fn for_each<R: Send>(
    n: usize,
    jobs: usize,
    cancel: &CancelToken,
    work: impl Fn(usize) -> R + Sync,
) -> Vec<Option<R>> {
    let deps = vec![Vec::new(); n];
    run(&deps, workers(jobs), cancel, &work, &|_| true, &mut |_| {})
        .into_iter()
        .map(|slot| match slot {
            Slot::Done(r) => Some(r),
            Slot::Blocked { .. } | Slot::NotRun => None,
        })
        .collect()
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A worker never panics while holding the lock (tasks run outside it), so a poisoned lock
    // still holds consistent state.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Runs task `i` of `deps` (the indices of the tasks it waits for) as `work(i)` on up to
/// `workers` threads; `succeeded` says whether a result lets the task's dependents start.
/// Returns one [`Slot`] per task, in the order given; `observe` sees every [`Event`] on the
/// calling thread while the pool runs. A task that panics blocks its dependents, and its panic
/// is raised again on the calling thread once every worker has stopped.
pub(crate) fn run<R: Send>(
    deps: &[Vec<usize>],
    workers: usize,
    cancel: &CancelToken,
    work: &(dyn Fn(usize) -> R + Sync),
    succeeded: &(dyn Fn(&R) -> bool + Sync),
    observe: &mut dyn FnMut(Event),
) -> Vec<Slot<R>> {
    let n = deps.len();
    let board = Mutex::new(Board {
        states: vec![State::Waiting; n],
        results: (0..n).map(|_| None).collect(),
        running: 0,
    });
    let wake = Condvar::new();
    let (events, received) = channel();
    std::thread::scope(|scope| {
        for _ in 0..workers.clamp(1, n.max(1)) {
            let events = events.clone();
            let (board, wake) = (&board, &wake);
            scope.spawn(move || worker(deps, cancel, work, succeeded, board, wake, &events));
        }
        // The workers hold the only senders left, so this ends when the last one stops.
        drop(events);
        for event in received {
            observe(event);
        }
    });
    let board = board.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut panic = None;
    let slots = board
        .states
        .iter()
        .zip(board.results)
        .map(|(state, result)| match (state, result) {
            (_, Some(Ok(r))) => Slot::Done(r),
            (State::Blocked(by), _) => Slot::Blocked { by: *by },
            (_, Some(Err(payload))) => {
                panic.get_or_insert(payload);
                Slot::NotRun
            }
            _ => Slot::NotRun,
        })
        .collect();
    if let Some(payload) = panic {
        resume_unwind(payload);
    }
    slots
}

/// One worker: takes ready tasks until none is left to take.
fn worker<R>(
    deps: &[Vec<usize>],
    cancel: &CancelToken,
    work: &(dyn Fn(usize) -> R + Sync),
    succeeded: &(dyn Fn(&R) -> bool + Sync),
    board: &Mutex<Board<R>>,
    wake: &Condvar,
    events: &Sender<Event>,
) {
    let mut b = lock(board);
    loop {
        if cancel.is_cancelled() {
            return;
        }
        b.block_dependents(deps);
        let Some(i) = b.next_ready(deps) else {
            if b.running == 0 {
                // Nothing ready and nothing that could make anything ready.
                wake.notify_all();
                return;
            }
            b = wake.wait(b).unwrap_or_else(|e| e.into_inner());
            continue;
        };
        b.states[i] = State::Running;
        b.running += 1;
        // Sent under the lock, so that the events' order is the order of the board's changes.
        let _ = events.send(Event::Started(i));
        drop(b);
        let result = catch_unwind(AssertUnwindSafe(|| work(i)));
        let ok = result.as_ref().is_ok_and(succeeded);
        b = lock(board);
        b.states[i] = if ok { State::Succeeded } else { State::Failed };
        b.results[i] = Some(result);
        b.running -= 1;
        let _ = events.send(Event::Finished(i));
        wake.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn run_all(
        deps: &[Vec<usize>],
        workers: usize,
        fails: &[usize],
    ) -> (Vec<Slot<usize>>, Vec<Event>) {
        let mut events = Vec::new();
        let slots = run(
            deps,
            workers,
            &CancelToken::new(),
            &|i| i,
            &|i| !fails.contains(i),
            &mut |e| events.push(e),
        );
        (slots, events)
    }

    fn position(events: &[Event], e: Event) -> usize {
        events
            .iter()
            .position(|x| *x == e)
            .unwrap_or_else(|| panic!("{e:?} not in {events:?}"))
    }

    #[test]
    fn every_task_runs_once_after_its_dependencies() {
        // 0 and 1 are sources, 2 waits for both, 3 and 4 for 2; 5 is unrelated; 6 points
        // forward to 5.
        let deps = vec![
            vec![],
            vec![],
            vec![0, 1],
            vec![2],
            vec![2],
            vec![],
            vec![5],
        ];
        for workers in [1, 2, 3, 8] {
            let (slots, events) = run_all(&deps, workers, &[]);
            for (i, s) in slots.iter().enumerate() {
                assert!(
                    matches!(s, Slot::Done(r) if *r == i),
                    "{workers}: {i} {s:?}"
                );
            }
            assert_eq!(events.len(), 2 * deps.len(), "{workers}: {events:?}");
            for (i, after) in deps.iter().enumerate() {
                let started = position(&events, Event::Started(i));
                assert!(started < position(&events, Event::Finished(i)));
                for &d in after {
                    assert!(
                        position(&events, Event::Finished(d)) < started,
                        "{i} after {d}"
                    );
                }
            }
        }
    }

    #[test]
    fn one_worker_starts_the_first_ready_task_in_order() {
        // 0 waits for 2, so 1 and 2 start first, then 0 (now first ready), then 3.
        let deps = vec![vec![2], vec![], vec![], vec![]];
        let (_, events) = run_all(&deps, 1, &[]);
        let starts: Vec<usize> = events
            .iter()
            .filter_map(|e| match e {
                Event::Started(i) => Some(*i),
                Event::Finished(_) => None,
            })
            .collect();
        assert_eq!(starts, [1, 2, 0, 3]);
        assert_eq!(run_all(&deps, 1, &[]).1, events, "the same again");
    }

    #[test]
    fn a_failed_task_blocks_its_dependents_and_nothing_else() {
        let deps = vec![vec![], vec![0], vec![1], vec![], vec![3]];
        for workers in [1, 2] {
            let (slots, events) = run_all(&deps, workers, &[0]);
            assert!(matches!(slots[0], Slot::Done(0)));
            assert!(matches!(slots[1], Slot::Blocked { by: 0 }));
            assert!(
                matches!(slots[2], Slot::Blocked { by: 0 }),
                "the root is named"
            );
            assert!(matches!(slots[3], Slot::Done(3)));
            assert!(matches!(slots[4], Slot::Done(4)));
            assert!(!events.contains(&Event::Started(1)));
        }
    }

    #[test]
    fn a_cancel_starts_nothing_more() {
        let cancel = CancelToken::new();
        let ran = AtomicUsize::new(0);
        let deps = vec![vec![]; 5];
        let slots = run(
            &deps,
            1,
            &cancel,
            &|i| {
                ran.fetch_add(1, Ordering::SeqCst);
                if i == 1 {
                    cancel.cancel();
                }
                i
            },
            &|_| true,
            &mut |_| {},
        );
        assert_eq!(ran.load(Ordering::SeqCst), 2);
        assert!(matches!(slots[1], Slot::Done(1)));
        assert!(slots[2..].iter().all(|s| matches!(s, Slot::NotRun)));
    }

    #[test]
    fn a_cycle_ends_the_pool_instead_of_hanging() {
        let deps = vec![vec![1], vec![0], vec![]];
        let (slots, _) = run_all(&deps, 2, &[]);
        assert!(matches!(slots[0], Slot::NotRun) && matches!(slots[1], Slot::NotRun));
        assert!(matches!(slots[2], Slot::Done(2)));
    }

    #[test]
    fn a_panicking_task_blocks_its_dependents_and_panics_on_the_caller() {
        let deps = vec![vec![], vec![0], vec![]];
        let ran = AtomicUsize::new(0);
        let caught = catch_unwind(AssertUnwindSafe(|| {
            run(
                &deps,
                2,
                &CancelToken::new(),
                &|i| {
                    ran.fetch_add(1, Ordering::SeqCst);
                    assert!(i != 0, "task 0 panics");
                    i
                },
                &|_| true,
                &mut |_| {},
            )
        }));
        assert!(caught.is_err());
        // 0 and 2 ran; 1 did not, and the pool did not hang waiting for it.
        assert_eq!(ran.load(Ordering::SeqCst), 2);
    }
}

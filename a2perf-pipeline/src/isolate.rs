//! Runs in processes of their own. The system meters measure the process they run in (its RAM,
//! its share of the CPU's energy), so a run trained in a process that trained others before it,
//! or beside it (`jobs > 1`), is measured with them. With [`Isolation::Children`] each run's
//! training, inference and generalization is a child process of its own, and its figures are its
//! alone, like the paper's per-job figures.
//!
//! The library does not know how to start itself: the front end supplies a [`ChildCommand`] that
//! turns a [`ChildTask`] into a command line (the `a2perf` command re-runs itself with the same
//! configs; see `a2perf train --isolate`). Training is the same either way: a child builds the
//! run's plan from the same configs and trains it with [`train_run`](crate::train::train_run).

use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use a2perf_core::{CancelToken, RunDir};

use crate::error::{PipelineError, Result};
use crate::outcome::{RunOutcome, RunReport};

/// What a child process is asked to do, for a [`ChildCommand`] to turn into a command line.
#[derive(Clone, Copy, Debug)]
pub enum ChildTask<'a> {
    /// Train the run whose directory is `run` (a run of the same configs as the parent's) and
    /// write its [`RunReport`] as JSON to `report`.
    Train {
        /// The run directory.
        run: &'a Path,
        /// Where the child writes its report.
        report: &'a Path,
    },
    /// Infer the trained run in `run` (writes its `inference.json`).
    Infer {
        /// The run directory.
        run: &'a Path,
    },
    /// Generalize the trained run in `run` (writes its `generalization.json`).
    Generalize {
        /// The run directory.
        run: &'a Path,
    },
}

impl ChildTask<'_> {
    /// What the task is called in messages, and its run directory.
    fn describe(&self) -> (&'static str, &Path) {
        match *self {
            ChildTask::Train { run, .. } => ("training", run),
            ChildTask::Infer { run } => ("inference", run),
            ChildTask::Generalize { run } => ("generalization", run),
        }
    }
}

/// Runs `task` in a child process with its standard output discarded (the parent prints the
/// results); an error naming the run when the process cannot start.
fn run_task(
    command: &ChildCommand,
    task: ChildTask<'_>,
    cancel: &CancelToken,
) -> Result<ExitStatus> {
    let (what, dir) = task.describe();
    let mut cmd = command(task);
    cmd.stdout(Stdio::null());
    run_child(cmd, cancel).map_err(|e| {
        PipelineError::Invalid(format!(
            "{}: cannot start the {what} process: {e}",
            dir.display()
        ))
    })
}

/// Builds the command of a child process.
pub type ChildCommand = Arc<dyn Fn(ChildTask<'_>) -> Command + Send + Sync>;

/// Where runs execute.
///
/// ```
/// use a2perf_pipeline::isolate::Isolation;
/// assert!(matches!(Isolation::default(), Isolation::InProcess));
/// ```
#[derive(Clone, Default)]
pub enum Isolation {
    /// In this process (in threads when `jobs > 1`): the meters measure the whole process.
    #[default]
    InProcess,
    /// Each run's training, inference and generalization in a child process of its own.
    Children(ChildCommand),
}

impl std::fmt::Debug for Isolation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Isolation::InProcess => "InProcess",
            Isolation::Children(_) => "Children",
        })
    }
}

/// Runs `command` to its end, in a process group of its own (so that a Ctrl-C at the terminal
/// reaches only this process), and sends it one SIGTERM when `cancel` fires: a training child
/// then writes a resume point and stops, as this process's runs do.
pub fn run_child(mut command: Command, cancel: &CancelToken) -> std::io::Result<ExitStatus> {
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        command.process_group(0);
    }
    let mut child = command.spawn()?;
    let mut forwarded = false;
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(status);
        }
        if cancel.is_cancelled() && !forwarded {
            terminate(child.id());
            forwarded = true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Sends SIGTERM to process `pid` (elsewhere than on Unix: ends it).
fn terminate(pid: u32) {
    let pid = ::sysinfo::Pid::from_u32(pid);
    let Ok(mut sys) = ::sysinfo::System::new() else {
        return;
    };
    sys.refresh_processes(::sysinfo::ProcessesToUpdate::Some(&[pid]), true);
    if let Some(p) = sys.process(pid)
        && p.kill_with(::sysinfo::Signal::Term).is_none()
    {
        p.kill();
    }
}

/// Trains the run in `dir` in a child process: the child's [`RunReport`], or a failure naming how
/// the child ended when it left none. A complete run is skipped without starting one.
pub(crate) fn train_in_child(
    command: &ChildCommand,
    dir: &Path,
    cancel: &CancelToken,
) -> Result<RunReport> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    if RunDir::new(dir).is_complete().unwrap_or(false) {
        return Ok(RunReport {
            outcome: RunOutcome::Skipped,
            resumed_from: None,
            warnings: Vec::new(),
        });
    }
    let report = std::env::temp_dir().join(format!(
        "a2perf-run-report-{}-{}.json",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let task = ChildTask::Train {
        run: dir,
        report: &report,
    };
    let status = run_task(command, task, cancel)?;
    let written = std::fs::read(&report);
    let _ = std::fs::remove_file(&report);
    match written
        .ok()
        .and_then(|b| serde_json::from_slice::<RunReport>(&b).ok())
    {
        Some(r) => Ok(r),
        None => Ok(RunReport {
            outcome: RunOutcome::Failed(format!(
                "the run's process ended without a report ({status}); its error is printed \
                 above"
            )),
            resumed_from: None,
            warnings: Vec::new(),
        }),
    }
}

/// Runs `task` (inference or generalization of one run) in a child process; an error when it does
/// not succeed, [`PipelineError::Cancelled`] when `cancel` fired meanwhile.
pub(crate) fn phase_in_child(
    command: &ChildCommand,
    task: ChildTask<'_>,
    cancel: &CancelToken,
) -> Result<()> {
    let (what, dir) = task.describe();
    let status = run_task(command, task, cancel)?;
    if cancel.is_cancelled() {
        return Err(PipelineError::Cancelled);
    }
    if !status.success() {
        return Err(PipelineError::Invalid(format!(
            "{}: the {what} process failed ({status}); its error is printed above",
            dir.display()
        )));
    }
    Ok(())
}

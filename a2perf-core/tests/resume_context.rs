//! The training context's side of resumption: when resume points are written, what cancellation
//! does with and without them, and what happens to a resume point the algorithm does not take.

use a2perf_core::{
    ActMode, Action, CancelToken, Checkpoint, CheckpointSink, Control, DiscardCheckpoints, Env,
    EnvError, EnvSpec, LearningCurve, Observation, Policy, PolicyError, ResumePoint, RunError,
    Space, Step, TrainingContext, TrainingProgress, TrainingSettings,
};

struct OneStep(EnvSpec);

impl Env for OneStep {
    fn spec(&self) -> &EnvSpec {
        &self.0
    }
    fn reset_into(&mut self, _: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        *obs = Observation::flat(vec![0.0]);
        Ok(())
    }
    fn step_into(&mut self, _: &Action, out: &mut Step) -> Result<(), EnvError> {
        out.reward = 1.0;
        out.terminated = true;
        Ok(())
    }
}

fn factory() -> impl Fn(usize) -> Result<Box<dyn Env>, EnvError> + Send + Sync {
    let spec = EnvSpec {
        id: "OneStep-v0".into(),
        observation_space: Space::uniform_box(&[1], 0.0, 1.0),
        action_space: Space::Discrete { n: 1 },
        max_episode_steps: Some(1),
        metadata: Default::default(),
    };
    move |_| Ok(Box::new(OneStep(spec.clone())) as Box<dyn Env>)
}

struct Zero;

impl Policy for Zero {
    fn act(&mut self, _: &Observation, _: ActMode) -> Result<Action, PolicyError> {
        Ok(Action::Discrete(0))
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Ok(Checkpoint {
            algorithm: "zero".into(),
            format_version: 1,
            payload: Vec::new(),
        })
    }
}

/// Records what it is given.
#[derive(Default)]
struct Record {
    checkpoints: Vec<u64>,
    points: Vec<u64>,
    discarded: usize,
}

impl CheckpointSink for Record {
    fn save(&mut self, env_steps: u64, _: &Checkpoint) -> std::io::Result<()> {
        self.checkpoints.push(env_steps);
        Ok(())
    }
    fn keeps_resume_points(&self) -> bool {
        true
    }
    fn save_resume(&mut self, point: &ResumePoint) -> std::io::Result<u64> {
        self.points.push(point.progress.env_steps);
        Ok(point.to_bytes().len() as u64)
    }
    fn discard_resume_points(&mut self) -> std::io::Result<()> {
        self.discarded += 1;
        Ok(())
    }
}

fn settings() -> TrainingSettings {
    TrainingSettings {
        total_env_steps: 100,
        eval_interval: 25,
        eval_episodes: 1,
        checkpoint_interval: 30,
        num_envs: 1,
    }
}

#[test]
fn resume_points_come_at_checkpoint_intervals_and_at_cancellation() {
    let f = factory();
    let mut sink = Record::default();
    let cancel = CancelToken::new();
    let mut ctx = TrainingContext::new(&f, 0, settings(), &mut sink, cancel.clone());
    let mut calls = 0;
    let mut stopped = None;
    for steps in (10..=100).step_by(10) {
        if steps == 80 {
            cancel.cancel();
        }
        let r = ctx.progress_resumable(steps, &mut Zero, |_| {
            calls += 1;
            Ok(vec![steps as u8])
        });
        match r {
            Ok(Control::Continue) => {}
            Ok(Control::Stop) => unreachable!("the budget is not spent"),
            Err(RunError::Cancelled) => {
                stopped = Some(steps);
                break;
            }
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(stopped, Some(80));
    assert_eq!(calls, 3, "the state is asked for only when a point is due");
    let writes: Vec<u64> = ctx.resume_writes().iter().map(|w| w.env_steps).collect();
    assert_eq!(writes, vec![30, 60, 80]);
    // The interruption's point comes after that call's evaluation (80 ≥ 50 + 25 is due), so a
    // resumed run does not skip it.
    assert_eq!(
        ctx.curve()
            .points
            .iter()
            .map(|p| p.env_steps)
            .collect::<Vec<_>>(),
        vec![30, 50, 80]
    );
    drop(ctx);
    assert_eq!(sink.points, vec![30, 60, 80]);
    assert_eq!(sink.checkpoints, vec![30, 60]);
}

#[test]
fn without_opting_in_or_a_sink_that_keeps_points_cancellation_stops_at_once() {
    let f = factory();
    for opted_in in [false, true] {
        let cancel = CancelToken::new();
        cancel.cancel();
        // `DiscardCheckpoints` keeps no resume points.
        let mut discard = DiscardCheckpoints;
        let mut record = Record::default();
        let sink: &mut dyn CheckpointSink = if opted_in { &mut discard } else { &mut record };
        let mut ctx = TrainingContext::new(&f, 0, settings(), sink, cancel);
        let r = if opted_in {
            ctx.progress_resumable(30, &mut Zero, |_| panic!("no point is written"))
        } else {
            ctx.progress(30, &mut Zero)
        };
        assert!(matches!(r, Err(RunError::Cancelled)));
        assert!(ctx.curve().points.is_empty(), "no evaluation first");
    }
}

#[test]
fn a_resume_point_not_taken_is_dropped_with_a_warning() {
    let f = factory();
    let mut sink = Record::default();
    let point = ResumePoint {
        progress: TrainingProgress {
            env_steps: 60,
            curve: LearningCurve::default(),
            next_eval: 75,
            next_checkpoint: 90,
            last_checkpoint: Some(60),
            clock_s: 12.0,
        },
        state: vec![1],
    };
    let mut ctx =
        TrainingContext::new(&f, 0, settings(), &mut sink, CancelToken::new()).with_resume(point);
    // An algorithm that ignores resumption starts at step 0: its first progress call drops the
    // point, so nothing of it leaks into this run.
    assert_eq!(ctx.progress(30, &mut Zero).unwrap(), Control::Continue);
    assert_eq!(ctx.resumed_from(), None);
    assert_eq!(ctx.take_resume_state(), None);
    assert!(ctx.warnings()[0].contains("did not take the resume point at step 60"));
    assert_eq!(ctx.curve().points[0].env_steps, 30);
    assert!(ctx.clock() < 12.0);
    drop(ctx);
    assert_eq!(sink.discarded, 1);
    assert_eq!(sink.checkpoints, vec![30]);
}

//! Behavioural cloning: supervised learning of the demonstrator's action — masked cross-entropy
//! for discrete actions, Gaussian negative log-likelihood (learned state-independent std) or
//! mean-squared error for continuous ones.
//!
//! BC consumes no environment steps. Its budget `total_env_steps` counts *dataset samples drawn*
//! (so `total_env_steps / batch_size` gradient steps), and its curve's x axis is samples drawn; the
//! environment is used only to evaluate the policy.

use std::sync::Arc;

use a2perf_core::{
    Action, Algorithm, Control, EnvSpec, ParamKind, ParamSpec, Params, Policy, RngStream, RunError,
    TrainingContext, Value, hash::Fnv1a,
};

use crate::batch::{ObsBatch, ObsLayout};
use crate::common::*;
use crate::dataset::{DatasetError, DatasetLoader, JsonDatasetFile};
use crate::model::{DiscreteNet, GaussianArch, NetOptions};
use crate::nn::dist::{gaussian, masked};
use crate::nn::optim::{Adam, LrSchedule};
use crate::nn::{MlpWs, clip_grad_norm, ensure};
use crate::obs_store::ObsStore;
use crate::policy::{Head, NetPolicy, ObsNorm};
use crate::resume::{StateReader, StateWriter, resume_err};

/// Version of BC's resumable training state (2: observations are typed, so the
/// observation hashes and the stored observations of version 1 no longer apply).
const STATE_VERSION: u32 = 2;

/// FNV-1a over the demonstrations as loaded (observations and actions), so that a run is not
/// resumed on a dataset that changed: tensor by tensor, each one's values over every sample
/// (floats as bits, integers as `u32`), then every sample's action mask, then the actions.
fn fingerprint(store: &ObsStore, layout: &ObsLayout, act_d: &[usize], act_c: &[f32]) -> u64 {
    let mut h = Fnv1a::new();
    let mut eat = |x: u64| h.write_u64(x);
    let n = act_d.len();
    let mut row = ObsBatch::new(layout);
    row.resize(1);
    for t in 0..row.num_tensors() {
        for slot in 0..n {
            store.read_tensor(slot, t, &mut row, 0);
            if row.is_integer(t) {
                for v in row.int_row(t, 0) {
                    eat(u64::from(*v as u32));
                }
            } else {
                for v in row.tensor_row(t, 0) {
                    eat(u64::from(v.to_bits()));
                }
            }
        }
    }
    for slot in 0..n {
        store.read_mask(slot, &mut row, 0);
        for legal in row.mask(0).unwrap_or(&[]) {
            eat(u64::from(*legal));
        }
    }
    for a in act_d {
        eat(*a as u64);
    }
    for a in act_c {
        eat(u64::from(a.to_bits()));
    }
    h.finish()
}

/// BC hyperparameters.
#[derive(Clone, Debug, PartialEq)]
pub struct BcConfig {
    /// Learning-rate schedule.
    pub lr: LrSchedule,
    /// Minibatch size.
    pub batch_size: usize,
    /// Continuous loss: Gaussian NLL (`true`) or MSE on the mean.
    pub nll: bool,
    /// Normalise observations with the dataset's statistics.
    pub normalize_observations: bool,
    /// Gradient-norm clip.
    pub max_grad_norm: f32,
    /// Initial log-std (continuous).
    pub init_log_std: f32,
    /// Networks.
    pub net: NetOptions,
}

/// Behavioural cloning from a [`DatasetLoader`].
#[derive(Clone)]
pub struct Bc {
    /// Hyperparameters.
    pub config: BcConfig,
    /// Where the demonstrations come from.
    pub loader: Option<Arc<dyn DatasetLoader>>,
}

impl Bc {
    /// Documented hyperparameters (paper: batch 128, lr 1e-4 web / 1e-3 circuit).
    pub fn params() -> Vec<ParamSpec> {
        let mut v = vec![
            ParamSpec::new(
                "learning_rate",
                ParamKind::Float,
                Value::Float(1e-4),
                "Adam learning rate (paper: 1e-4 web, 1e-3 circuit)",
            ),
            ParamSpec::new(
                "batch_size",
                ParamKind::Int,
                Value::Int(128),
                "minibatch size (paper: 128)",
            ),
            ParamSpec::new(
                "loss",
                ParamKind::Choice(&["nll", "mse"]),
                Value::Str("nll".into()),
                "continuous actions: Gaussian negative log-likelihood or mean-squared error (discrete: cross-entropy)",
            ),
            ParamSpec::new(
                "dataset",
                ParamKind::Path,
                Value::Null,
                "JSON dataset file (see `Dataset::save_json`), or a dataset directory holding one as \
                 `samples.json` (`a2perf collect`'s); pipelines may supply a loader instead",
            ),
            ParamSpec::new(
                "normalize_observations",
                ParamKind::Bool,
                Value::Bool(true),
                "normalise observations with the dataset's statistics",
            ),
            ParamSpec::new(
                "max_grad_norm",
                ParamKind::Float,
                Value::Float(1.0),
                "global gradient-norm clipping, 0 = off",
            ),
            ParamSpec::new(
                "init_log_std",
                ParamKind::Float,
                Value::Float(-0.5),
                "initial log-std of the Gaussian policy (continuous actions)",
            ),
        ];
        v.extend(schedule_specs());
        v.extend(net_specs(&[64, 64]));
        v
    }

    /// Builds BC from resolved hyperparameters.
    pub fn from_params(p: &Params) -> Result<Self, RunError> {
        let lr = positive_f32(p, "learning_rate")?;
        let loader = p
            .opt_str("dataset")
            .map_err(hp)?
            .map(|path| Arc::new(JsonDatasetFile(dataset_file(path))) as Arc<dyn DatasetLoader>);
        Ok(Self {
            config: BcConfig {
                lr: schedule(p, lr)?,
                batch_size: positive_usize(p, "batch_size")?,
                nll: p.str("loss").map_err(hp)? == "nll",
                normalize_observations: p.bool("normalize_observations").map_err(hp)?,
                max_grad_norm: nonneg_f32(p, "max_grad_norm")?,
                init_log_std: p.f64("init_log_std").map_err(hp)? as f32,
                net: net_options(p)?,
            },
            loader,
        })
    }

    /// Uses `loader` for the demonstrations.
    pub fn with_loader(mut self, loader: Arc<dyn DatasetLoader>) -> Self {
        self.loader = Some(loader);
        self
    }
}

/// The JSON file `dataset` names: the path itself, or the `samples.json` inside a dataset
/// directory (what `a2perf collect` writes).
fn dataset_file(dataset: &str) -> std::path::PathBuf {
    let path = std::path::PathBuf::from(dataset);
    if path.is_dir() {
        path.join("samples.json")
    } else {
        path
    }
}

fn data_err(e: DatasetError) -> RunError {
    RunError::InvalidHyperparameter {
        name: "dataset".into(),
        reason: e.to_string(),
    }
}

impl Algorithm for Bc {
    fn name(&self) -> &str {
        "bc"
    }

    /// Resumable: the state saved at every checkpoint interval holds the policy (parameters,
    /// the dataset's normalisation statistics), Adam, the minibatch stream, the samples drawn
    /// and a fingerprint of the dataset (a changed dataset is refused).
    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError> {
        let cfg = self.config.clone();
        let resume = ctx.take_resume_state();
        let loader = self.loader.clone().ok_or_else(|| {
            invalid(
                "dataset",
                "behavioural cloning needs demonstrations: set `dataset` to a JSON dataset file or a dataset directory",
            )
        })?;
        let spec = ctx.make_env(0)?.spec().clone();
        let layout = ObsLayout::from_spec(&spec)?;
        let head = head_for(&spec, &layout, &cfg.net, false)?;
        let demos = Demonstrations::load(loader.as_ref(), &spec, &layout, &head)?;
        let params = initial_params(&head, &mut ctx.rng("bc/init"), cfg.init_log_std)?;
        let mut obs_norm = if cfg.normalize_observations {
            ObsNorm::for_head(&head, &layout)
        } else {
            None
        };
        let normalised = match &mut obs_norm {
            Some(norm) => demos.normalised_tensors(norm, &layout),
            None => Vec::new(),
        };
        let mut policy = NetPolicy::new("bc", &spec, head, params, obs_norm, ctx.seed())?;
        let mut run = BcRun::new(cfg, layout, demos, normalised, &policy, ctx);
        if let Some(bytes) = &resume {
            run.restore(bytes, &mut policy)?;
        }
        loop {
            let learn = std::time::Instant::now();
            run.step(&mut policy)?;
            let seconds = learn.elapsed().as_secs_f64();
            ctx.time_split_mut()
                .add(a2perf_core::TimePart::Learn, seconds);
            let save = |p: &NetPolicy| Ok(run.save_state(p));
            if ctx.progress_resumable(run.samples, &mut policy, save)? == Control::Stop {
                break;
            }
        }
        check_finite("BC parameters", &policy.params)?;
        ctx.finish(run.samples, &mut policy)?;
        Ok(Box::new(policy))
    }
}

/// The demonstrations as BC reads them: their observations, compact and exact (see
/// `obs_store`: a netlist's adjacency is kept once, token ids in a byte or two, masks in bits;
/// sample `i` is slot `i`), and their actions.
struct Demonstrations {
    store: ObsStore,
    act_d: Vec<usize>,
    act_c: Vec<f32>,
    /// Number of samples.
    n: usize,
    /// Fingerprint of the observations and actions (see [`fingerprint`]).
    fingerprint: u64,
}

impl Demonstrations {
    /// The samples of `loader` for `spec`, checked against its spaces. The loader hands them
    /// over one at a time (a JSON file is parsed as it is read), so the dataset is never held
    /// whole beside the store.
    fn load(
        loader: &dyn DatasetLoader,
        spec: &EnvSpec,
        layout: &ObsLayout,
        head: &Head,
    ) -> Result<Self, RunError> {
        let act_dim = match head {
            Head::Gaussian(g) => g.act_dim,
            _ => 0,
        };
        let n_actions = layout.num_actions.unwrap_or(0);
        let mut store = ObsStore::new(layout);
        let mut row = ObsBatch::new(layout);
        row.resize(1);
        let (mut act_d, mut act_c) = (Vec::new(), Vec::new());
        let mismatch = |reason: String| DatasetError::Mismatch {
            env: spec.id.clone(),
            reason,
        };
        let n = loader
            .for_each_sample(spec, &mut |s| {
                let i = act_d.len();
                row.write_row(0, &s.observation)
                    .map_err(|e| mismatch(format!("sample {i}: {e}")))?;
                match (&s.action, act_dim) {
                    (Action::Discrete(a), 0) => {
                        if *a >= n_actions || !row.mask(0).is_none_or(|m| m[*a]) {
                            return Err(mismatch(format!(
                                "sample {i}: action {a} is out of range or masked out"
                            )));
                        }
                        act_d.push(*a);
                    }
                    (Action::Continuous(v), d) if v.len() == d && d > 0 => {
                        act_d.push(0);
                        act_c.extend_from_slice(v);
                    }
                    _ => {
                        return Err(mismatch(format!(
                            "sample {i}: action {:?} does not fit the action space",
                            s.action
                        )));
                    }
                }
                store.insert(&row, 0);
                Ok(())
            })
            .map_err(data_err)?;
        if n == 0 {
            return Err(data_err(mismatch("the dataset is empty".into())));
        }
        let fingerprint = fingerprint(&store, layout, &act_d, &act_c);
        Ok(Self {
            store,
            act_d,
            act_c,
            n,
            fingerprint,
        })
    }

    /// The tensors `norm` normalises (`[n, dim]` each), decoded and normalised once with the
    /// dataset's statistics, which `norm` takes here: minibatches read them from here, every
    /// other tensor from the store.
    fn normalised_tensors(&self, norm: &mut ObsNorm, layout: &ObsLayout) -> Vec<(usize, Vec<f32>)> {
        let n = self.n;
        let mut row = ObsBatch::new(layout);
        row.resize(1);
        let mut normalised = Vec::new();
        for (&t, stats) in norm.tensors.iter().zip(norm.stats.iter_mut()) {
            let d = layout.dim(t);
            let mut all = vec![0.0f32; n * d];
            for (slot, dst) in all.chunks_exact_mut(d.max(1)).enumerate() {
                self.store.read_tensor(slot, t, &mut row, 0);
                dst.copy_from_slice(row.tensor_row(t, 0));
            }
            stats.update(&all, n);
            for r in all.chunks_exact_mut(d.max(1)) {
                stats.apply(r);
            }
            normalised.push((t, all));
        }
        normalised
    }
}

/// Everything a BC run updates besides the policy: the optimiser, the minibatch stream, the
/// samples drawn, and the demonstrations with the workspaces of a step.
struct BcRun {
    cfg: BcConfig,
    layout: ObsLayout,
    demos: Demonstrations,
    /// See [`Demonstrations::normalised_tensors`].
    normalised: Vec<(usize, Vec<f32>)>,
    n_actions: usize,
    act_dim: usize,
    adam: Adam,
    grads: Vec<f32>,
    rng: RngStream,
    mb: ObsBatch,
    idx: Vec<usize>,
    x: Vec<f32>,
    ws: MlpWs,
    dl: Vec<f32>,
    lp: Vec<f32>,
    /// The discrete minibatch's legal actions, row after row (`legal_rows[k]..legal_rows[k +
    /// 1]` is row `k`'s): the entries of `dl` a step sets and clears.
    legal: Vec<usize>,
    legal_rows: Vec<usize>,
    dlog_std: Vec<f32>,
    total: u64,
    /// Dataset samples drawn so far (BC's budget and curve axis).
    samples: u64,
}

impl BcRun {
    fn new(
        cfg: BcConfig,
        layout: ObsLayout,
        demos: Demonstrations,
        normalised: Vec<(usize, Vec<f32>)>,
        policy: &NetPolicy,
        ctx: &TrainingContext<'_>,
    ) -> Self {
        let act_dim = match &policy.head {
            Head::Gaussian(g) => g.act_dim,
            _ => 0,
        };
        Self {
            n_actions: layout.num_actions.unwrap_or(0),
            act_dim,
            adam: Adam::new(policy.params.len()),
            grads: vec![0.0; policy.params.len()],
            rng: ctx.rng("bc/minibatch"),
            mb: ObsBatch::new(&layout),
            idx: Vec::new(),
            x: Vec::new(),
            ws: MlpWs::default(),
            dl: Vec::new(),
            lp: Vec::new(),
            legal: Vec::new(),
            legal_rows: Vec::new(),
            dlog_std: vec![0.0; act_dim],
            total: ctx.settings().total_env_steps.max(1),
            samples: 0,
            cfg,
            layout,
            demos,
            normalised,
        }
    }

    /// Continues from a state written by [`save_state`](Self::save_state), on the same dataset.
    fn restore(&mut self, bytes: &[u8], policy: &mut NetPolicy) -> Result<(), RunError> {
        let mut r = StateReader::new(bytes, "bc", STATE_VERSION)?;
        if r.u64()? != self.demos.fingerprint {
            return Err(resume_err(
                "the dataset differs from the one training started on",
            ));
        }
        policy.load_training_state(&mut r)?;
        self.adam.load("policy", &mut r)?;
        self.rng = r.rng()?;
        self.samples = r.u64()?;
        r.finish()
    }

    /// The state [`restore`](Self::restore) continues from.
    fn save_state(&self, policy: &NetPolicy) -> Vec<u8> {
        let mut w = StateWriter::new("bc", STATE_VERSION);
        w.u64(self.demos.fingerprint);
        policy.save_training_state(&mut w);
        self.adam.save(&mut w);
        w.rng(&self.rng);
        w.u64(self.samples);
        w.finish()
    }

    /// One gradient step on `batch_size` samples drawn with replacement.
    fn step(&mut self, policy: &mut NetPolicy) -> Result<(), RunError> {
        let b = self.cfg.batch_size;
        self.draw_minibatch(b);
        let inv = 1.0 / b as f32;
        self.grads.fill(0.0);
        match &mut policy.head {
            Head::Discrete(net) => self.discrete_gradient(net, &policy.params, inv),
            Head::Gaussian(g) => self.gaussian_gradient(g, &policy.params, inv),
            Head::Squashed(_) => {}
        }
        clip_grad_norm(&mut self.grads, self.cfg.max_grad_norm);
        self.adam.step(
            &mut policy.params,
            &self.grads,
            self.cfg.lr.at(self.samples as f64 / self.total as f64),
        );
        self.samples += b as u64;
        if self.adam.steps().is_multiple_of(100) {
            check_finite("BC parameters", &policy.params)?;
        }
        Ok(())
    }

    /// `b` samples into `mb` (their indices in `idx`), normalised tensors from `normalised`.
    fn draw_minibatch(&mut self, b: usize) {
        let n = self.demos.n;
        self.idx.clear();
        self.idx.extend((0..b).map(|_| self.rng.index(n)));
        self.mb.resize(b);
        for (k, &r) in self.idx.iter().enumerate() {
            self.demos.store.read(r, &mut self.mb, k);
            for (t, all) in &self.normalised {
                let d = self.layout.dim(*t);
                self.mb
                    .row_mut(*t, k)
                    .copy_from_slice(&all[r * d..(r + 1) * d]);
            }
        }
    }

    /// Cross-entropy −log p(a) of the demonstrated actions under the masked categorical.
    ///
    /// With an action mask, the softmax and its gradient visit the legal actions only
    /// ([`masked::grad_logp_legal`], the same values): a web page leaves most of its 12,500
    /// actions illegal. `dl` is all zeros between steps (each step clears the entries it set),
    /// which spares a `[B, n]` fill.
    fn discrete_gradient(&mut self, net: &mut DiscreteNet, params: &[f32], inv: f32) {
        let (n, b) = (self.n_actions, self.idx.len());
        net.forward(params, &self.mb);
        ensure(&mut self.dl, b * n);
        self.legal_rows.clear();
        self.legal.clear();
        for (k, &r) in self.idx.iter().enumerate() {
            let logits = &net.logits()[k * n..(k + 1) * n];
            let dl = &mut self.dl[k * n..(k + 1) * n];
            let action = self.demos.act_d[r];
            let start = self.legal.len();
            match self.mb.mask(k) {
                Some(mask) => {
                    self.legal
                        .extend(mask.iter().enumerate().filter(|(_, m)| **m).map(|(i, _)| i));
                    masked::grad_logp_legal(logits, &self.legal[start..], action, -inv, dl);
                }
                None => {
                    self.legal.extend(0..n);
                    ensure(&mut self.lp, n);
                    let l = &mut self.lp[..n];
                    masked::log_softmax(logits, None, l);
                    masked::grad_logp(l, action, -inv, dl);
                }
            }
            self.legal_rows.push(start);
        }
        self.legal_rows.push(self.legal.len());
        net.backward(params, &mut self.grads, &self.mb, &self.dl, None);
        for k in 0..b {
            let dl = &mut self.dl[k * n..(k + 1) * n];
            for &i in &self.legal[self.legal_rows[k]..self.legal_rows[k + 1]] {
                dl[i] = 0.0;
            }
        }
    }

    /// Gaussian negative log-likelihood of the demonstrated actions (mean network and
    /// log-std), or the mean's squared error.
    fn gaussian_gradient(&mut self, g: &GaussianArch, params: &[f32], inv: f32) {
        let (act_dim, b) = (self.act_dim, self.idx.len());
        self.mb.concat_into(&mut self.x);
        let mean = g.actor.forward(params, &self.x, b, &mut self.ws);
        let log_std = &params[g.log_std..g.log_std + act_dim];
        ensure(&mut self.dl, b * act_dim);
        self.dl[..b * act_dim].fill(0.0);
        self.dlog_std.fill(0.0);
        for (k, &r) in self.idx.iter().enumerate() {
            let m = &mean[k * act_dim..(k + 1) * act_dim];
            let a = &self.demos.act_c[r * act_dim..(r + 1) * act_dim];
            let d = &mut self.dl[k * act_dim..(k + 1) * act_dim];
            if self.cfg.nll {
                gaussian::grad_log_prob(m, log_std, a, -inv, d, &mut self.dlog_std);
            } else {
                for j in 0..act_dim {
                    d[j] = 2.0 * (m[j] - a[j]) * inv / act_dim as f32;
                }
            }
        }
        g.actor.backward(
            params,
            &mut self.grads,
            &self.x,
            &self.dl,
            &mut self.ws,
            None,
        );
        for (j, v) in self.dlog_std.iter().enumerate() {
            self.grads[g.log_std + j] += v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::dataset_file;

    #[test]
    fn a_dataset_directory_names_its_samples_file() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().to_str().unwrap();
        assert_eq!(dataset_file(d), dir.path().join("samples.json"));
        let file = dir.path().join("demos.json");
        std::fs::write(&file, "{}").unwrap();
        assert_eq!(dataset_file(file.to_str().unwrap()), file);
        // A missing path stays as given, so the error names it.
        let missing = dir.path().join("missing.json");
        assert_eq!(dataset_file(missing.to_str().unwrap()), missing);
    }
}

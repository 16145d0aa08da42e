//! [`NetPolicy`]: the trained policy of every baseline, and its checkpoint format.
//!
//! # Checkpoint payload, format version 1
//!
//! The payload sits inside [`a2perf_core::Checkpoint`] (whose container already carries the
//! algorithm name, the payload version and a checksum). All integers are little-endian.
//!
//! | bytes | content |
//! |---|---|
//! | 4 | magic `A2BL` |
//! | 4 | `u32` payload version (= [`PAYLOAD_VERSION`], repeated so a payload is self-describing) |
//! | 4 | `u32` header length *H* |
//! | *H* | UTF-8 JSON header: algorithm, observation layout, network architecture, action space, exploration ε, normalised tensor dims |
//! | 8 | `u64` parameter count *P* |
//! | 4·*P* | parameters, `f32` |
//! | 16·Σdims | for each normalised tensor: means then variances, `f64`, followed by one `f64` sample count |
//!
//! Floats are stored as raw bits, so a save/load round trip is bit-exact. Loading checks the
//! magic, both versions, the algorithm name, the observation layout against the environment's
//! spec, every length, and rejects trailing bytes.

use a2perf_core::bytes::ByteReader;
use a2perf_core::{
    ActMode, Action, Checkpoint, EnvSpec, Observation, Policy, PolicyError, RngStream, Space,
};
use serde::{Deserialize, Serialize};

use crate::batch::{ObsBatch, ObsLayout};
use crate::model::{DiscreteArch, DiscreteNet, GaussianArch, SquashedArch};
use crate::nn::MlpWs;
use crate::nn::dist::{masked, tanh_gaussian};
use crate::nn::norm::RunningNorm;
use crate::nn::tanh::tanh;

/// Version of the payload format written by [`NetPolicy::checkpoint`].
pub const PAYLOAD_VERSION: u32 = 1;
const MAGIC: &[u8; 4] = b"A2BL";

/// The network that produces actions.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)] // one per policy, never in collections
pub enum Head {
    /// Logits or Q-values over a (masked) discrete space.
    Discrete(DiscreteNet),
    /// Diagonal Gaussian with state-independent log-std.
    Gaussian(GaussianArch),
    /// Tanh-squashed Gaussian (SAC).
    Squashed(SquashedArch),
}

#[derive(Clone, Serialize, Deserialize)]
enum HeadSpec {
    Discrete {
        arch: DiscreteArch,
        n: usize,
        num_params: usize,
    },
    Gaussian(GaussianArch),
    Squashed(SquashedArch),
}

/// Running normalisation of some observation tensors.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsNorm {
    /// Indices of the normalised tensors in the layout.
    pub tensors: Vec<usize>,
    /// Their statistics.
    pub stats: Vec<RunningNorm>,
}

impl ObsNorm {
    /// Normalisation for the tensors that carry real-valued features: every float tensor for
    /// the MLP fallback, `features` for the circuit network, nothing for the web network. Integer
    /// tensors (token ids, indices, flags) are never shifted: they stay exact.
    pub fn for_head(head: &Head, layout: &ObsLayout) -> Option<Self> {
        let floats = || (0..layout.tensors.len()).filter(|&i| !layout.is_integer(i));
        let tensors: Vec<usize> = match head {
            Head::Discrete(net) => match net.kind() {
                "web" => Vec::new(),
                "circuit" => layout.index("features").into_iter().collect(),
                _ => floats().collect(),
            },
            _ => floats().collect(),
        };
        if tensors.is_empty() {
            return None;
        }
        let stats = tensors
            .iter()
            .map(|&i| RunningNorm::new(layout.dim(i)))
            .collect();
        Some(Self { tensors, stats })
    }

    /// Normalises row `row` of `batch` in place.
    pub fn apply(&self, batch: &mut ObsBatch, row: usize) {
        for (&t, s) in self.tensors.iter().zip(&self.stats) {
            s.apply(batch.row_mut(t, row));
        }
    }

    /// Adds rows `0..rows` of `batch` (raw values) to the statistics.
    pub fn update(&mut self, batch: &ObsBatch, rows: usize) {
        for (&t, s) in self.tensors.iter().zip(self.stats.iter_mut()) {
            s.update(batch.tensor(t), rows);
        }
    }
}

/// Whether a checkpoint's action space is `current`. Box bounds are compared as `f32`: the
/// checkpoints written before spaces were typed stored `f32` bounds, which read back as the
/// nearest `f64` of their decimal text, not the `f64` of the `f32`.
fn same_action_space(saved: &Space, current: &Space) -> bool {
    match (saved, current) {
        (
            Space::Box {
                low: l1,
                high: h1,
                shape: s1,
                dtype: d1,
            },
            Space::Box {
                low: l2,
                high: h2,
                shape: s2,
                dtype: d2,
            },
        ) => {
            let same = |a: &[f64], b: &[f64]| {
                a.len() == b.len() && a.iter().zip(b).all(|(x, y)| *x as f32 == *y as f32)
            };
            s1 == s2 && d1 == d2 && same(l1, l2) && same(h1, h2)
        }
        _ => saved == current,
    }
}

#[derive(Serialize, Deserialize)]
struct Header {
    algorithm: String,
    layout: ObsLayout,
    head: HeadSpec,
    action_space: Space,
    explore_epsilon: f32,
    norm_tensors: Vec<usize>,
    norm_dims: Vec<usize>,
    norm_clip: f32,
    #[serde(default)]
    action_limit: f32,
}

fn bad(m: String) -> PolicyError {
    PolicyError::BadCheckpoint(m)
}

/// Checks a checkpoint's container and payload header against `algorithm`; returns the
/// header and the reader at the parameters.
fn read_header<'a>(
    ckpt: &'a Checkpoint,
    algorithm: &str,
) -> Result<(ByteReader<'a>, Header), PolicyError> {
    if ckpt.algorithm != algorithm {
        return Err(bad(format!(
            "checkpoint was written by `{}`, not `{algorithm}`",
            ckpt.algorithm
        )));
    }
    if ckpt.format_version != PAYLOAD_VERSION {
        return Err(bad(format!(
            "payload format version {} is not supported (this build reads {PAYLOAD_VERSION})",
            ckpt.format_version
        )));
    }
    let mut r = ByteReader::new(&ckpt.payload);
    if r.take(4)? != MAGIC {
        return Err(bad(
            "payload is not an a2perf-baselines network (bad magic)".into(),
        ));
    }
    let version = r.u32()?;
    if version != PAYLOAD_VERSION {
        return Err(bad(format!("payload version {version} is not supported")));
    }
    let hlen = r.u32()? as usize;
    let header: Header =
        serde_json::from_slice(r.take(hlen)?).map_err(|e| bad(format!("malformed header: {e}")))?;
    if header.algorithm != algorithm {
        return Err(bad(format!(
            "payload header names algorithm `{}`, expected `{algorithm}`",
            header.algorithm
        )));
    }
    Ok((r, header))
}

/// The network of `header` for environment `spec` and its number of parameters. A circuit
/// placement network does not depend on the netlist's size, so it may run on other circuits;
/// every other network needs exactly the observations and actions it was trained on.
fn head_for_env(
    header: &Header,
    spec: &EnvSpec,
    layout: &ObsLayout,
) -> Result<(Head, usize), PolicyError> {
    let mut head_spec = header.head.clone();
    if !layout.same_shapes(&header.layout)
        || !same_action_space(&header.action_space, &spec.action_space)
    {
        match &mut head_spec {
            HeadSpec::Discrete {
                arch: DiscreteArch::Circuit(c),
                n,
                ..
            } => {
                c.retarget(spec, layout).map_err(|why| {
                    bad(format!(
                        "checkpoint's circuit network cannot run on environment `{}`: {why}",
                        spec.id
                    ))
                })?;
                *n = layout.num_actions.unwrap_or(0);
            }
            _ if !layout.same_shapes(&header.layout) => {
                return Err(bad(format!(
                    "checkpoint was trained on observations {:?} but environment `{}` produces {:?}",
                    header.layout.tensors, spec.id, layout.tensors
                )));
            }
            _ => {
                return Err(bad(format!(
                    "checkpoint's action space differs from environment `{}`'s",
                    spec.id
                )));
            }
        }
    }
    if let HeadSpec::Discrete { arch, .. } = &head_spec {
        arch.check_dtypes(layout).map_err(|why| {
            bad(format!(
                "checkpoint's network cannot run on environment `{}`: {why}",
                spec.id
            ))
        })?;
    }
    Ok(match head_spec {
        HeadSpec::Discrete {
            arch,
            n,
            num_params,
        } => (
            Head::Discrete(DiscreteNet::from_arch(arch, n, num_params)),
            num_params,
        ),
        HeadSpec::Gaussian(g) => {
            let n = g.num_params;
            (Head::Gaussian(g), n)
        }
        HeadSpec::Squashed(s) => {
            let n = s.num_params;
            (Head::Squashed(s), n)
        }
    })
}

/// The observation statistics stored after the parameters, if the header names any.
fn read_obs_norm(
    header: &Header,
    spec: &EnvSpec,
    layout: &ObsLayout,
    r: &mut ByteReader<'_>,
) -> Result<Option<ObsNorm>, PolicyError> {
    if header.norm_tensors.is_empty() {
        return Ok(None);
    }
    if header.norm_tensors.len() != header.norm_dims.len() {
        return Err(bad("normalisation tensors and dims disagree".into()));
    }
    let mut stats = Vec::new();
    for (&t, &d) in header.norm_tensors.iter().zip(&header.norm_dims) {
        if t >= layout.tensors.len() || layout.dim(t) != d {
            return Err(bad(format!(
                "normalisation of tensor {t} has the wrong size"
            )));
        }
        if layout.is_integer(t) {
            return Err(bad(format!(
                "the checkpoint normalises tensor `{}`, which environment `{}` gives as \
                 {} (integers are never normalised); retrain the policy",
                layout.tensors[t].0,
                spec.id,
                layout.dtype(t)
            )));
        }
        let mut s = RunningNorm::new(d);
        s.clip = header.norm_clip;
        for v in s.mean.iter_mut().chain(s.var.iter_mut()) {
            *v = r.f64()?;
        }
        s.count = r.f64()?;
        stats.push(s);
    }
    Ok(Some(ObsNorm {
        tensors: header.norm_tensors.clone(),
        stats,
    }))
}

/// A neural-network policy (any of the baselines). Greedy actions are deterministic; exploring
/// actions come from the policy's own seeded stream.
#[derive(Clone, Debug)]
pub struct NetPolicy {
    /// Algorithm that trained it (checkpoint loader key).
    pub algorithm: String,
    /// Observation layout.
    pub layout: ObsLayout,
    /// The network.
    pub head: Head,
    /// Parameters.
    pub params: Vec<f32>,
    /// Observation normalisation, frozen at inference.
    pub obs_norm: Option<ObsNorm>,
    /// Action space (bounds for continuous actions).
    pub action_space: Space,
    /// ε of ε-greedy exploration (DDQN); 0 = sample from the policy distribution.
    pub explore_epsilon: f32,
    /// Squashed (SAC) actions span `centre ± action_limit` (capped at the bounds); 0 = the full
    /// bounds.
    pub action_limit: f32,
    batch: ObsBatch,
    ws: MlpWs,
    x: Vec<f32>,
    logp: Vec<f32>,
    rng: RngStream,
}

impl NetPolicy {
    /// A policy with the given network and parameters.
    pub fn new(
        algorithm: &str,
        spec: &EnvSpec,
        head: Head,
        params: Vec<f32>,
        obs_norm: Option<ObsNorm>,
        seed: u64,
    ) -> Result<Self, PolicyError> {
        let layout = ObsLayout::from_spec(spec)?;
        Ok(Self {
            algorithm: algorithm.to_string(),
            batch: ObsBatch::new(&layout),
            layout,
            head,
            params,
            obs_norm,
            action_space: spec.action_space.clone(),
            explore_epsilon: 0.0,
            action_limit: 0.0,
            ws: MlpWs::default(),
            x: Vec::new(),
            logp: Vec::new(),
            rng: RngStream::new(seed, "policy/explore"),
        })
    }

    /// Greedy action for a batch row already in `self.batch` (after forward).
    fn act_loaded(&mut self, mode: ActMode) -> Result<Action, PolicyError> {
        match &mut self.head {
            Head::Discrete(net) => {
                net.forward(&self.params, &self.batch);
                let logits = net.logits();
                let mask = self.batch.mask(0);
                let explore = mode == ActMode::Explore;
                if explore && self.explore_epsilon > 0.0 {
                    if self.rng.uniform() < f64::from(self.explore_epsilon) {
                        return self
                            .action_space
                            .sample(&mut self.rng, mask)
                            .ok_or(PolicyError::NoLegalAction);
                    }
                } else if explore {
                    crate::nn::ensure(&mut self.logp, logits.len());
                    let lp = &mut self.logp[..logits.len()];
                    if !masked::log_softmax(logits, mask, lp) {
                        return Err(PolicyError::NoLegalAction);
                    }
                    return masked::sample(lp, &mut self.rng)
                        .map(Action::Discrete)
                        .ok_or(PolicyError::NoLegalAction);
                }
                masked::argmax(logits, mask)
                    .map(Action::Discrete)
                    .ok_or(PolicyError::NoLegalAction)
            }
            Head::Gaussian(g) => {
                self.batch.concat_into(&mut self.x);
                let mean = g.actor.forward(&self.params, &self.x, 1, &mut self.ws);
                let explore = mode == ActMode::Explore;
                let (params, rng) = (&self.params, &mut self.rng);
                let a = mean
                    .iter()
                    .enumerate()
                    .map(|(i, m)| {
                        if explore {
                            m + params[g.log_std + i].exp() * rng.normal() as f32
                        } else {
                            *m
                        }
                    })
                    .zip(bounds(&self.action_space))
                    .map(|(x, (l, h))| x.clamp(l, h))
                    .collect();
                Ok(Action::Continuous(a))
            }
            Head::Squashed(s) => {
                self.batch.concat_into(&mut self.x);
                let out = s.actor.forward(&self.params, &self.x, 1, &mut self.ws);
                let d = s.act_dim;
                let explore = mode == ActMode::Explore;
                let (rng, limit) = (&mut self.rng, self.action_limit);
                let a = (0..d)
                    .map(|i| {
                        if explore {
                            let sigma = tanh_gaussian::log_std(out[d + i]).exp();
                            tanh(out[i] + sigma * rng.normal() as f32)
                        } else {
                            tanh(out[i])
                        }
                    })
                    .zip(bounds(&self.action_space))
                    .map(|(x, (l, h))| {
                        if l.is_finite() && h.is_finite() {
                            squash_to_bounds(x, l, h, limit)
                        } else {
                            x
                        }
                    })
                    .collect();
                Ok(Action::Continuous(a))
            }
        }
    }

    fn encode(&self) -> Result<Vec<u8>, PolicyError> {
        let head = match &self.head {
            Head::Discrete(net) => HeadSpec::Discrete {
                arch: net.arch.clone(),
                n: net.num_actions(),
                num_params: net.num_params(),
            },
            Head::Gaussian(g) => HeadSpec::Gaussian(g.clone()),
            Head::Squashed(s) => HeadSpec::Squashed(s.clone()),
        };
        let (norm_tensors, norm_dims, norm_clip) = match &self.obs_norm {
            Some(n) => (
                n.tensors.clone(),
                n.stats.iter().map(|s| s.mean.len()).collect(),
                n.stats.first().map_or(10.0, |s| s.clip),
            ),
            None => (Vec::new(), Vec::new(), 10.0),
        };
        let header = Header {
            algorithm: self.algorithm.clone(),
            layout: self.layout.clone(),
            head,
            action_space: self.action_space.clone(),
            explore_epsilon: self.explore_epsilon,
            norm_tensors,
            norm_dims,
            norm_clip,
            action_limit: self.action_limit,
        };
        let json =
            serde_json::to_vec(&header).map_err(|e| PolicyError::BadCheckpoint(e.to_string()))?;
        let mut out = Vec::with_capacity(32 + json.len() + 4 * self.params.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&PAYLOAD_VERSION.to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(&json);
        out.extend_from_slice(&(self.params.len() as u64).to_le_bytes());
        for p in &self.params {
            out.extend_from_slice(&p.to_le_bytes());
        }
        if let Some(n) = &self.obs_norm {
            for s in &n.stats {
                for v in s.mean.iter().chain(&s.var).chain(std::iter::once(&s.count)) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        Ok(out)
    }

    /// Rebuilds a policy saved by `algorithm` for the environment `spec`.
    pub fn from_checkpoint(
        ckpt: &Checkpoint,
        spec: &EnvSpec,
        algorithm: &str,
    ) -> Result<Self, PolicyError> {
        let (mut r, header) = read_header(ckpt, algorithm)?;
        let layout = ObsLayout::from_spec(spec)?;
        let (head, expected) = head_for_env(&header, spec, &layout)?;
        let count = r.u64()?;
        if count != expected as u64 {
            return Err(bad(format!(
                "{count} parameters stored, the network needs {expected}"
            )));
        }
        let raw = r.take(
            expected
                .checked_mul(4)
                .ok_or_else(|| bad("too many parameters".into()))?,
        )?;
        let params: Vec<f32> = raw
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let obs_norm = read_obs_norm(&header, spec, &layout, &mut r)?;
        if r.remaining() != 0 {
            return Err(bad(format!(
                "{} trailing bytes after the payload",
                r.remaining()
            )));
        }
        if params.iter().any(|p| !p.is_finite()) {
            return Err(bad("parameters contain non-finite values".into()));
        }
        let mut p = Self::new(algorithm, spec, head, params, obs_norm, 0)?;
        p.explore_epsilon = header.explore_epsilon;
        p.action_limit = header.action_limit;
        Ok(p)
    }

    /// Writes what training changes in the policy: parameters, normalisation statistics and the
    /// exploration stream (for resumable training).
    pub(crate) fn save_training_state(&self, w: &mut crate::resume::StateWriter) {
        w.f32s(&self.params);
        w.bool(self.obs_norm.is_some());
        if let Some(n) = &self.obs_norm {
            w.usizes(&n.tensors);
            for s in &n.stats {
                s.save(w);
            }
        }
        w.rng(&self.rng);
    }

    /// Restores what [`save_training_state`](Self::save_training_state) wrote into a policy built
    /// the same way (same network, same normalised tensors).
    pub(crate) fn load_training_state(
        &mut self,
        r: &mut crate::resume::StateReader<'_>,
    ) -> Result<(), a2perf_core::RunError> {
        r.f32s_into("policy parameters", &mut self.params)?;
        let has_norm = r.bool()?;
        match (&mut self.obs_norm, has_norm) {
            (Some(n), true) => {
                if r.usizes()? != n.tensors {
                    return Err(crate::resume::resume_err(
                        "the saved observation normalisation covers other tensors",
                    ));
                }
                for s in &mut n.stats {
                    s.load(r)?;
                }
            }
            (None, false) => {}
            _ => {
                return Err(crate::resume::resume_err(
                    "observation normalisation was switched on or off since the state was saved",
                ));
            }
        }
        self.rng = r.rng()?;
        Ok(())
    }

    /// Reseeds the exploration stream.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = RngStream::new(seed, "policy/explore");
    }
}

/// Per-dimension bounds of a box space (unbounded for anything else).
fn bounds(space: &Space) -> impl Iterator<Item = (f32, f32)> + '_ {
    let (low, high): (&[f64], &[f64]) = match space {
        Space::Box { low, high, .. } => (low, high),
        _ => (&[], &[]),
    };
    low.iter()
        .zip(high)
        .map(|(l, h)| (*l as f32, *h as f32))
        .chain(std::iter::repeat((f32::NEG_INFINITY, f32::INFINITY)))
}

/// Maps `x ∈ [-1, 1]` onto `[l, h]`, or onto `centre ± limit` (within the bounds) when
/// `limit > 0`.
pub fn squash_to_bounds(x: f32, l: f32, h: f32, limit: f32) -> f32 {
    let centre = 0.5 * (l + h);
    let half = 0.5 * (h - l);
    let half = if limit > 0.0 { half.min(limit) } else { half };
    centre + x * half
}

impl Policy for NetPolicy {
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError> {
        self.batch.clear();
        self.batch.push(obs)?;
        if let Some(n) = &self.obs_norm {
            n.apply(&mut self.batch, 0);
        }
        self.act_loaded(mode)
    }

    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Ok(Checkpoint {
            algorithm: self.algorithm.clone(),
            format_version: PAYLOAD_VERSION,
            payload: self.encode()?,
        })
    }

    /// A clone: greedy actions use the network and the frozen normalisation alone.
    fn fork(&self) -> Option<Box<dyn Policy>> {
        Some(Box::new(self.clone()))
    }
}

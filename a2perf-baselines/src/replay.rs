//! A fixed-capacity ring buffer of transitions for off-policy algorithms, storing observations
//! compactly and exactly.
//!
//! **Each observation is stored once.** Within an episode the next observation of step `t` is
//! the observation of step `t + 1`; a transition refers to observation *slots* of a store by
//! index, and a stream's (environment's) new observation reuses the previous transition's next
//! slot when the two are equal (checked, not assumed). Slots are reference-counted and recycled.
//! The store keeps each tensor in its narrowest exact type (token ids in one or two bytes, the
//! action mask in one bit per action) and a tensor that never changes (a netlist's adjacency)
//! once, not per slot. Nothing of this changes a sampled value.
//!
//! The buffer knows nothing about domains: it sees only the observation layout's tensors.

use a2perf_core::{Observation, PolicyError, RngStream};

use crate::batch::{ObsBatch, ObsLayout};
use crate::obs_store::ObsStore;

/// Uniform replay of `(obs, action, reward, next_obs, terminated)`.
///
/// Transitions come from numbered *streams* (one per environment); see the module documentation
/// for how observations are shared and compressed. Once full, the oldest transition is
/// overwritten. Sampling returns exactly the values that were pushed.
///
/// ```
/// use a2perf_baselines::replay::{ReplayBuffer, ReplaySample};
/// use a2perf_baselines::{ObsBatch, ObsLayout};
/// use a2perf_core::{Observation, RngStream, Tensor};
/// let layout = ObsLayout::floats(vec![("obs".into(), vec![2])], Some(3));
/// let obs = |x: f32| Observation {
///     tensors: vec![Tensor::new("obs", &[2], vec![x, 0.5])],
///     action_mask: Some(vec![true, false, true]),
/// };
/// let mut replay = ReplayBuffer::new(&layout, 100, 0);
/// let mut cur = ObsBatch::new(&layout);
/// cur.push(&obs(0.0)).unwrap();
/// for t in 1..=3 {
///     replay.push(0, &cur, 0, &obs(t as f32), t, &[], 1.0, false).unwrap();
///     cur.write_row(0, &obs(t as f32)).unwrap();
/// }
/// // Three transitions, four distinct observations.
/// assert_eq!((replay.len(), replay.stored_observations()), (3, 4));
/// let mut sample = ReplaySample::new(&layout);
/// replay.sample(8, &mut RngStream::new(0, "replay"), &mut Vec::new(), &mut sample);
/// assert_eq!(sample.obs.mask(0), Some(&[true, false, true][..]));
/// ```
#[derive(Clone, Debug)]
pub struct ReplayBuffer {
    store: ObsStore,
    /// Decoding scratch for the next observation of a push.
    next_row: ObsBatch,
    obs_slot: Vec<usize>,
    next_slot: Vec<usize>,
    /// Per stream: the next-observation slot of its latest transition (holds one reference).
    last_next: Vec<Option<usize>>,
    act_d: Vec<usize>,
    act_c: Vec<f32>,
    act_dim: usize,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    capacity: usize,
    pos: usize,
    size: usize,
}

/// A sampled minibatch.
#[derive(Clone, Debug)]
pub struct ReplaySample {
    /// Observations.
    pub obs: ObsBatch,
    /// Next observations.
    pub next: ObsBatch,
    /// Discrete actions.
    pub act_d: Vec<usize>,
    /// Continuous actions `[B, act_dim]`.
    pub act_c: Vec<f32>,
    /// Rewards.
    pub rewards: Vec<f32>,
    /// Whether the next state is terminal (no bootstrap).
    pub terminated: Vec<bool>,
    /// After [`ReplayBuffer::sample_legal_at`]: whether each of its actions is legal in each
    /// next observation, `[B, actions]` (empty otherwise).
    pub next_legal: Vec<bool>,
}

impl ReplaySample {
    /// Empty sample storage for `layout`.
    pub fn new(layout: &ObsLayout) -> Self {
        Self {
            obs: ObsBatch::new(layout),
            next: ObsBatch::new(layout),
            act_d: Vec::new(),
            act_c: Vec::new(),
            rewards: Vec::new(),
            terminated: Vec::new(),
            next_legal: Vec::new(),
        }
    }
}

impl ReplayBuffer {
    /// A buffer of `capacity` transitions (`act_dim` = 0 for discrete actions).
    pub fn new(layout: &ObsLayout, capacity: usize, act_dim: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            store: ObsStore::new(layout),
            next_row: ObsBatch::new(layout),
            obs_slot: vec![0; capacity],
            next_slot: vec![0; capacity],
            last_next: Vec::new(),
            act_d: vec![0; capacity],
            act_c: vec![0.0; capacity * act_dim],
            act_dim,
            rewards: vec![0.0; capacity],
            terminated: vec![false; capacity],
            capacity,
            pos: 0,
            size: 0,
        }
    }

    /// Stored transitions.
    pub fn len(&self) -> usize {
        self.size
    }

    /// Whether nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.size == 0
    }

    /// Distinct observations currently stored (at most `2 × len()`, about `len()` for long
    /// episodes).
    pub fn stored_observations(&self) -> usize {
        self.store.live()
    }

    /// Bytes reserved for observations (tensor columns, mask bits, the rows' lengths and slot
    /// bookkeeping).
    pub fn observation_bytes(&self) -> usize {
        self.store.bytes()
    }

    /// Adds a transition of stream `stream` (e.g. the environment's index) whose observation is
    /// row `row` of `obs` and whose next observation is `next`.
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        stream: usize,
        obs: &ObsBatch,
        row: usize,
        next: &Observation,
        act_d: usize,
        act_c: &[f32],
        reward: f32,
        terminated: bool,
    ) -> Result<(), PolicyError> {
        // Validate `next` before touching the buffer, so a bad observation changes nothing.
        self.next_row.resize(1);
        self.next_row.write_row(0, next)?;
        let i = self.pos;
        if self.size == self.capacity {
            self.store.release(self.obs_slot[i]);
            self.store.release(self.next_slot[i]);
        }
        if self.last_next.len() <= stream {
            self.last_next.resize(stream + 1, None);
        }
        let obs_slot = match self.last_next[stream] {
            Some(s) if self.store.equals(s, obs, row) => {
                self.store.retain(s);
                s
            }
            _ => self.store.insert(obs, row),
        };
        let next_slot = self.store.insert(&self.next_row, 0);
        self.store.retain(next_slot);
        if let Some(old) = self.last_next[stream].replace(next_slot) {
            self.store.release(old);
        }
        self.obs_slot[i] = obs_slot;
        self.next_slot[i] = next_slot;
        self.act_d[i] = act_d;
        self.act_c[i * self.act_dim..(i + 1) * self.act_dim].copy_from_slice(act_c);
        self.rewards[i] = reward;
        self.terminated[i] = terminated;
        self.pos = (self.pos + 1) % self.capacity;
        self.size = (self.size + 1).min(self.capacity);
        Ok(())
    }

    /// Writes the whole buffer, observation store included, exactly (for resumable training:
    /// keeping the replay is what makes a resumed off-policy run identical to an uninterrupted
    /// one). Only the filled part of the ring is written.
    pub(crate) fn save(&self, w: &mut crate::resume::StateWriter) {
        w.usize(self.capacity);
        w.usize(self.act_dim);
        w.usize(self.pos);
        w.usize(self.size);
        self.store.save(w);
        let n = self.size;
        w.usizes(&self.obs_slot[..n]);
        w.usizes(&self.next_slot[..n]);
        w.usizes(&self.act_d[..n]);
        w.f32s(&self.act_c[..n * self.act_dim]);
        w.f32s(&self.rewards[..n]);
        w.bools(&self.terminated[..n]);
        w.usize(self.last_next.len());
        for s in &self.last_next {
            w.bool(s.is_some());
            w.usize(s.unwrap_or(0));
        }
    }

    /// Restores what [`save`](Self::save) wrote into a buffer built with the same layout,
    /// capacity and action dimension.
    pub(crate) fn load(
        &mut self,
        r: &mut crate::resume::StateReader<'_>,
    ) -> Result<(), a2perf_core::RunError> {
        use crate::resume::resume_err;
        let (capacity, act_dim) = (r.usize()?, r.usize()?);
        if (capacity, act_dim) != (self.capacity, self.act_dim) {
            return Err(resume_err(format!(
                "replay buffer: capacity {capacity} and action size {act_dim} saved, this \
                 configuration has {} and {}",
                self.capacity, self.act_dim
            )));
        }
        let (pos, size) = (r.usize()?, r.usize()?);
        if pos >= capacity || size > capacity {
            return Err(resume_err("replay buffer: position out of range"));
        }
        let store = self.store.load(r)?;
        let slots = store.slots();
        let obs_slot = r.usizes()?;
        let next_slot = r.usizes()?;
        let act_d = r.usizes()?;
        let act_c = r.f32s()?;
        let rewards = r.f32s()?;
        let terminated = r.bools()?;
        let lens_ok = [
            obs_slot.len(),
            next_slot.len(),
            act_d.len(),
            rewards.len(),
            terminated.len(),
        ]
        .iter()
        .all(|l| *l == size)
            && act_c.len() == size * act_dim;
        if !lens_ok || obs_slot.iter().chain(&next_slot).any(|s| *s >= slots) {
            return Err(resume_err("replay buffer: inconsistent transitions"));
        }
        let streams = r.usize()?;
        let mut last_next = Vec::with_capacity(streams.min(1 << 16));
        for _ in 0..streams {
            let some = r.bool()?;
            let slot = r.usize()?;
            if some && slot >= slots {
                return Err(resume_err("replay buffer: inconsistent stream slot"));
            }
            last_next.push(some.then_some(slot));
        }
        self.store = store;
        self.obs_slot[..size].copy_from_slice(&obs_slot);
        self.next_slot[..size].copy_from_slice(&next_slot);
        self.act_d[..size].copy_from_slice(&act_d);
        self.act_c[..size * act_dim].copy_from_slice(&act_c);
        self.rewards[..size].copy_from_slice(&rewards);
        self.terminated[..size].copy_from_slice(&terminated);
        self.last_next = last_next;
        self.pos = pos;
        self.size = size;
        Ok(())
    }

    /// Draws `n` transitions uniformly (with replacement) into `out`.
    pub fn sample(
        &self,
        n: usize,
        rng: &mut RngStream,
        idx: &mut Vec<usize>,
        out: &mut ReplaySample,
    ) {
        self.sample_into(n, rng, idx, out, Masks::All);
    }

    /// As [`sample`](Self::sample), the same transitions, but without decoding the
    /// observations' action masks (`out.obs`'s masks keep whatever they held): Q-learning reads
    /// only the next observations' masks, and a mask can hold 16,384 actions.
    pub fn sample_next_masks(
        &self,
        n: usize,
        rng: &mut RngStream,
        idx: &mut Vec<usize>,
        out: &mut ReplaySample,
    ) {
        self.sample_into(n, rng, idx, out, Masks::Next);
    }

    /// As [`sample_next_masks`](Self::sample_next_masks), the same transitions, but the next
    /// observations' masks are read at `actions` only, into `out.next_legal` (`out.next`'s masks
    /// keep whatever they held): Q-learning over a network's scored actions needs no more.
    pub fn sample_legal_at(
        &self,
        n: usize,
        rng: &mut RngStream,
        idx: &mut Vec<usize>,
        out: &mut ReplaySample,
        actions: &[usize],
    ) {
        self.sample_into(n, rng, idx, out, Masks::LegalAt(actions));
    }

    fn sample_into(
        &self,
        n: usize,
        rng: &mut RngStream,
        idx: &mut Vec<usize>,
        out: &mut ReplaySample,
        masks: Masks<'_>,
    ) {
        idx.clear();
        idx.extend((0..n).map(|_| rng.index(self.size)));
        out.obs.resize(n);
        out.next.resize(n);
        out.act_d.clear();
        out.act_c.clear();
        out.rewards.clear();
        out.terminated.clear();
        out.next_legal.clear();
        if let Masks::LegalAt(actions) = masks {
            out.next_legal.resize(n * actions.len(), false);
        }
        for (k, &i) in idx.iter().enumerate() {
            let (obs, next) = (self.obs_slot[i], self.next_slot[i]);
            match masks {
                Masks::All => {
                    self.store.read(obs, &mut out.obs, k);
                    self.store.read(next, &mut out.next, k);
                }
                Masks::Next => {
                    self.store.read_tensors(obs, &mut out.obs, k);
                    self.store.read(next, &mut out.next, k);
                }
                Masks::LegalAt(actions) => {
                    self.store.read_tensors(obs, &mut out.obs, k);
                    self.store.read_tensors(next, &mut out.next, k);
                    let m = actions.len();
                    let legal = &mut out.next_legal[k * m..(k + 1) * m];
                    self.store.read_mask_at(next, actions, legal);
                }
            }
            out.act_d.push(self.act_d[i]);
            out.act_c
                .extend_from_slice(&self.act_c[i * self.act_dim..(i + 1) * self.act_dim]);
            out.rewards.push(self.rewards[i]);
            out.terminated.push(self.terminated[i]);
        }
    }
}

/// Which action masks a sample decodes.
#[derive(Clone, Copy)]
enum Masks<'a> {
    /// Both observations' masks.
    All,
    /// The next observations' masks.
    Next,
    /// The next observations' legality of these actions alone (into `next_legal`).
    LegalAt(&'a [usize]),
}

#[cfg(test)]
mod tests {
    use super::*;
    use a2perf_core::{DType, Tensor, TensorData};

    fn layout() -> ObsLayout {
        ObsLayout {
            tensors: vec![
                ("ids".into(), vec![3]),
                ("x".into(), vec![2]),
                ("tok".into(), vec![2]),
                ("stat".into(), vec![3]),
                ("late".into(), vec![2]),
            ],
            dtypes: vec![DType::F32, DType::F32, DType::I32, DType::F32, DType::I32],
            num_actions: Some(70),
        }
    }

    /// Row `k` of tensor `i` as exact bits, whichever kind of values it holds.
    fn row_bits(b: &ObsBatch, i: usize, k: usize) -> Vec<u32> {
        if b.is_integer(i) {
            b.int_row(i, k).iter().map(|v| *v as u32).collect()
        } else {
            b.tensor_row(i, k).iter().map(|v| v.to_bits()).collect()
        }
    }

    fn obs(t: u32) -> Observation {
        let f = t as f32;
        Observation {
            tensors: vec![
                Tensor {
                    name: "ids".into(),
                    shape: vec![3],
                    // Grows past u8 and later past u16 (forces widening mid-run); -0.0 must
                    // survive bit-exactly.
                    data: TensorData::F32(vec![f, f * 37.0, if t == 5 { -0.0 } else { 0.0 }]),
                },
                Tensor::new("x", &[2], vec![f * 0.1, if t > 20 { 1e6 + f } else { 1.0 }]),
                // Integer column: u8, then u16, then past f32's exact range (forces i32 mid-run).
                Tensor::new(
                    "tok",
                    &[2],
                    vec![
                        t as i32,
                        if t > 10 {
                            (1 << 24) + 1 + t as i32
                        } else {
                            t as i32 * 300
                        },
                    ],
                ),
                // Never changes (stored once); -0.0 and 0.0 must stay apart.
                Tensor::new("stat", &[3], vec![-0.0, 0.0, 2.5]),
                // The same until step 15, then different at every step (stored per slot
                // from then on).
                Tensor::new(
                    "late",
                    &[2],
                    vec![7, if t >= 15 { 1000 + t as i32 } else { 9 }],
                ),
            ],
            action_mask: Some(
                (0..70)
                    .map(|a| !(a + t as usize).is_multiple_of(3))
                    .collect(),
            ),
        }
    }

    /// Every sampled row equals what was pushed, bit for bit, across episode ends, wrap-around
    /// and column widening.
    #[test]
    fn samples_are_exact() {
        let l = layout();
        let mut rb = ReplayBuffer::new(&l, 7, 1);
        let mut cur = ObsBatch::new(&l);
        cur.push(&obs(0)).unwrap();
        let mut pushed: Vec<(u32, u32)> = Vec::new();
        let mut t = 0u32;
        for step in 1..40u32 {
            // Episodes of 4 steps: the next observation after an end is not the stored one.
            let next = step + if step.is_multiple_of(4) { 100 } else { 0 };
            rb.push(
                0,
                &cur,
                0,
                &obs(next),
                step as usize,
                &[step as f32],
                0.5,
                false,
            )
            .unwrap();
            pushed.push((t, next));
            t = if step.is_multiple_of(4) {
                step + 200
            } else {
                next
            };
            cur.write_row(0, &obs(t)).unwrap();
        }
        assert_eq!(rb.len(), 7);
        assert!(rb.stored_observations() <= 2 * 7 + 1);
        let mut sample = ReplaySample::new(&l);
        let mut idx = Vec::new();
        rb.sample(50, &mut RngStream::new(3, "t"), &mut idx, &mut sample);
        let mut want = ObsBatch::new(&l);
        want.resize(2);
        for (k, &i) in idx.iter().enumerate() {
            let step = rb.act_d[i] as u32;
            let (o, n) = pushed[step as usize - 1];
            want.write_row(0, &obs(o)).unwrap();
            want.write_row(1, &obs(n)).unwrap();
            for ti in 0..5 {
                assert_eq!(row_bits(&sample.obs, ti, k), row_bits(&want, ti, 0));
                assert_eq!(row_bits(&sample.next, ti, k), row_bits(&want, ti, 1));
            }
            assert_eq!(sample.obs.mask(k), want.mask(0));
            assert_eq!(sample.next.mask(k), want.mask(1));
            assert_eq!(sample.act_c[k], step as f32);
        }
        // The same transitions with the next masks read at some actions only, across the
        // mask's first word boundary: the full masks' entries there.
        let actions = [0, 2, 5, 63, 64, 65, 69];
        let mut at = ReplaySample::new(&l);
        let mut idx_at = Vec::new();
        let rng = &mut RngStream::new(3, "t");
        rb.sample_legal_at(50, rng, &mut idx_at, &mut at, &actions);
        assert_eq!(idx_at, idx);
        assert_eq!(at.next_legal.len(), 50 * actions.len());
        for k in 0..50 {
            let full = sample.next.mask(k).unwrap();
            for (j, &a) in actions.iter().enumerate() {
                assert_eq!(
                    at.next_legal[k * actions.len() + j],
                    full[a],
                    "row {k}, action {a}"
                );
            }
            for ti in 0..5 {
                assert_eq!(row_bits(&at.next, ti, k), row_bits(&sample.next, ti, k));
            }
        }
        assert!(at.next_legal.iter().any(|l| !l) && at.next_legal.iter().any(|l| *l));
    }

    /// A saved and restored buffer samples exactly what the original samples, and keeps
    /// sharing observations with the next push.
    #[test]
    fn save_and_load_are_exact() {
        let l = layout();
        let mut rb = ReplayBuffer::new(&l, 9, 1);
        let mut cur = ObsBatch::new(&l);
        cur.push(&obs(0)).unwrap();
        for t in 1..25u32 {
            let next = if t.is_multiple_of(5) { t + 300 } else { t };
            rb.push(
                0,
                &cur,
                0,
                &obs(next),
                t as usize,
                &[t as f32],
                -0.5,
                t % 7 == 0,
            )
            .unwrap();
            cur.write_row(0, &obs(if t.is_multiple_of(5) { t + 500 } else { t }))
                .unwrap();
        }
        let mut w = crate::resume::StateWriter::new("test", 1);
        rb.save(&mut w);
        let bytes = w.finish();
        let mut back = ReplayBuffer::new(&l, 9, 1);
        let mut r = crate::resume::StateReader::new(&bytes, "test", 1).unwrap();
        back.load(&mut r).unwrap();
        r.finish().unwrap();
        for b in [&mut rb, &mut back] {
            b.push(0, &cur, 0, &obs(26), 26, &[26.0], 1.0, false)
                .unwrap();
        }
        assert_eq!(back.stored_observations(), rb.stored_observations());
        let (mut s1, mut s2) = (ReplaySample::new(&l), ReplaySample::new(&l));
        let mut idx = Vec::new();
        rb.sample(40, &mut RngStream::new(1, "s"), &mut idx, &mut s1);
        back.sample(40, &mut RngStream::new(1, "s"), &mut idx, &mut s2);
        for k in 0..40 {
            for t in 0..5 {
                assert_eq!(row_bits(&s1.obs, t, k), row_bits(&s2.obs, t, k));
                assert_eq!(row_bits(&s1.next, t, k), row_bits(&s2.next, t, k));
            }
            assert_eq!(s1.obs.mask(k), s2.obs.mask(k));
        }
        assert_eq!(
            (s1.act_d, s1.act_c, s1.rewards, s1.terminated),
            (s2.act_d, s2.act_c, s2.rewards, s2.terminated)
        );
        let mut other = ReplayBuffer::new(&l, 10, 1);
        let mut r = crate::resume::StateReader::new(&bytes, "test", 1).unwrap();
        let err = other.load(&mut r).unwrap_err().to_string();
        assert!(err.contains("capacity 9"), "{err}");
    }

    /// A tensor that never changes costs its size once, not once per transition; the first
    /// different value makes it per-slot, and every sample stays exact.
    #[test]
    fn unchanging_tensors_are_stored_once() {
        let l = ObsLayout::floats(
            vec![("adj".into(), vec![1000]), ("x".into(), vec![1])],
            None,
        );
        let o = |t: usize, adj: f32| Observation {
            tensors: vec![
                Tensor::new("adj", &[1000], vec![adj; 1000]),
                Tensor::new("x", &[1], vec![t as f32 * 0.1]),
            ],
            action_mask: None,
        };
        let mut rb = ReplayBuffer::new(&l, 200, 0);
        let mut cur = ObsBatch::new(&l);
        cur.push(&o(0, 0.5)).unwrap();
        for t in 1..=100 {
            rb.push(0, &cur, 0, &o(t, 0.5), t, &[], 0.0, false).unwrap();
            cur.write_row(0, &o(t, 0.5)).unwrap();
        }
        // 101 observations: one shared row of 1,000 floats, one float each, bookkeeping.
        let shared = rb.observation_bytes();
        assert!(shared < 4 * 1000 + 101 * 64, "{shared} bytes");
        rb.push(0, &cur, 0, &o(101, 0.25), 101, &[], 0.0, false)
            .unwrap();
        // Per slot from now on: 102 slots of 1,000 floats.
        assert!(rb.observation_bytes() >= 102 * 4000);
        let mut sample = ReplaySample::new(&l);
        let mut idx = Vec::new();
        rb.sample(300, &mut RngStream::new(0, "s"), &mut idx, &mut sample);
        for (k, &i) in idx.iter().enumerate() {
            let t = rb.act_d[i];
            let next_adj = if t == 101 { 0.25 } else { 0.5 };
            assert!(sample.obs.tensor_row(0, k).iter().all(|v| *v == 0.5));
            assert!(sample.next.tensor_row(0, k).iter().all(|v| *v == next_adj));
            assert_eq!(sample.obs.tensor_row(1, k), &[(t - 1) as f32 * 0.1]);
            assert_eq!(sample.next.tensor_row(1, k), &[t as f32 * 0.1]);
        }
    }

    /// A buffer saved before anything was pushed loads, and then fills as a new one does.
    #[test]
    fn an_empty_buffer_saves_and_loads() {
        let l = layout();
        let rb = ReplayBuffer::new(&l, 5, 0);
        let mut w = crate::resume::StateWriter::new("test", 1);
        rb.save(&mut w);
        let bytes = w.finish();
        let mut back = ReplayBuffer::new(&l, 5, 0);
        let mut r = crate::resume::StateReader::new(&bytes, "test", 1).unwrap();
        back.load(&mut r).unwrap();
        r.finish().unwrap();
        assert!(back.is_empty());
        let mut cur = ObsBatch::new(&l);
        cur.push(&obs(1)).unwrap();
        back.push(0, &cur, 0, &obs(2), 0, &[], 0.0, false).unwrap();
        let mut sample = ReplaySample::new(&l);
        back.sample(1, &mut RngStream::new(0, "e"), &mut Vec::new(), &mut sample);
        let mut want = ObsBatch::new(&l);
        want.push(&obs(2)).unwrap();
        for t in 0..5 {
            assert_eq!(row_bits(&sample.next, t, 0), row_bits(&want, t, 0));
        }
    }

    #[test]
    fn consecutive_observations_are_shared() {
        let l = layout();
        let mut rb = ReplayBuffer::new(&l, 100, 0);
        let mut cur = ObsBatch::new(&l);
        cur.push(&obs(1)).unwrap();
        for t in 2..12 {
            rb.push(0, &cur, 0, &obs(t), 0, &[], 0.0, false).unwrap();
            cur.write_row(0, &obs(t)).unwrap();
        }
        assert_eq!(rb.stored_observations(), 11);
    }

    #[test]
    fn a_bad_next_observation_changes_nothing() {
        let l = layout();
        let mut rb = ReplayBuffer::new(&l, 4, 0);
        let mut cur = ObsBatch::new(&l);
        cur.push(&obs(1)).unwrap();
        let mut bad = obs(2);
        bad.tensors[0].data = TensorData::F32(vec![0.0; 2]);
        assert!(rb.push(0, &cur, 0, &bad, 0, &[], 0.0, false).is_err());
        assert!(rb.is_empty());
        assert_eq!(rb.stored_observations(), 0);
    }
}

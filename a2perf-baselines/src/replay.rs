//! A fixed-capacity ring buffer of transitions for off-policy algorithms, storing observations
//! compactly and exactly.
//!
//! Two things keep web-navigation replay small without changing a single sampled value:
//!
//! - **Each observation is stored once.** Within an episode the next observation of step `t` is
//!   the observation of step `t + 1`; a transition refers to observation *slots* by index, and a
//!   stream's (environment's) new observation reuses the previous transition's next slot when the
//!   two are equal (checked, not assumed). Slots are reference-counted and recycled.
//! - **Each tensor is stored in the narrowest exact type.** A tensor column starts as `u8` and is
//!   widened (`u8 → u16 → f32` for a float tensor, `u8 → u16 → i32` for an integer one) the first
//!   time a value does not fit, so token ids cost one or two bytes instead of four, float features
//!   stay `f32`, and the action mask costs one bit per action. A float is narrowed only if it
//!   converts back to the identical `f32` bit pattern.
//!
//! The buffer knows nothing about domains: it sees only the observation layout's tensors.

use a2perf_core::{Observation, PolicyError, RngStream};

use crate::batch::{ObsBatch, ObsLayout};

/// One tensor of every slot, `[slots, dim]`, in the narrowest type that holds it exactly. A float
/// tensor's column widens `u8 → u16 → f32`, an integer tensor's `u8 → u16 → i32`.
#[derive(Clone, Debug)]
enum Column {
    U8(Vec<u8>),
    U16(Vec<u16>),
    F32(Vec<f32>),
    I32(Vec<i32>),
}

/// One row of values on its way in or out of a column.
enum Values<'a> {
    Floats(&'a [f32]),
    Ints(&'a [i32]),
}

/// A value that may be stored narrowed (only once it is known to fit: see [`width_of`] and
/// [`int_width_of`]).
trait Narrow: Copy {
    fn to_u8(self) -> u8;
    fn to_u16(self) -> u16;
}

impl Narrow for f32 {
    fn to_u8(self) -> u8 {
        self as u8
    }
    fn to_u16(self) -> u16 {
        self as u16
    }
}

impl Narrow for i32 {
    fn to_u8(self) -> u8 {
        self as u8
    }
    fn to_u16(self) -> u16 {
        self as u16
    }
}

/// Narrowest exact encoding of one float: 0 = u8, 1 = u16, 2 = f32.
fn width_of(v: f32) -> u8 {
    if v.to_bits() == f32::from(v as u8).to_bits() {
        0
    } else if v.to_bits() == f32::from(v as u16).to_bits() {
        1
    } else {
        2
    }
}

/// Narrowest exact encoding of one integer: 0 = u8, 1 = u16, 2 = i32.
fn int_width_of(v: i32) -> u8 {
    if u8::try_from(v).is_ok() {
        0
    } else if u16::try_from(v).is_ok() {
        1
    } else {
        2
    }
}

impl Column {
    fn width(&self) -> u8 {
        match self {
            Column::U8(_) => 0,
            Column::U16(_) => 1,
            Column::F32(_) | Column::I32(_) => 2,
        }
    }

    fn len(&self) -> usize {
        match self {
            Column::U8(v) => v.len(),
            Column::U16(v) => v.len(),
            Column::F32(v) => v.len(),
            Column::I32(v) => v.len(),
        }
    }

    /// Re-encodes every stored value at width `w` (exact: widening only); the widest encoding
    /// is `i32` for an integer tensor, `f32` for a float one.
    fn widen(&mut self, w: u8, integer: bool) {
        if w <= self.width() {
            return;
        }
        let old: Vec<i32> = match self {
            Column::U8(v) => v.iter().map(|x| i32::from(*x)).collect(),
            Column::U16(v) => v.iter().map(|x| i32::from(*x)).collect(),
            // Already the widest encoding (`w > width` excludes it).
            Column::F32(_) | Column::I32(_) => return,
        };
        *self = match (w, integer) {
            (1, _) => Column::U16(old.iter().map(|x| *x as u16).collect()),
            (_, true) => Column::I32(old),
            (_, false) => Column::F32(old.iter().map(|x| *x as f32).collect()),
        };
    }

    /// Grows storage to `n` values (zero-filled), reserving in steps of a quarter of the current
    /// size so that amortised growth wastes at most ~25% (not the 100% of `Vec` doubling).
    fn grow_to(&mut self, n: usize) {
        fn grow<T: Clone + Default>(v: &mut Vec<T>, n: usize) {
            if n > v.capacity() {
                v.reserve_exact((n - v.len()).max(v.len() / 4));
            }
            v.resize(n, T::default());
        }
        if n <= self.len() {
            return;
        }
        match self {
            Column::U8(v) => grow(v, n),
            Column::U16(v) => grow(v, n),
            Column::F32(v) => grow(v, n),
            Column::I32(v) => grow(v, n),
        }
    }

    fn write(&mut self, at: usize, src: Values<'_>) {
        match src {
            Values::Floats(src) => {
                self.widen(src.iter().map(|v| width_of(*v)).max().unwrap_or(0), false);
                if !self.write_narrow(at, src)
                    && let Column::F32(v) = self
                {
                    v[at..at + src.len()].copy_from_slice(src);
                }
            }
            Values::Ints(src) => {
                self.widen(
                    src.iter().map(|v| int_width_of(*v)).max().unwrap_or(0),
                    true,
                );
                if !self.write_narrow(at, src)
                    && let Column::I32(v) = self
                {
                    v[at..at + src.len()].copy_from_slice(src);
                }
            }
        }
    }

    /// Writes `src` if the column is `u8` or `u16` (the caller widened it so that every value
    /// fits); `false` for the widest encodings, which the caller writes itself.
    fn write_narrow<T: Narrow>(&mut self, at: usize, src: &[T]) -> bool {
        match self {
            Column::U8(v) => v[at..at + src.len()]
                .iter_mut()
                .zip(src)
                .for_each(|(d, s)| *d = s.to_u8()),
            Column::U16(v) => v[at..at + src.len()]
                .iter_mut()
                .zip(src)
                .for_each(|(d, s)| *d = s.to_u16()),
            Column::F32(_) | Column::I32(_) => return false,
        }
        true
    }

    fn read_floats(&self, at: usize, dst: &mut [f32]) {
        let n = dst.len();
        match self {
            Column::U8(v) => dst
                .iter_mut()
                .zip(&v[at..at + n])
                .for_each(|(d, s)| *d = f32::from(*s)),
            Column::U16(v) => dst
                .iter_mut()
                .zip(&v[at..at + n])
                .for_each(|(d, s)| *d = f32::from(*s)),
            Column::F32(v) => dst.copy_from_slice(&v[at..at + n]),
            Column::I32(_) => {}
        }
    }

    fn read_ints(&self, at: usize, dst: &mut [i32]) {
        let n = dst.len();
        match self {
            Column::U8(v) => dst
                .iter_mut()
                .zip(&v[at..at + n])
                .for_each(|(d, s)| *d = i32::from(*s)),
            Column::U16(v) => dst
                .iter_mut()
                .zip(&v[at..at + n])
                .for_each(|(d, s)| *d = i32::from(*s)),
            Column::I32(v) => dst.copy_from_slice(&v[at..at + n]),
            Column::F32(_) => {}
        }
    }

    /// Whether the stored values equal `src` exactly (floats bit for bit).
    fn equals(&self, at: usize, src: Values<'_>) -> bool {
        fn same<S: Copy, T: Copy>(a: &[S], b: &[T], eq: impl Fn(S, T) -> bool) -> bool {
            a.iter().zip(b).all(|(x, y)| eq(*x, *y))
        }
        match src {
            Values::Floats(src) => {
                let n = src.len();
                match self {
                    Column::U8(v) => same(&v[at..at + n], src, |s, x| {
                        f32::from(s).to_bits() == x.to_bits()
                    }),
                    Column::U16(v) => same(&v[at..at + n], src, |s, x| {
                        f32::from(s).to_bits() == x.to_bits()
                    }),
                    Column::F32(v) => same(&v[at..at + n], src, |s, x| s.to_bits() == x.to_bits()),
                    Column::I32(_) => false,
                }
            }
            Values::Ints(src) => {
                let n = src.len();
                match self {
                    Column::U8(v) => same(&v[at..at + n], src, |s, x| i32::from(s) == x),
                    Column::U16(v) => same(&v[at..at + n], src, |s, x| i32::from(s) == x),
                    Column::I32(v) => same(&v[at..at + n], src, |s, x| s == x),
                    Column::F32(_) => false,
                }
            }
        }
    }

    fn bytes(&self) -> usize {
        match self {
            Column::U8(v) => v.capacity(),
            Column::U16(v) => v.capacity() * 2,
            Column::F32(v) => v.capacity() * 4,
            Column::I32(v) => v.capacity() * 4,
        }
    }
}

/// Row `row` of tensor `i` of `batch`, in the batch's kind of values.
fn values_of(batch: &ObsBatch, i: usize, row: usize) -> Values<'_> {
    if batch.is_integer(i) {
        Values::Ints(batch.int_row(i, row))
    } else {
        Values::Floats(batch.tensor_row(i, row))
    }
}

/// Reference-counted observation slots.
#[derive(Clone, Debug)]
struct ObsStore {
    dims: Vec<usize>,
    /// Per tensor: whether it holds integers (its column widens to `i32`, not `f32`).
    integer: Vec<bool>,
    columns: Vec<Column>,
    /// Action masks, one bit per action, `words` u64 per slot.
    mask: Vec<u64>,
    words: usize,
    refs: Vec<u32>,
    free: Vec<usize>,
}

impl ObsStore {
    fn new(layout: &ObsLayout) -> Self {
        let dims: Vec<usize> = (0..layout.tensors.len()).map(|i| layout.dim(i)).collect();
        let mask_width = layout.num_actions.unwrap_or(0);
        Self {
            columns: dims.iter().map(|_| Column::U8(Vec::new())).collect(),
            integer: (0..dims.len()).map(|i| layout.is_integer(i)).collect(),
            dims,
            mask: Vec::new(),
            words: mask_width.div_ceil(64),
            refs: Vec::new(),
            free: Vec::new(),
        }
    }

    /// A slot holding row `row` of `src`, with one reference.
    fn insert(&mut self, src: &ObsBatch, row: usize) -> usize {
        let slot = match self.free.pop() {
            Some(s) => s,
            None => {
                let s = self.refs.len();
                self.refs.push(0);
                for (c, d) in self.columns.iter_mut().zip(&self.dims) {
                    c.grow_to((s + 1) * d);
                }
                if self.mask.len() < (s + 1) * self.words {
                    if (s + 1) * self.words > self.mask.capacity() {
                        self.mask.reserve_exact(self.words.max(self.mask.len() / 4));
                    }
                    self.mask.resize((s + 1) * self.words, 0);
                }
                s
            }
        };
        self.refs[slot] = 1;
        for (i, (c, d)) in self.columns.iter_mut().zip(&self.dims).enumerate() {
            c.write(slot * d, values_of(src, i, row));
        }
        if let Some(m) = src.mask(row) {
            let bits = &mut self.mask[slot * self.words..(slot + 1) * self.words];
            bits.fill(0);
            for (a, legal) in m.iter().enumerate() {
                if *legal {
                    bits[a / 64] |= 1 << (a % 64);
                }
            }
        }
        slot
    }

    fn equals(&self, slot: usize, src: &ObsBatch, row: usize) -> bool {
        let tensors_equal = self
            .columns
            .iter()
            .zip(&self.dims)
            .enumerate()
            .all(|(i, (c, d))| c.equals(slot * d, values_of(src, i, row)));
        tensors_equal
            && src.mask(row).is_none_or(|m| {
                let bits = &self.mask[slot * self.words..(slot + 1) * self.words];
                m.iter()
                    .enumerate()
                    .all(|(a, legal)| (bits[a / 64] >> (a % 64)) & 1 == u64::from(*legal))
            })
    }

    fn retain(&mut self, slot: usize) {
        self.refs[slot] += 1;
    }

    fn release(&mut self, slot: usize) {
        self.refs[slot] -= 1;
        if self.refs[slot] == 0 {
            self.free.push(slot);
        }
    }

    /// Decodes `slot` into row `row` of `out`.
    fn read(&self, slot: usize, out: &mut ObsBatch, row: usize) {
        for (i, (c, d)) in self.columns.iter().zip(&self.dims).enumerate() {
            if out.is_integer(i) {
                c.read_ints(slot * d, out.int_row_mut(i, row));
            } else {
                c.read_floats(slot * d, out.row_mut(i, row));
            }
        }
        if let Some(m) = out.mask_mut(row) {
            let bits = &self.mask[slot * self.words..(slot + 1) * self.words];
            for (a, legal) in m.iter_mut().enumerate() {
                *legal = (bits[a / 64] >> (a % 64)) & 1 == 1;
            }
        }
    }

    fn bytes(&self) -> usize {
        self.columns.iter().map(Column::bytes).sum::<usize>()
            + self.mask.capacity() * 8
            + self.refs.capacity() * 4
            + self.free.capacity() * std::mem::size_of::<usize>()
    }
}

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
        self.store.refs.len() - self.store.free.len()
    }

    /// Bytes reserved for observations (tensor columns, mask bits and slot bookkeeping).
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
        let st = &self.store;
        w.usizes(&st.dims);
        w.usize(st.words);
        for c in &st.columns {
            match c {
                Column::U8(v) => {
                    w.u32(0);
                    w.u8s(v);
                }
                Column::U16(v) => {
                    w.u32(1);
                    w.u16s(v);
                }
                Column::F32(v) => {
                    w.u32(2);
                    w.f32s(v);
                }
                Column::I32(v) => {
                    w.u32(3);
                    w.u32s(&v.iter().map(|x| *x as u32).collect::<Vec<u32>>());
                }
            }
        }
        w.u64s(&st.mask);
        let refs: Vec<u32> = st.refs.clone();
        w.u32s(&refs);
        w.usizes(&st.free);
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
        let dims = r.usizes()?;
        let words = r.usize()?;
        if dims != self.store.dims || words != self.store.words {
            return Err(resume_err(
                "replay buffer: the saved observations have another layout",
            ));
        }
        let mut columns = Vec::with_capacity(dims.len());
        for &integer in &self.store.integer {
            let column = match r.u32()? {
                0 => Column::U8(r.u8s()?),
                1 => Column::U16(r.u16s()?),
                2 => Column::F32(r.f32s()?),
                3 => Column::I32(r.u32s()?.into_iter().map(|x| x as i32).collect()),
                t => {
                    return Err(resume_err(format!(
                        "replay buffer: unknown column type {t}"
                    )));
                }
            };
            let kind_fits = match column {
                Column::F32(_) => !integer,
                Column::I32(_) => integer,
                _ => true,
            };
            if !kind_fits {
                return Err(resume_err(
                    "replay buffer: a saved tensor is float where the layout has integers, or \
                     the other way round",
                ));
            }
            columns.push(column);
        }
        let mask = r.u64s()?;
        let refs = r.u32s()?;
        let free = r.usizes()?;
        let slots = refs.len();
        let columns_fit = columns.iter().zip(&dims).all(|(c, d)| c.len() == slots * d);
        if !columns_fit || mask.len() != slots * words || free.iter().any(|f| *f >= slots) {
            return Err(resume_err("replay buffer: inconsistent observation store"));
        }
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
        self.store.columns = columns;
        self.store.mask = mask;
        self.store.refs = refs;
        self.store.free = free;
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
        idx.clear();
        idx.extend((0..n).map(|_| rng.index(self.size)));
        out.obs.resize(n);
        out.next.resize(n);
        out.act_d.clear();
        out.act_c.clear();
        out.rewards.clear();
        out.terminated.clear();
        for (k, &i) in idx.iter().enumerate() {
            self.store.read(self.obs_slot[i], &mut out.obs, k);
            self.store.read(self.next_slot[i], &mut out.next, k);
            out.act_d.push(self.act_d[i]);
            out.act_c
                .extend_from_slice(&self.act_c[i * self.act_dim..(i + 1) * self.act_dim]);
            out.rewards.push(self.rewards[i]);
            out.terminated.push(self.terminated[i]);
        }
    }
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
            ],
            dtypes: vec![DType::F32, DType::F32, DType::I32],
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
            for ti in 0..3 {
                assert_eq!(row_bits(&sample.obs, ti, k), row_bits(&want, ti, 0));
                assert_eq!(row_bits(&sample.next, ti, k), row_bits(&want, ti, 1));
            }
            assert_eq!(sample.obs.mask(k), want.mask(0));
            assert_eq!(sample.next.mask(k), want.mask(1));
            assert_eq!(sample.act_c[k], step as f32);
        }
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
            for t in 0..3 {
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

//! Observations stored compactly and exactly, in reference-counted *slots*: the storage of the
//! replay buffer ([`ReplayBuffer`](crate::replay::ReplayBuffer)) and of behavioural cloning's
//! demonstrations.
//!
//! Two things keep a store small without changing a single value read back:
//!
//! - **Each tensor is stored in the narrowest exact type.** A tensor column starts as `u8` and is
//!   widened (`u8 → u16 → f32` for a float tensor, `u8 → u16 → i32` for an integer one) the first
//!   time a value does not fit, so token ids cost one or two bytes instead of four, float features
//!   stay `f32`, and the action mask costs one bit per action. A float is narrowed only if it
//!   converts back to the identical `f32` bit pattern.
//! - **A tensor that never changes is stored once.** Until a tensor's value differs from the
//!   first one stored (compared bit for bit), the store keeps that one row for every slot; the
//!   first different value turns it into a per-slot column. A chip netlist's adjacency, which
//!   is most of a circuit observation, therefore costs its size once, not once per step.
//!
//! The store knows nothing about domains: it sees only the observation layout's tensors.

use crate::batch::{ObsBatch, ObsLayout};
use crate::resume::{StateReader, StateWriter, resume_err};

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
#[derive(Clone, Copy)]
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

    /// The length of the row `[at, at + n)` without its trailing zeros (values whose bits are
    /// all zero: `-0.0` is not one).
    fn nz_len(&self, at: usize, n: usize) -> usize {
        fn last<T: Copy>(v: &[T], zero: impl Fn(T) -> bool) -> usize {
            v.iter().rposition(|x| !zero(*x)).map_or(0, |k| k + 1)
        }
        match self {
            Column::U8(v) => last(&v[at..at + n], |x| x == 0),
            Column::U16(v) => last(&v[at..at + n], |x| x == 0),
            Column::F32(v) => last(&v[at..at + n], |x| x.to_bits() == 0),
            Column::I32(v) => last(&v[at..at + n], |x| x == 0),
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

    /// The column's values repeated `n` times, in the same encoding.
    fn tiled(&self, n: usize) -> Column {
        match self {
            Column::U8(v) => Column::U8(v.repeat(n)),
            Column::U16(v) => Column::U16(v.repeat(n)),
            Column::F32(v) => Column::F32(v.repeat(n)),
            Column::I32(v) => Column::I32(v.repeat(n)),
        }
    }

    /// Writes the column to a training state: its encoding's tag, then its values.
    fn save(&self, w: &mut StateWriter) {
        match self {
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

    /// Reads what [`save`](Self::save) wrote after its `tag`, for a tensor of integers or of
    /// floats.
    fn load(
        r: &mut StateReader<'_>,
        tag: u32,
        integer: bool,
    ) -> Result<Column, a2perf_core::RunError> {
        let column = match tag {
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
                "replay buffer: a saved tensor is float where the layout has integers, or the \
                 other way round",
            ));
        }
        Ok(column)
    }
}

/// Training-state tag of a tensor kept once for every slot ([`Stored::Same`]), followed by its
/// column.
const TAG_SAME: u32 = 4;
/// Training-state tag of a tensor with nothing stored yet ([`Stored::Empty`]).
const TAG_EMPTY: u32 = 5;

/// How the observation store keeps one tensor.
#[derive(Clone, Debug)]
enum Stored {
    /// No observation stored yet.
    Empty,
    /// Every observation stored so far holds this one row (`[dim]`): a feature that has not
    /// changed, kept once instead of per slot.
    Same(Column),
    /// One row per slot, `[slots, dim]`.
    PerSlot(Column),
}

impl Stored {
    /// The column holding slot `slot`'s row, and where the row starts in it.
    fn at(&self, slot: usize, dim: usize) -> Option<(&Column, usize)> {
        match self {
            Stored::Empty => None,
            Stored::Same(c) => Some((c, 0)),
            Stored::PerSlot(c) => Some((c, slot * dim)),
        }
    }

    /// The length of slot `slot`'s row without its trailing zeros (0 with nothing stored).
    fn nz_len(&self, slot: usize, dim: usize) -> u32 {
        self.at(slot, dim).map_or(0, |(c, at)| c.nz_len(at, dim)) as u32
    }

    /// Stores `src` as slot `slot`'s row, `slots` being the number of slots (free ones
    /// included). A row that differs from the shared one turns the tensor into a per-slot
    /// column, every other slot keeping the shared row.
    fn write(&mut self, slot: usize, dim: usize, slots: usize, src: Values<'_>) {
        match self {
            Stored::Empty => {
                let mut row = Column::U8(vec![0; dim]);
                row.write(0, src);
                *self = Stored::Same(row);
            }
            Stored::Same(row) => {
                if !row.equals(0, src) {
                    let mut all = row.tiled(slots);
                    all.write(slot * dim, src);
                    *self = Stored::PerSlot(all);
                }
            }
            Stored::PerSlot(c) => c.write(slot * dim, src),
        }
    }

    fn bytes(&self) -> usize {
        match self {
            Stored::Empty => 0,
            Stored::Same(c) | Stored::PerSlot(c) => c.bytes(),
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
pub(crate) struct ObsStore {
    dims: Vec<usize>,
    /// Per tensor: whether it holds integers (its column widens to `i32`, not `f32`).
    integer: Vec<bool>,
    tensors: Vec<Stored>,
    /// Per tensor, per slot: the length of the slot's row without its trailing zeros (a web
    /// page's 250 element slots are mostly empty), so that reads decode only that much.
    nz: Vec<Vec<u32>>,
    /// Action masks, one bit per action, `words` u64 per slot.
    mask: Vec<u64>,
    /// Per slot: the mask's words up to its last legal action's (reads decode only those).
    mask_words: Vec<u32>,
    words: usize,
    refs: Vec<u32>,
    free: Vec<usize>,
}

impl ObsStore {
    pub(crate) fn new(layout: &ObsLayout) -> Self {
        let dims: Vec<usize> = (0..layout.tensors.len()).map(|i| layout.dim(i)).collect();
        let mask_width = layout.num_actions.unwrap_or(0);
        Self {
            tensors: dims.iter().map(|_| Stored::Empty).collect(),
            nz: dims.iter().map(|_| Vec::new()).collect(),
            integer: (0..dims.len()).map(|i| layout.is_integer(i)).collect(),
            dims,
            mask: Vec::new(),
            mask_words: Vec::new(),
            words: mask_width.div_ceil(64),
            refs: Vec::new(),
            free: Vec::new(),
        }
    }

    /// A slot holding row `row` of `src`, with one reference.
    pub(crate) fn insert(&mut self, src: &ObsBatch, row: usize) -> usize {
        let slot = match self.free.pop() {
            Some(s) => s,
            None => {
                let s = self.refs.len();
                self.refs.push(0);
                for (t, d) in self.tensors.iter_mut().zip(&self.dims) {
                    if let Stored::PerSlot(c) = t {
                        c.grow_to((s + 1) * d);
                    }
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
        let slots = self.refs.len();
        for (i, (t, d)) in self.tensors.iter_mut().zip(&self.dims).enumerate() {
            t.write(slot, *d, slots, values_of(src, i, row));
            let nz = &mut self.nz[i];
            if nz.len() < slots {
                nz.resize(slots, 0);
            }
            nz[slot] = t.nz_len(slot, *d);
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
        if self.mask_words.len() < slots {
            self.mask_words.resize(slots, 0);
        }
        self.mask_words[slot] = self.used_words(slot);
        slot
    }

    /// Whether `slot` holds row `row` of `src`, bit for bit.
    pub(crate) fn equals(&self, slot: usize, src: &ObsBatch, row: usize) -> bool {
        let tensors_equal = self
            .tensors
            .iter()
            .zip(&self.dims)
            .enumerate()
            .all(|(i, (t, d))| {
                t.at(slot, *d)
                    .is_some_and(|(c, at)| c.equals(at, values_of(src, i, row)))
            });
        tensors_equal
            && src.mask(row).is_none_or(|m| {
                let bits = &self.mask[slot * self.words..(slot + 1) * self.words];
                m.iter()
                    .enumerate()
                    .all(|(a, legal)| (bits[a / 64] >> (a % 64)) & 1 == u64::from(*legal))
            })
    }

    /// Adds a reference to `slot`.
    pub(crate) fn retain(&mut self, slot: usize) {
        self.refs[slot] += 1;
    }

    /// Drops a reference to `slot`; the slot is reused once none is left.
    pub(crate) fn release(&mut self, slot: usize) {
        self.refs[slot] -= 1;
        if self.refs[slot] == 0 {
            self.free.push(slot);
        }
    }

    /// Decodes `slot` into row `row` of `out`.
    pub(crate) fn read(&self, slot: usize, out: &mut ObsBatch, row: usize) {
        self.read_tensors(slot, out, row);
        self.read_mask(slot, out, row);
    }

    /// Decodes every tensor of `slot`, not its mask, into row `row` of `out`.
    pub(crate) fn read_tensors(&self, slot: usize, out: &mut ObsBatch, row: usize) {
        for i in 0..self.tensors.len() {
            self.read_tensor(slot, i, out, row);
        }
    }

    /// Decodes tensor `i` of `slot` into row `row` of `out`.
    ///
    /// Only the row's values before its trailing zeros are decoded; the batch zeroes the rest
    /// where its last write through here did not leave zeros ([`ObsBatch::write_trimmed`]).
    pub(crate) fn read_tensor(&self, slot: usize, i: usize, out: &mut ObsBatch, row: usize) {
        let Some((c, at)) = self.tensors[i].at(slot, self.dims[i]) else {
            return;
        };
        out.write_trimmed(
            i,
            row,
            self.nz[i][slot] as usize,
            |dst| c.read_floats(at, dst),
            |dst| c.read_ints(at, dst),
        );
    }

    /// Decodes the action mask of `slot` into row `row` of `out` (nothing without a mask).
    ///
    /// Only the words up to the last legal action's are decoded; the batch marks the rest
    /// illegal where its last read through here did not ([`ObsBatch::write_mask_trimmed`]).
    pub(crate) fn read_mask(&self, slot: usize, out: &mut ObsBatch, row: usize) {
        if self.words == 0 {
            return;
        }
        let used = self.mask_words[slot] as usize;
        let bits = &self.mask[slot * self.words..slot * self.words + used];
        out.write_mask_trimmed(row, used * 64, |m| {
            // A byte at a time through a table: a web observation's mask has 12,500 actions
            // and a replay minibatch decodes hundreds of them per update.
            for (chunk, word) in m.chunks_mut(64).zip(bits) {
                for (flags, byte) in chunk.chunks_mut(8).zip(word.to_le_bytes()) {
                    let table = &BYTE_FLAGS[usize::from(byte)];
                    // Eight flags as one fixed-size copy (a slice copy of unknown length is a
                    // `memmove` call per byte of bits); the mask's last byte may be shorter.
                    match <&mut [bool; 8]>::try_from(&mut *flags) {
                        Ok(full) => *full = *table,
                        Err(_) => flags.copy_from_slice(&table[..flags.len()]),
                    }
                }
            }
        });
    }

    /// The words of `slot`'s mask up to and including its last non-zero one.
    fn used_words(&self, slot: usize) -> u32 {
        let bits = &self.mask[slot * self.words..(slot + 1) * self.words];
        bits.iter().rposition(|w| *w != 0).map_or(0, |k| k + 1) as u32
    }

    /// Writes into `out` whether each of `actions` is legal in `slot`'s mask (`true` without a
    /// mask): the entries of [`read_mask`](Self::read_mask)'s row at those actions, without
    /// decoding the rest (a learner that scores 504 of A2Perf's 16,384 circuit actions).
    pub(crate) fn read_mask_at(&self, slot: usize, actions: &[usize], out: &mut [bool]) {
        if self.words == 0 {
            out.fill(true);
            return;
        }
        let bits = &self.mask[slot * self.words..(slot + 1) * self.words];
        for (o, &a) in out.iter_mut().zip(actions) {
            *o = (bits[a / 64] >> (a % 64)) & 1 == 1;
        }
    }

    /// Bytes reserved (tensor columns, mask bits, the rows' and masks' lengths and slot
    /// bookkeeping).
    pub(crate) fn bytes(&self) -> usize {
        self.tensors.iter().map(Stored::bytes).sum::<usize>()
            + self.mask.capacity() * 8
            + self.refs.capacity() * 4
            + self.nz.iter().map(|v| v.capacity() * 4).sum::<usize>()
            + self.mask_words.capacity() * 4
            + self.free.capacity() * std::mem::size_of::<usize>()
    }

    /// Slots allocated, free ones included (every valid slot index is below this).
    pub(crate) fn slots(&self) -> usize {
        self.refs.len()
    }

    /// Slots in use.
    pub(crate) fn live(&self) -> usize {
        self.refs.len() - self.free.len()
    }

    /// Writes the store exactly (layout, tensors, masks, references) to a training state.
    pub(crate) fn save(&self, w: &mut StateWriter) {
        w.usizes(&self.dims);
        w.usize(self.words);
        for t in &self.tensors {
            match t {
                Stored::Empty => w.u32(TAG_EMPTY),
                Stored::Same(c) => {
                    w.u32(TAG_SAME);
                    c.save(w);
                }
                Stored::PerSlot(c) => c.save(w),
            }
        }
        w.u64s(&self.mask);
        w.u32s(&self.refs);
        w.usizes(&self.free);
    }

    /// Reads what [`save`](Self::save) wrote, as a store of this one's layout; a state of
    /// another layout, or one that does not hang together, is refused.
    pub(crate) fn load(&self, r: &mut StateReader<'_>) -> Result<ObsStore, a2perf_core::RunError> {
        let dims = r.usizes()?;
        let words = r.usize()?;
        if dims != self.dims || words != self.words {
            return Err(resume_err(
                "replay buffer: the saved observations have another layout",
            ));
        }
        // States written before tensors could be shared hold only per-slot columns (tags 0-3),
        // which load as such.
        let mut tensors = Vec::with_capacity(dims.len());
        for &integer in &self.integer {
            let tensor = match r.u32()? {
                TAG_EMPTY => Stored::Empty,
                TAG_SAME => {
                    let tag = r.u32()?;
                    Stored::Same(Column::load(r, tag, integer)?)
                }
                tag => Stored::PerSlot(Column::load(r, tag, integer)?),
            };
            tensors.push(tensor);
        }
        let mask = r.u64s()?;
        let refs = r.u32s()?;
        let free = r.usizes()?;
        let slots = refs.len();
        let columns_fit = tensors.iter().zip(&dims).all(|(t, d)| match t {
            Stored::Empty => slots == 0,
            Stored::Same(c) => c.len() == *d,
            Stored::PerSlot(c) => c.len() == slots * d,
        });
        if !columns_fit || mask.len() != slots * words || free.iter().any(|f| *f >= slots) {
            return Err(resume_err("replay buffer: inconsistent observation store"));
        }
        let nz = tensors
            .iter()
            .zip(&dims)
            .map(|(t, &d)| (0..slots).map(|slot| t.nz_len(slot, d)).collect())
            .collect();
        let mut store = ObsStore {
            dims,
            integer: self.integer.clone(),
            tensors,
            nz,
            mask,
            mask_words: Vec::new(),
            words,
            refs,
            free,
        };
        store.mask_words = (0..slots).map(|slot| store.used_words(slot)).collect();
        Ok(store)
    }
}

/// The eight flags of each byte value, least significant bit first (mask decoding).
const BYTE_FLAGS: [[bool; 8]; 256] = {
    let mut table = [[false; 8]; 256];
    let mut byte = 0;
    while byte < 256 {
        let mut bit = 0;
        while bit < 8 {
            table[byte][bit] = (byte >> bit) & 1 == 1;
            bit += 1;
        }
        byte += 1;
    }
    table
};

#[cfg(test)]
mod tests {
    use super::*;
    use a2perf_core::DType;
    use proptest::prelude::*;

    proptest! {
        /// Reads decode a row up to its trailing zeros and clear what an earlier read into the
        /// same batch row left there: whatever order rows of different lengths (and a float
        /// `-0.0`, which is not a zero) are read in, and whatever was written into the batch
        /// row in between, every read gives back the stored row bit for bit.
        #[test]
        fn trimmed_reads_give_back_every_row_bit_for_bit(
            lens in prop::collection::vec(0usize..=12, 1..6),
            reads in prop::collection::vec((0usize..6, any::<bool>()), 1..20),
        ) {
            let layout = ObsLayout {
                tensors: vec![("f".into(), vec![12]), ("i".into(), vec![12])],
                dtypes: vec![DType::F32, DType::I32],
                num_actions: None,
            };
            let mut src = ObsBatch::new(&layout);
            src.resize(lens.len());
            for (r, &n) in lens.iter().enumerate() {
                let f = src.row_mut(0, r);
                f.fill(0.0);
                for (k, v) in f[..n].iter_mut().enumerate() {
                    *v = if k % 3 == 1 { 0.0 } else { (k + r) as f32 * 0.5 + 0.25 };
                }
                if n > 0 && n % 2 == 0 {
                    f[n - 1] = -0.0;
                }
                let i = src.int_row_mut(1, r);
                i.fill(0);
                for (k, v) in i[..n].iter_mut().enumerate() {
                    *v = (k * 7 + r) as i32 - 3;
                }
            }
            let mut store = ObsStore::new(&layout);
            let slots: Vec<usize> = (0..lens.len()).map(|r| store.insert(&src, r)).collect();
            let mut out = ObsBatch::new(&layout);
            out.resize(1);
            for (pick, scribble) in reads {
                let r = pick % lens.len();
                if scribble {
                    out.row_mut(0, 0).fill(9.0);
                    out.int_row_mut(1, 0).fill(9);
                }
                store.read(slots[r], &mut out, 0);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                prop_assert_eq!(bits(out.tensor_row(0, 0)), bits(src.tensor_row(0, r)));
                prop_assert_eq!(out.int_row(1, 0), src.int_row(1, r));
            }
        }
    }

    proptest! {
        /// Masks read up to their last legal action's word, the rest marked illegal where an
        /// earlier read into the same batch row did not leave it so: every read gives back the
        /// stored mask, and no action from `legal_end` on is legal.
        #[test]
        fn trimmed_mask_reads_give_back_every_mask(
            lasts in prop::collection::vec(prop::option::of(0usize..200), 1..6),
            reads in prop::collection::vec((0usize..6, any::<bool>()), 1..20),
        ) {
            let n = 200;
            let layout = ObsLayout::floats(vec![("x".into(), vec![1])], Some(n));
            let mut src = ObsBatch::new(&layout);
            src.resize(lasts.len());
            for (r, last) in lasts.iter().enumerate() {
                let m = src.mask_mut(r).unwrap();
                for (a, legal) in m.iter_mut().enumerate() {
                    *legal = last.is_some_and(|l| a == l || (a < l && (a * 5 + r) % 3 == 0));
                }
            }
            let mut store = ObsStore::new(&layout);
            let slots: Vec<usize> = (0..lasts.len()).map(|r| store.insert(&src, r)).collect();
            let mut out = ObsBatch::new(&layout);
            out.resize(1);
            for (pick, scribble) in reads {
                let r = pick % lasts.len();
                if scribble {
                    out.mask_mut(0).unwrap().fill(true);
                }
                store.read(slots[r], &mut out, 0);
                prop_assert_eq!(out.mask(0), src.mask(r));
                let end = out.legal_end(0);
                prop_assert!(lasts[r].is_none_or(|l| l < end));
                prop_assert!(out.mask(0).unwrap()[end..].iter().all(|l| !l));
            }
        }
    }

    #[test]
    fn masks_round_trip_across_word_and_byte_boundaries() {
        for n in [1, 7, 8, 9, 63, 64, 65, 150] {
            let layout = ObsLayout::floats(vec![("x".into(), vec![1])], Some(n));
            let mut batch = ObsBatch::new(&layout);
            batch.resize(1);
            let want: Vec<bool> = (0..n).map(|a| (a * 7 + a / 5) % 3 == 0).collect();
            batch.mask_mut(0).unwrap().copy_from_slice(&want);
            let mut store = ObsStore::new(&layout);
            let slot = store.insert(&batch, 0);
            let mut out = ObsBatch::new(&layout);
            out.resize(1);
            store.read(slot, &mut out, 0);
            assert_eq!(out.mask(0), Some(&want[..]), "{n} actions");
        }
    }
}

//! A minimal writer of the Apache Arrow IPC *file* format (the `arrow` storage of Minari ≥ 0.5),
//! for the handful of column types offline RL datasets need: `int32`, `int64`, `double`, `bool`,
//! `fixed_size_list` of `float`, `int32`, `int64` or `uint8` (observation tensors in their own
//! element type) and `struct`. One file holds one record batch without nulls.
//!
//! The metadata is FlatBuffers; this module has its own tiny FlatBuffers encoder that lays out
//! every table after the object that points at it (offsets only point forward, as the format
//! requires), so no generated code or `arrow` dependency is needed.

use std::io;
use std::path::Path;

use a2perf_core::TensorData;

/// A column of values (no nulls).
#[derive(Clone, Debug, PartialEq)]
pub enum Column {
    /// 32-bit signed integers.
    I32(Vec<i32>),
    /// 64-bit signed integers.
    I64(Vec<i64>),
    /// 64-bit floats.
    F64(Vec<f64>),
    /// Booleans.
    Bool(Vec<bool>),
    /// Fixed-size lists, `size` per row, row-major in `values`, of the values' element type
    /// (`float`, `int32`, `int64` or `uint8`).
    Fixed {
        /// Elements per row.
        size: usize,
        /// `rows × size` values.
        values: TensorData,
    },
    /// A struct of named child columns.
    Struct(Vec<(String, Column)>),
}

impl Column {
    /// Number of rows.
    pub fn rows(&self) -> usize {
        match self {
            Column::I32(v) => v.len(),
            Column::I64(v) => v.len(),
            Column::F64(v) => v.len(),
            Column::Bool(v) => v.len(),
            Column::Fixed { size, values } => values.len() / (*size).max(1),
            Column::Struct(children) => children.first().map_or(0, |(_, c)| c.rows()),
        }
    }
}

// ---- FlatBuffers -------------------------------------------------------------------------

enum Fb {
    U8(u8),
    I16(i16),
    I32(i32),
    I64(i64),
    Bool(bool),
    Str(String),
    Table(Table),
    Tables(Vec<Table>),
    /// Vector of structs: raw bytes, element count, alignment.
    Structs(Vec<u8>, usize, usize),
}

#[derive(Default)]
struct Table(Vec<(u16, Fb)>);

impl Table {
    fn with(mut self, id: u16, v: Fb) -> Self {
        self.0.push((id, v));
        self
    }
}

struct Buf(Vec<u8>);

impl Buf {
    fn align(&mut self, a: usize) {
        while !self.0.len().is_multiple_of(a) {
            self.0.push(0);
        }
    }
    fn patch_u32(&mut self, at: usize, target: usize) {
        let rel = (target - at) as u32;
        self.0[at..at + 4].copy_from_slice(&rel.to_le_bytes());
    }

    /// Writes `t` (vtable first, then the table, then what it references) and returns the
    /// table's position.
    fn table(&mut self, t: &Table) -> usize {
        let max_id =
            t.0.iter()
                .map(|(id, _)| *id)
                .max()
                .map_or(0, |m| m as usize + 1);
        // Inline layout: soffset (4 bytes), then fields, each aligned to its size.
        let mut layout = Vec::with_capacity(t.0.len());
        let mut size = 4usize;
        for (_, v) in &t.0 {
            let (sz, al) = match v {
                Fb::U8(_) | Fb::Bool(_) => (1, 1),
                Fb::I16(_) => (2, 2),
                Fb::I32(_) => (4, 4),
                Fb::I64(_) => (8, 8),
                _ => (4, 4),
            };
            size = size.next_multiple_of(al);
            layout.push(size);
            size += sz;
        }
        let size = size.next_multiple_of(4);
        // vtable
        self.align(2);
        let vt_pos = self.0.len();
        let vt_len = 4 + 2 * max_id;
        self.0.extend_from_slice(&(vt_len as u16).to_le_bytes());
        self.0.extend_from_slice(&(size as u16).to_le_bytes());
        let mut slots = vec![0u16; max_id];
        for ((id, _), off) in t.0.iter().zip(&layout) {
            slots[*id as usize] = *off as u16;
        }
        for s in slots {
            self.0.extend_from_slice(&s.to_le_bytes());
        }
        // table
        self.align(8);
        let t_pos = self.0.len();
        self.0.resize(t_pos + size, 0);
        let so = (t_pos - vt_pos) as i32;
        self.0[t_pos..t_pos + 4].copy_from_slice(&so.to_le_bytes());
        let mut refs = Vec::new();
        for ((_, v), off) in t.0.iter().zip(&layout) {
            let at = t_pos + off;
            match v {
                Fb::U8(x) => self.0[at] = *x,
                Fb::Bool(x) => self.0[at] = u8::from(*x),
                Fb::I16(x) => self.0[at..at + 2].copy_from_slice(&x.to_le_bytes()),
                Fb::I32(x) => self.0[at..at + 4].copy_from_slice(&x.to_le_bytes()),
                Fb::I64(x) => self.0[at..at + 8].copy_from_slice(&x.to_le_bytes()),
                _ => refs.push((at, v)),
            }
        }
        for (at, v) in refs {
            let target = match v {
                Fb::Str(s) => {
                    self.align(4);
                    let p = self.0.len();
                    self.0.extend_from_slice(&(s.len() as u32).to_le_bytes());
                    self.0.extend_from_slice(s.as_bytes());
                    self.0.push(0);
                    p
                }
                Fb::Table(t) => self.table(t),
                Fb::Tables(ts) => {
                    self.align(4);
                    let p = self.0.len();
                    self.0.extend_from_slice(&(ts.len() as u32).to_le_bytes());
                    let slots: Vec<usize> = (0..ts.len())
                        .map(|_| {
                            let s = self.0.len();
                            self.0.extend_from_slice(&[0; 4]);
                            s
                        })
                        .collect();
                    for (slot, t) in slots.into_iter().zip(ts) {
                        let tp = self.table(t);
                        self.patch_u32(slot, tp);
                    }
                    p
                }
                Fb::Structs(bytes, n, align) => {
                    // The elements must be aligned, so the length prefix sits just before.
                    while !(self.0.len() + 4).is_multiple_of(*align) {
                        self.0.push(0);
                    }
                    let p = self.0.len();
                    self.0.extend_from_slice(&(*n as u32).to_le_bytes());
                    self.0.extend_from_slice(bytes);
                    p
                }
                _ => unreachable!("scalars are written inline"),
            };
            self.patch_u32(at, target);
        }
        t_pos
    }
}

/// A finished FlatBuffer whose root is `root`, padded to a multiple of 8 bytes.
fn finish(root: &Table) -> Vec<u8> {
    let mut b = Buf(vec![0; 8]);
    let pos = b.table(root);
    b.patch_u32(0, pos);
    b.align(8);
    b.0
}

// ---- Arrow schema and batches ---------------------------------------------------------------

const V5: i16 = 4;

fn field(name: &str, col: &Column) -> Table {
    let t = Table::default()
        .with(0, Fb::Str(name.into()))
        .with(1, Fb::Bool(true));
    let (ty, ty_table, children): (u8, Table, Vec<Table>) = match col {
        Column::I32(_) => (
            2,
            Table::default()
                .with(0, Fb::I32(32))
                .with(1, Fb::Bool(true)),
            vec![],
        ),
        Column::I64(_) => (
            2,
            Table::default()
                .with(0, Fb::I32(64))
                .with(1, Fb::Bool(true)),
            vec![],
        ),
        Column::F64(_) => (3, Table::default().with(0, Fb::I16(2)), vec![]),
        Column::Bool(_) => (6, Table::default(), vec![]),
        Column::Fixed { size, values } => (
            16,
            Table::default().with(0, Fb::I32(*size as i32)),
            vec![item_field(values)],
        ),
        Column::Struct(ch) => (
            13,
            Table::default(),
            ch.iter().map(|(n, c)| field(n, c)).collect(),
        ),
    };
    t.with(2, Fb::U8(ty))
        .with(3, Fb::Table(ty_table))
        .with(5, Fb::Tables(children))
}

/// The child field `item` of a fixed-size list holding `values`: `FloatingPoint(SINGLE)` for
/// `f32`, `Int(bits, signed)` for the integer types.
fn item_field(values: &TensorData) -> Table {
    let int = |bits: i32, signed: bool| {
        (
            2u8,
            Table::default()
                .with(0, Fb::I32(bits))
                .with(1, Fb::Bool(signed)),
        )
    };
    let (ty, ty_table) = match values {
        TensorData::F32(_) => (3u8, Table::default().with(0, Fb::I16(1))),
        TensorData::I32(_) => int(32, true),
        TensorData::I64(_) => int(64, true),
        TensorData::U8(_) => int(8, false),
    };
    Table::default()
        .with(0, Fb::Str("item".into()))
        .with(1, Fb::Bool(true))
        .with(2, Fb::U8(ty))
        .with(3, Fb::Table(ty_table))
        .with(5, Fb::Tables(Vec::new()))
}

fn schema(cols: &[(String, Column)]) -> Table {
    Table::default().with(0, Fb::I16(0)).with(
        1,
        Fb::Tables(cols.iter().map(|(n, c)| field(n, c)).collect()),
    )
}

struct Body {
    bytes: Vec<u8>,
    nodes: Vec<(i64, i64)>,
    buffers: Vec<(i64, i64)>,
}

impl Body {
    fn push_buffer(&mut self, data: &[u8]) {
        let off = self.bytes.len();
        self.bytes.extend_from_slice(data);
        self.buffers.push((off as i64, data.len() as i64));
        while !self.bytes.len().is_multiple_of(8) {
            self.bytes.push(0);
        }
    }
    fn column(&mut self, c: &Column) {
        self.nodes.push((c.rows() as i64, 0));
        // No nulls: an empty validity bitmap.
        self.buffers.push((self.bytes.len() as i64, 0));
        match c {
            Column::I32(v) => {
                self.push_buffer(&v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>())
            }
            Column::I64(v) => {
                self.push_buffer(&v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>())
            }
            Column::F64(v) => {
                self.push_buffer(&v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>())
            }
            Column::Bool(v) => {
                let mut bits = vec![0u8; v.len().div_ceil(8)];
                for (i, b) in v.iter().enumerate() {
                    if *b {
                        bits[i / 8] |= 1 << (i % 8);
                    }
                }
                self.push_buffer(&bits);
            }
            Column::Fixed { values, .. } => {
                self.nodes.push((values.len() as i64, 0));
                self.buffers.push((self.bytes.len() as i64, 0));
                let bytes: Vec<u8> = match values {
                    TensorData::F32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                    TensorData::I32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                    TensorData::I64(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                    TensorData::U8(v) => v.clone(),
                };
                self.push_buffer(&bytes);
            }
            Column::Struct(ch) => {
                for (_, c) in ch {
                    self.column(c);
                }
            }
        }
    }
}

fn structs16(pairs: &[(i64, i64)]) -> Fb {
    let bytes = pairs
        .iter()
        .flat_map(|(a, b)| a.to_le_bytes().into_iter().chain(b.to_le_bytes()))
        .collect();
    Fb::Structs(bytes, pairs.len(), 8)
}

/// Encapsulates a message: continuation marker, metadata length, metadata (padded to 8).
fn message(out: &mut Vec<u8>, header_type: u8, header: Table, body_len: usize) -> usize {
    let meta = finish(
        &Table::default()
            .with(0, Fb::I16(V5))
            .with(1, Fb::U8(header_type))
            .with(2, Fb::Table(header))
            .with(3, Fb::I64(body_len as i64)),
    );
    out.extend_from_slice(&0xFFFF_FFFFu32.to_le_bytes());
    out.extend_from_slice(&(meta.len() as u32).to_le_bytes());
    out.extend_from_slice(&meta);
    8 + meta.len()
}

/// Encodes one record batch of `cols` (all with the same number of rows) as an Arrow IPC file.
pub fn encode_file(cols: &[(String, Column)]) -> io::Result<Vec<u8>> {
    let rows = cols.first().map_or(0, |(_, c)| c.rows());
    if let Some((name, _)) = cols.iter().find(|(_, c)| c.rows() != rows) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("column `{name}` has a different number of rows"),
        ));
    }
    let mut out = b"ARROW1\0\0".to_vec();
    message(&mut out, 1, schema(cols), 0);
    let mut body = Body {
        bytes: Vec::new(),
        nodes: Vec::new(),
        buffers: Vec::new(),
    };
    for (_, c) in cols {
        body.column(c);
    }
    let batch = Table::default()
        .with(0, Fb::I64(rows as i64))
        .with(1, structs16(&body.nodes))
        .with(2, structs16(&body.buffers));
    let block_offset = out.len();
    let meta_len = message(&mut out, 3, batch, body.bytes.len());
    out.extend_from_slice(&body.bytes);
    // End-of-stream marker.
    out.extend_from_slice(&0xFFFF_FFFFu32.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    let mut block = Vec::with_capacity(24);
    block.extend_from_slice(&(block_offset as i64).to_le_bytes());
    block.extend_from_slice(&(meta_len as i32).to_le_bytes());
    block.extend_from_slice(&[0; 4]);
    block.extend_from_slice(&(body.bytes.len() as i64).to_le_bytes());
    let footer = finish(
        &Table::default()
            .with(0, Fb::I16(V5))
            .with(1, Fb::Table(schema(cols)))
            .with(2, Fb::Structs(Vec::new(), 0, 8))
            .with(3, Fb::Structs(block, 1, 8)),
    );
    out.extend_from_slice(&footer);
    out.extend_from_slice(&(footer.len() as i32).to_le_bytes());
    out.extend_from_slice(b"ARROW1");
    Ok(out)
}

/// Writes [`encode_file`]'s output atomically to `path`.
pub fn write_file(path: &Path, cols: &[(String, Column)]) -> io::Result<()> {
    a2perf_core::write_atomic(path, &encode_file(cols)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_has_magic_footer_and_aligned_messages() {
        let cols = vec![
            ("a".to_string(), Column::I32(vec![1, 2, 3])),
            ("b".to_string(), Column::Bool(vec![true, false, true])),
            (
                "c".to_string(),
                Column::Fixed {
                    size: 2,
                    values: TensorData::F32(vec![0.5; 6]),
                },
            ),
            (
                "d".to_string(),
                Column::Fixed {
                    size: 3,
                    values: TensorData::I32(vec![7; 9]),
                },
            ),
        ];
        let bytes = encode_file(&cols).unwrap();
        assert_eq!(&bytes[..6], b"ARROW1");
        assert_eq!(&bytes[bytes.len() - 6..], b"ARROW1");
        let n = bytes.len();
        let footer_len = i32::from_le_bytes(bytes[n - 10..n - 6].try_into().unwrap()) as usize;
        assert!(footer_len > 0 && footer_len.is_multiple_of(8) && footer_len < n);
        // First message: continuation marker, then a metadata length that keeps 8-byte alignment.
        assert_eq!(&bytes[8..12], &[0xff; 4]);
        let meta = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        assert_eq!((16 + meta) % 8, 0);
        let mismatched = vec![
            ("a".to_string(), Column::I32(vec![1])),
            ("b".to_string(), Column::F64(vec![1.0, 2.0])),
        ];
        assert!(encode_file(&mismatched).is_err());
    }
}

//! Circuit Training netlists: the protobuf-text `GraphDef` format (plain or gzipped), parsed into a
//! typed [`Netlist`] with implicit nets, and written back.
//!
//! Every `f:` attribute is rounded to `f32` and then widened to `f64`, because Google's binary stores
//! netlist attributes as protobuf `float` and computes in double; costs differ in the 7th digit
//! otherwise.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Read;
use std::path::Path;

/// Errors reading a netlist.
#[derive(Debug, thiserror::Error)]
pub enum NetlistError {
    /// The file could not be read or decompressed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The text is malformed or inconsistent.
    #[error("{path}:{line}: {reason}")]
    Syntax {
        /// The file (or `<text>`).
        path: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// What a node is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum NodeKind {
    /// A hard macro (memory block), placed by the agent.
    HardMacro,
    /// A soft macro: a cluster of standard cells, placed by the force-directed placer.
    SoftMacro,
    /// A pin of a hard macro (offset from the macro centre, rotated with its orientation).
    HardMacroPin,
    /// A pin of a soft macro (at the soft macro's centre).
    SoftMacroPin,
    /// An I/O port: dimensionless and fixed.
    Port,
    /// A standard cell (toy netlists): placed by the force-directed placer.
    StdCell,
}

impl NodeKind {
    /// The netlist's `type` attribute for this kind (`MACRO`, `macro`, `MACRO_PIN`,
    /// `macro_pin`, `PORT`, `STDCELL`), the names `plc_client`'s `get_node_type` returns.
    ///
    /// ```
    /// use a2perf_circuit::netlist::NodeKind;
    /// assert_eq!(NodeKind::SoftMacroPin.type_name(), "macro_pin");
    /// ```
    pub fn type_name(self) -> &'static str {
        match self {
            NodeKind::HardMacro => "MACRO",
            NodeKind::SoftMacro => "macro",
            NodeKind::HardMacroPin => "MACRO_PIN",
            NodeKind::SoftMacroPin => "macro_pin",
            NodeKind::Port => "PORT",
            NodeKind::StdCell => "STDCELL",
        }
    }

    /// Whether the node has an area (macros and standard cells).
    pub fn has_area(self) -> bool {
        matches!(
            self,
            NodeKind::HardMacro | NodeKind::SoftMacro | NodeKind::StdCell
        )
    }

    /// Whether the node is a pin of a macro.
    pub fn is_pin(self) -> bool {
        matches!(self, NodeKind::HardMacroPin | NodeKind::SoftMacroPin)
    }
}

/// Macro orientation (the eight DEF orientations).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
pub enum Orientation {
    /// North (identity).
    #[default]
    N,
    /// Flipped north (mirror x).
    FN,
    /// South (180°).
    S,
    /// Flipped south (mirror y).
    FS,
    /// East.
    E,
    /// Flipped east.
    FE,
    /// West.
    W,
    /// Flipped west.
    FW,
}

impl Orientation {
    /// Parses `N`, `FN`, `S`, …
    ///
    /// ```
    /// use a2perf_circuit::Orientation;
    /// assert_eq!(Orientation::parse("FS"), Some(Orientation::FS));
    /// assert_eq!(Orientation::parse("Q"), None);
    /// ```
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "N" => Self::N,
            "FN" => Self::FN,
            "S" => Self::S,
            "FS" => Self::FS,
            "E" => Self::E,
            "FE" => Self::FE,
            "W" => Self::W,
            "FW" => Self::FW,
            _ => return None,
        })
    }

    /// The name as written in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::N => "N",
            Self::FN => "FN",
            Self::S => "S",
            Self::FS => "FS",
            Self::E => "E",
            Self::FE => "FE",
            Self::W => "W",
            Self::FW => "FW",
        }
    }

    /// Transforms an N-frame pin offset into this orientation (plc_client_os convention; `S`
    /// verified against Google's binary, the 90° ones are not).
    ///
    /// ```
    /// use a2perf_circuit::Orientation;
    /// assert_eq!(Orientation::S.apply(1.0, 2.0), (-1.0, -2.0));
    /// ```
    pub fn apply(self, x: f64, y: f64) -> (f64, f64) {
        match self {
            Self::N => (x, y),
            Self::FN => (-x, y),
            Self::S => (-x, -y),
            Self::FS => (x, -y),
            Self::E => (y, -x),
            Self::FE => (-y, -x),
            Self::W => (-y, x),
            Self::FW => (y, x),
        }
    }
}

/// How lower/upper-case `macro` nodes are split into hard and soft macros.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SoftMacroRule {
    /// Google's documented rule (and the binary's behaviour on `macro_tiles_10x10`): a macro is soft
    /// iff its name starts with `Grp`.
    #[default]
    NamePrefix,
    /// plc_client_os's rule: `macro` (lower case) is soft, `MACRO` hard.
    TypeCase,
}

/// A netlist attribute value.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum AttrValue {
    /// A float (already rounded to f32).
    F(f64),
    /// A string (`placeholder:` or `s:`).
    S(String),
}

/// One node of the netlist.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// Unique name.
    pub name: String,
    /// Classification.
    pub kind: NodeKind,
    /// The `type` attribute as written (`MACRO`, `macro`, …).
    pub type_name: String,
    /// Width (µm), 0 for pins and ports.
    pub width: f64,
    /// Height (µm).
    pub height: f64,
    /// Centre x from the netlist (0 when absent).
    pub x: f64,
    /// Centre y from the netlist.
    pub y: f64,
    /// Whether the netlist gives `x`/`y`.
    pub has_xy: bool,
    /// Orientation (macros).
    pub orientation: Orientation,
    /// For pins: node index of the owning macro.
    pub macro_index: Option<usize>,
    /// For pins: N-frame offset from the macro centre.
    pub x_offset: f64,
    /// For pins: N-frame offset from the macro centre.
    pub y_offset: f64,
    /// `weight` attribute, when present.
    pub weight: Option<f64>,
    /// Port side.
    pub side: Option<String>,
    /// Standard-cell reference name.
    pub ref_name: Option<String>,
    /// Node indices this node drives (its `input` list).
    pub inputs: Vec<usize>,
    /// Attributes not covered by the fields above, in file order.
    pub other_attrs: Vec<(String, AttrValue)>,
}

impl Node {
    /// A node of `kind` with everything else empty.
    pub fn new(name: &str, kind: NodeKind) -> Self {
        Self {
            name: name.to_string(),
            kind,
            type_name: kind.type_name().to_string(),
            width: 0.0,
            height: 0.0,
            x: 0.0,
            y: 0.0,
            has_xy: false,
            orientation: Orientation::N,
            macro_index: None,
            x_offset: 0.0,
            y_offset: 0.0,
            weight: None,
            side: None,
            ref_name: None,
            inputs: Vec::new(),
            other_attrs: Vec::new(),
        }
    }
}

/// An implicit net: a driver and the nodes in its `input` list.
#[derive(Clone, Debug, PartialEq)]
pub struct Net {
    /// Driver node index.
    pub driver: usize,
    /// Sink node indices (file order, duplicates kept).
    pub sinks: Vec<usize>,
    /// Wirelength weight: the driver's `weight` (default 1; ports 1).
    pub weight: f64,
    /// Congestion weight: the driver's weight when it is a pin/cell with weight > 1, else 1.
    pub congestion_weight: f64,
}

/// A parsed netlist.
#[derive(Clone, Debug, PartialEq)]
pub struct Netlist {
    /// Name (file stem or generator name).
    pub name: String,
    /// Nodes in file order (without `__metadata__`).
    pub nodes: Vec<Node>,
    /// Attributes of the `__metadata__` node.
    pub metadata: Vec<(String, AttrValue)>,
    /// `# FP bbox: {x0 y0} {W H}` from the comments, when present.
    pub fp_bbox: Option<[f64; 4]>,
    /// Comment lines at the top of the file (without `#`).
    pub comments: Vec<String>,
    /// Implicit nets, in driver order.
    pub nets: Vec<Net>,
    /// FNV-1a 64-bit hash of the (decompressed) text, hex.
    pub content_hash: String,
}

/// FNV-1a 64 of bytes as 16 hex digits (stable provenance hash).
pub fn content_hash(bytes: &[u8]) -> String {
    format!("{:016x}", a2perf_core::hash::fnv1a64(bytes))
}

/// Reads a file, gunzipping when it starts with the gzip magic.
pub(crate) fn read_maybe_gz(path: &Path) -> Result<String, std::io::Error> {
    let bytes = std::fs::read(path)?;
    let bytes = if bytes.starts_with(&[0x1f, 0x8b]) {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(&bytes[..]).read_to_end(&mut out)?;
        out
    } else {
        bytes
    };
    String::from_utf8(bytes)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e.to_string()))
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Word(String),
    Str(String),
    Colon,
    Open,
    Close,
}

struct Lexer<'a> {
    src: &'a [u8],
    pos: usize,
    line: usize,
    comments: Vec<String>,
    seen_token: bool,
}

impl<'a> Lexer<'a> {
    fn next(&mut self) -> Result<Option<(Tok, usize)>, (usize, String)> {
        loop {
            let Some(&c) = self.src.get(self.pos) else {
                return Ok(None);
            };
            match c {
                b'\n' => {
                    self.line += 1;
                    self.pos += 1;
                }
                b' ' | b'\t' | b'\r' | b',' | b';' => self.pos += 1,
                b'#' => {
                    let start = self.pos + 1;
                    while self.pos < self.src.len() && self.src[self.pos] != b'\n' {
                        self.pos += 1;
                    }
                    if !self.seen_token {
                        let text = String::from_utf8_lossy(&self.src[start..self.pos]);
                        self.comments.push(text.trim().to_string());
                    }
                }
                b':' => {
                    self.pos += 1;
                    self.seen_token = true;
                    return Ok(Some((Tok::Colon, self.line)));
                }
                b'{' | b'<' => {
                    self.pos += 1;
                    self.seen_token = true;
                    return Ok(Some((Tok::Open, self.line)));
                }
                b'}' | b'>' => {
                    self.pos += 1;
                    self.seen_token = true;
                    return Ok(Some((Tok::Close, self.line)));
                }
                b'"' | b'\'' => {
                    let quote = c;
                    let line = self.line;
                    self.pos += 1;
                    let mut out = Vec::new();
                    loop {
                        let Some(&d) = self.src.get(self.pos) else {
                            return Err((line, "unterminated string".into()));
                        };
                        self.pos += 1;
                        if d == quote {
                            break;
                        }
                        if d == b'\n' {
                            return Err((line, "newline inside string".into()));
                        }
                        if d == b'\\' {
                            let Some(&e) = self.src.get(self.pos) else {
                                return Err((line, "unterminated escape".into()));
                            };
                            self.pos += 1;
                            out.push(match e {
                                b'n' => b'\n',
                                b't' => b'\t',
                                other => other,
                            });
                        } else {
                            out.push(d);
                        }
                    }
                    self.seen_token = true;
                    let s = String::from_utf8(out).map_err(|_| (line, "invalid UTF-8".into()))?;
                    return Ok(Some((Tok::Str(s), line)));
                }
                _ => {
                    let start = self.pos;
                    while let Some(&d) = self.src.get(self.pos) {
                        if d.is_ascii_whitespace()
                            || matches!(d, b':' | b'{' | b'}' | b'<' | b'>' | b'"' | b'\'' | b'#')
                            || d == b','
                            || d == b';'
                        {
                            break;
                        }
                        self.pos += 1;
                    }
                    self.seen_token = true;
                    let w = String::from_utf8_lossy(&self.src[start..self.pos]).into_owned();
                    return Ok(Some((Tok::Word(w), self.line)));
                }
            }
        }
    }
}

struct Parser<'a> {
    lex: Lexer<'a>,
    round_f32: bool,
    peeked: Option<(Tok, usize)>,
    last_line: usize,
}

type PResult<T> = Result<T, (usize, String)>;

impl Parser<'_> {
    fn bump(&mut self) -> PResult<Option<(Tok, usize)>> {
        let t = match self.peeked.take() {
            Some(t) => Some(t),
            None => self.lex.next()?,
        };
        if let Some((_, l)) = &t {
            self.last_line = *l;
        }
        Ok(t)
    }

    fn expect(&mut self, what: &str) -> PResult<(Tok, usize)> {
        self.bump()?.ok_or_else(|| {
            (
                self.lex.line,
                format!("unexpected end of file, expected {what}"),
            )
        })
    }

    /// After a field name: optional `:` then `{` (returns None) or a scalar (returns it).
    fn field_value(&mut self, field: &str) -> PResult<Option<(Tok, usize)>> {
        let (t, line) = self.expect(&format!("a value for `{field}`"))?;
        let (t, line) = if t == Tok::Colon {
            self.expect(&format!("a value for `{field}`"))?
        } else {
            (t, line)
        };
        match t {
            Tok::Open => Ok(None),
            Tok::Str(_) | Tok::Word(_) => Ok(Some((t, line))),
            other => Err((
                line,
                format!("expected a value for `{field}`, found {other:?}"),
            )),
        }
    }

    /// Skips the body of a message whose `{` was consumed.
    fn skip_message(&mut self) -> PResult<()> {
        let mut depth = 1usize;
        while depth > 0 {
            let (t, _) = self.expect("`}`")?;
            match t {
                Tok::Open => depth += 1,
                Tok::Close => depth -= 1,
                _ => {}
            }
        }
        Ok(())
    }
}

struct RawNode {
    name: Option<String>,
    line: usize,
    inputs: Vec<(String, usize)>,
    attrs: Vec<(String, AttrValue, usize)>,
}

fn parse_attr(p: &mut Parser<'_>, line: usize) -> PResult<(String, AttrValue, usize)> {
    let mut key = None;
    let mut value = None;
    loop {
        let (t, l) = p.expect("`}` closing attr")?;
        match t {
            Tok::Close => break,
            Tok::Word(w) if w == "key" => match p.field_value("key")? {
                Some((Tok::Str(s), _)) | Some((Tok::Word(s), _)) => key = Some(s),
                _ => return Err((l, "attr key must be a string".into())),
            },
            Tok::Word(w) if w == "value" => {
                if p.field_value("value")?.is_some() {
                    return Err((l, "attr value must be a message `{ ... }`".into()));
                }
                loop {
                    let (t, l2) = p.expect("`}` closing value")?;
                    match t {
                        Tok::Close => break,
                        Tok::Word(kind) => match p.field_value(&kind)? {
                            None => p.skip_message()?,
                            Some((scalar, l3)) => {
                                let text = match scalar {
                                    Tok::Str(s) | Tok::Word(s) => s,
                                    _ => String::new(),
                                };
                                value = Some(match kind.as_str() {
                                    "f" | "i" => {
                                        let v: f64 =
                                            text.trim_end_matches(['f', 'F']).parse().map_err(
                                                |_| (l3, format!("`{text}` is not a number")),
                                            )?;
                                        // protobuf `float`: rounded to f32 like Google's binary.
                                        let v = if p.round_f32 { f64::from(v as f32) } else { v };
                                        if !v.is_finite() {
                                            return Err((
                                                l3,
                                                format!("`{text}` is not a finite float"),
                                            ));
                                        }
                                        AttrValue::F(v)
                                    }
                                    _ => AttrValue::S(text),
                                });
                            }
                        },
                        other => return Err((l2, format!("unexpected {other:?} in attr value"))),
                    }
                }
            }
            Tok::Word(w) => {
                if p.field_value(&w)?.is_none() {
                    p.skip_message()?;
                }
            }
            other => return Err((l, format!("unexpected {other:?} in attr"))),
        }
    }
    let key = key.ok_or((line, "attr without `key`".to_string()))?;
    let value = value.ok_or((line, format!("attr `{key}` without a value")))?;
    Ok((key, value, line))
}

fn parse_node(p: &mut Parser<'_>, line: usize) -> PResult<RawNode> {
    let mut node = RawNode {
        name: None,
        line,
        inputs: Vec::new(),
        attrs: Vec::new(),
    };
    loop {
        let (t, l) = p.expect("`}` closing node")?;
        match t {
            Tok::Close => return Ok(node),
            Tok::Word(w) => match w.as_str() {
                "name" => match p.field_value("name")? {
                    Some((Tok::Str(s), _)) => node.name = Some(s),
                    _ => return Err((l, "node name must be a quoted string".into())),
                },
                "input" => match p.field_value("input")? {
                    Some((Tok::Str(s), l2)) => node.inputs.push((s, l2)),
                    _ => return Err((l, "input must be a quoted string".into())),
                },
                "attr" => {
                    if p.field_value("attr")?.is_some() {
                        return Err((l, "attr must be a message `{ ... }`".into()));
                    }
                    node.attrs.push(parse_attr(p, l)?);
                }
                _ => {
                    if p.field_value(&w)?.is_none() {
                        p.skip_message()?;
                    }
                }
            },
            other => return Err((l, format!("unexpected {other:?} in node"))),
        }
    }
}

pub(crate) fn parse_fp_bbox(comments: &[String]) -> Option<[f64; 4]> {
    for c in comments {
        if let Some(rest) = c.split("FP bbox:").nth(1) {
            let nums: Vec<f64> = rest
                .split(|ch: char| ch == '{' || ch == '}' || ch.is_whitespace())
                .filter(|s| !s.is_empty())
                .filter_map(|s| s.parse().ok())
                .collect();
            if nums.len() == 4 && nums.iter().all(|v| v.is_finite()) {
                return Some([nums[0], nums[1], nums[2], nums[3]]);
            }
        }
    }
    None
}

impl Netlist {
    /// Reads a netlist file (`.pb.txt`, optionally gzipped).
    pub fn from_file(path: impl AsRef<Path>, rule: SoftMacroRule) -> Result<Self, NetlistError> {
        Self::from_file_with(path, rule, true)
    }

    /// Like [`Netlist::from_file`]; `round_f32 = false` keeps attributes in full `f64` precision
    /// (plc_client_os behaviour, for cross-checks).
    pub fn from_file_with(
        path: impl AsRef<Path>,
        rule: SoftMacroRule,
        round_f32: bool,
    ) -> Result<Self, NetlistError> {
        let path = path.as_ref();
        let shown = path.display().to_string();
        let text = read_maybe_gz(path).map_err(|source| NetlistError::Io {
            path: shown.clone(),
            source,
        })?;
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .map(|n| {
                n.trim_end_matches(".gz")
                    .trim_end_matches(".pb.txt")
                    .to_string()
            })
            .unwrap_or_default();
        // A netlist called `netlist.pb.txt` is named after its directory.
        let name = if name == "netlist" {
            path.parent()
                .and_then(|p| p.file_name())
                .and_then(|n| n.to_str())
                .unwrap_or("netlist")
                .to_string()
        } else {
            name
        };
        Self::parse_named(&text, &name, &shown, rule, round_f32)
    }

    /// Parses netlist text; `source` names it in errors.
    ///
    /// ```
    /// use a2perf_circuit::{Netlist, SoftMacroRule, NodeKind};
    /// let text = r#"
    /// node { name: "M0" attr { key: "type" value { placeholder: "MACRO" } }
    ///        attr { key: "width" value { f: 10 } } attr { key: "height" value { f: 5 } } }
    /// node { name: "M0/P" input: "P0"
    ///        attr { key: "type" value { placeholder: "MACRO_PIN" } }
    ///        attr { key: "macro_name" value { placeholder: "M0" } } }
    /// node { name: "P0" attr { key: "type" value { placeholder: "PORT" } } }
    /// "#;
    /// let n = Netlist::parse(text, SoftMacroRule::default()).unwrap();
    /// assert_eq!(n.nodes[0].kind, NodeKind::HardMacro);
    /// assert_eq!(n.nets.len(), 1);
    /// assert!(Netlist::parse("node { name: ", SoftMacroRule::default()).is_err());
    /// ```
    pub fn parse(text: &str, rule: SoftMacroRule) -> Result<Self, NetlistError> {
        Self::parse_named(text, "netlist", "<text>", rule, true)
    }

    fn parse_named(
        text: &str,
        name: &str,
        source: &str,
        rule: SoftMacroRule,
        round_f32: bool,
    ) -> Result<Self, NetlistError> {
        let err = |line: usize, reason: String| NetlistError::Syntax {
            path: source.to_string(),
            line,
            reason,
        };
        let mut p = Parser {
            lex: Lexer {
                src: text.as_bytes(),
                pos: 0,
                line: 1,
                comments: Vec::new(),
                seen_token: false,
            },
            round_f32,
            peeked: None,
            last_line: 1,
        };
        let mut raw = Vec::new();
        while let Some((t, line)) = p.bump().map_err(|(l, r)| err(l, r))? {
            match t {
                Tok::Word(w) if w == "node" => {
                    let opened = p.field_value("node").map_err(|(l, r)| err(l, r))?;
                    if opened.is_some() {
                        return Err(err(line, "`node` must be a message `{ ... }`".into()));
                    }
                    raw.push(parse_node(&mut p, line).map_err(|(l, r)| err(l, r))?);
                }
                other => {
                    return Err(err(line, format!("expected `node {{`, found {other:?}")));
                }
            }
        }
        let _ = p.last_line;
        let comments = std::mem::take(&mut p.lex.comments);
        let mut metadata = Vec::new();
        let mut index: HashMap<String, usize> = HashMap::new();
        let mut nodes: Vec<Node> = Vec::new();
        let mut pending_inputs: Vec<Vec<(String, usize)>> = Vec::new();
        let mut pending_macro: Vec<Option<(String, usize)>> = Vec::new();
        for r in raw {
            let Some(node_name) = r.name else {
                return Err(err(r.line, "node without `name`".into()));
            };
            if node_name == "__metadata__" {
                metadata = r.attrs.into_iter().map(|(k, v, _)| (k, v)).collect();
                continue;
            }
            let ty = r
                .attrs
                .iter()
                .find(|(k, _, _)| k == "type")
                .map(|(_, v, l)| (v.clone(), *l));
            let Some((AttrValue::S(ty), ty_line)) = ty else {
                return Err(err(
                    r.line,
                    format!("node `{node_name}` has no string `type` attribute"),
                ));
            };
            let kind = match ty.as_str() {
                "MACRO" | "macro" => {
                    let soft = match rule {
                        SoftMacroRule::NamePrefix => node_name.starts_with("Grp"),
                        SoftMacroRule::TypeCase => ty == "macro",
                    };
                    if soft {
                        NodeKind::SoftMacro
                    } else {
                        NodeKind::HardMacro
                    }
                }
                // Resolved once the owning macro is known.
                "MACRO_PIN" | "macro_pin" => NodeKind::HardMacroPin,
                "PORT" | "port" => NodeKind::Port,
                "STDCELL" | "stdcell" => NodeKind::StdCell,
                other => {
                    return Err(err(
                        ty_line,
                        format!("node `{node_name}`: unknown type `{other}`"),
                    ));
                }
            };
            let mut node = Node::new(&node_name, kind);
            node.type_name = ty;
            let mut macro_name = None;
            let mut has_x = false;
            let mut has_y = false;
            for (k, v, l) in r.attrs {
                let num = |v: &AttrValue| match v {
                    AttrValue::F(f) => Ok(*f),
                    AttrValue::S(s) => s
                        .parse::<f64>()
                        .ok()
                        .map(|f| if round_f32 { f64::from(f as f32) } else { f })
                        .filter(|f| f.is_finite())
                        .ok_or_else(|| err(l, format!("attr `{k}` must be a number, found `{s}`"))),
                };
                match k.as_str() {
                    "type" => {}
                    "width" => node.width = num(&v)?,
                    "height" => node.height = num(&v)?,
                    "x" => {
                        node.x = num(&v)?;
                        has_x = true;
                    }
                    "y" => {
                        node.y = num(&v)?;
                        has_y = true;
                    }
                    "x_offset" => node.x_offset = num(&v)?,
                    "y_offset" => node.y_offset = num(&v)?,
                    "weight" => node.weight = Some(num(&v)?),
                    "orientation" => match &v {
                        AttrValue::S(s) => {
                            node.orientation = Orientation::parse(s)
                                .ok_or_else(|| err(l, format!("unknown orientation `{s}`")))?;
                        }
                        AttrValue::F(_) => {
                            return Err(err(l, "orientation must be a string".into()));
                        }
                    },
                    "macro_name" => match v {
                        AttrValue::S(s) => macro_name = Some((s, l)),
                        AttrValue::F(_) => {
                            return Err(err(l, "macro_name must be a string".into()));
                        }
                    },
                    "side" => {
                        if let AttrValue::S(s) = v {
                            node.side = Some(s);
                        }
                    }
                    "ref_name" => {
                        if let AttrValue::S(s) = v {
                            node.ref_name = Some(s);
                        }
                    }
                    _ => node.other_attrs.push((k, v)),
                }
            }
            if node.width < 0.0 || node.height < 0.0 {
                return Err(err(
                    r.line,
                    format!("node `{node_name}` has a negative size"),
                ));
            }
            node.has_xy = has_x && has_y;
            if index.insert(node_name.clone(), nodes.len()).is_some() {
                return Err(err(r.line, format!("duplicate node name `{node_name}`")));
            }
            if node.kind.is_pin() && macro_name.is_none() {
                return Err(err(
                    r.line,
                    format!("pin `{node_name}` has no `macro_name`"),
                ));
            }
            nodes.push(node);
            pending_inputs.push(r.inputs);
            pending_macro.push(macro_name);
        }
        for (i, m) in pending_macro.into_iter().enumerate() {
            let Some((mname, l)) = m else { continue };
            let Some(&mi) = index.get(&mname) else {
                return Err(err(l, format!("unknown macro `{mname}`")));
            };
            let kind = match nodes[mi].kind {
                NodeKind::HardMacro => NodeKind::HardMacroPin,
                NodeKind::SoftMacro => NodeKind::SoftMacroPin,
                _ => {
                    return Err(err(l, format!("`{mname}` is not a macro")));
                }
            };
            nodes[i].kind = kind;
            nodes[i].macro_index = Some(mi);
        }
        for (i, inputs) in pending_inputs.into_iter().enumerate() {
            let mut resolved = Vec::with_capacity(inputs.len());
            for (s, l) in inputs {
                let Some(&j) = index.get(&s) else {
                    return Err(err(l, format!("input `{s}` names no node")));
                };
                resolved.push(j);
            }
            nodes[i].inputs = resolved;
        }
        let mut netlist = Netlist {
            name: name.to_string(),
            fp_bbox: parse_fp_bbox(&comments),
            comments,
            nodes,
            metadata,
            nets: Vec::new(),
            content_hash: content_hash(text.as_bytes()),
        };
        netlist.rebuild_nets();
        Ok(netlist)
    }

    /// Recomputes [`Netlist::nets`] from the nodes' `inputs`.
    pub fn rebuild_nets(&mut self) {
        self.nets = self
            .nodes
            .iter()
            .enumerate()
            .filter(|(_, n)| !n.inputs.is_empty())
            .map(|(i, n)| {
                let w = if n.kind == NodeKind::Port {
                    1.0
                } else {
                    n.weight.unwrap_or(1.0)
                };
                Net {
                    driver: i,
                    sinks: n.inputs.clone(),
                    weight: w,
                    congestion_weight: if w > 1.0 { w } else { 1.0 },
                }
            })
            .collect();
    }

    /// Indices of nodes of `kind`, ascending.
    pub fn indices_of(&self, kind: NodeKind) -> Vec<usize> {
        self.nodes
            .iter()
            .enumerate()
            .filter(|(_, n)| n.kind == kind)
            .map(|(i, _)| i)
            .collect()
    }

    /// Number of nodes of `kind`.
    pub fn count(&self, kind: NodeKind) -> usize {
        self.nodes.iter().filter(|n| n.kind == kind).count()
    }

    /// Total area of macros and standard cells (f32 attributes, summed in f64).
    pub fn total_area(&self) -> f64 {
        self.nodes
            .iter()
            .filter(|n| n.kind.has_area())
            .map(|n| n.width * n.height)
            .sum()
    }

    /// Σ net weights (0 → 1).
    pub fn weighted_net_count(&self) -> f64 {
        let s: f64 = self.nets.iter().map(|n| n.weight).sum();
        if s == 0.0 { 1.0 } else { s }
    }

    /// Writes the netlist in protobuf text format (parseable by [`Netlist::parse`], with identical
    /// nodes when every float is an f32 value).
    pub fn to_pbtxt(&self) -> String {
        let mut s = String::new();
        for c in &self.comments {
            let _ = writeln!(s, "# {c}");
        }
        if !self.metadata.is_empty() {
            s.push_str("node {\n  name: \"__metadata__\"\n");
            for (k, v) in &self.metadata {
                write_attr(&mut s, k, v);
            }
            s.push_str("}\n");
        }
        for n in &self.nodes {
            let _ = writeln!(s, "node {{\n  name: {}", quote(&n.name));
            for &i in &n.inputs {
                let _ = writeln!(s, "  input: {}", quote(&self.nodes[i].name));
            }
            write_attr(&mut s, "type", &AttrValue::S(n.type_name.clone()));
            if let Some(m) = n.macro_index {
                write_attr(
                    &mut s,
                    "macro_name",
                    &AttrValue::S(self.nodes[m].name.clone()),
                );
            }
            if n.kind.has_area() {
                write_attr(&mut s, "width", &AttrValue::F(n.width));
                write_attr(&mut s, "height", &AttrValue::F(n.height));
            }
            if n.has_xy {
                write_attr(&mut s, "x", &AttrValue::F(n.x));
                write_attr(&mut s, "y", &AttrValue::F(n.y));
            }
            if n.kind.is_pin() {
                write_attr(&mut s, "x_offset", &AttrValue::F(n.x_offset));
                write_attr(&mut s, "y_offset", &AttrValue::F(n.y_offset));
            }
            if matches!(n.kind, NodeKind::HardMacro | NodeKind::SoftMacro)
                && n.orientation != Orientation::N
                || n.kind == NodeKind::HardMacro
            {
                write_attr(
                    &mut s,
                    "orientation",
                    &AttrValue::S(n.orientation.as_str().into()),
                );
            }
            if let Some(w) = n.weight {
                write_attr(&mut s, "weight", &AttrValue::F(w));
            }
            if let Some(side) = &n.side {
                write_attr(&mut s, "side", &AttrValue::S(side.clone()));
            }
            if let Some(r) = &n.ref_name {
                write_attr(&mut s, "ref_name", &AttrValue::S(r.clone()));
            }
            for (k, v) in &n.other_attrs {
                write_attr(&mut s, k, v);
            }
            s.push_str("}\n");
        }
        s
    }
}

fn quote(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn write_attr(s: &mut String, key: &str, v: &AttrValue) {
    let _ = writeln!(s, "  attr {{\n    key: {}\n    value {{", quote(key));
    match v {
        // f32 Display is the shortest text that round-trips to the same f32.
        AttrValue::F(f) => {
            let _ = writeln!(s, "      f: {}", *f as f32);
        }
        AttrValue::S(t) => {
            let _ = writeln!(s, "      placeholder: {}", quote(t));
        }
    }
    s.push_str("    }\n  }\n");
}

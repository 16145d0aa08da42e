//! `.plc` placement files: `#` header comments and `node_index x y orientation fixed` lines.

use std::fmt::Write as _;
use std::path::Path;

use crate::netlist::Orientation;

/// Errors reading a placement.
#[derive(Debug, thiserror::Error)]
pub enum PlcError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A malformed line.
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

/// One node line.
#[derive(Clone, Debug, PartialEq)]
pub struct PlcEntry {
    /// Node index in the netlist.
    pub index: usize,
    /// Centre x.
    pub x: f64,
    /// Centre y.
    pub y: f64,
    /// Orientation (`None` for `-`).
    pub orientation: Option<Orientation>,
    /// Whether the node is fixed.
    pub fixed: bool,
}

/// A blockage rectangle `minx miny maxx maxy rate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blockage {
    /// Rectangle and blockage rate.
    pub rect: [f64; 5],
}

/// Header values recognised in the comments (everything else is kept verbatim).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlcHeader {
    /// `Columns : c  Rows : r`.
    pub grid: Option<(usize, usize)>,
    /// `Width : w  Height : h`.
    pub canvas: Option<(f64, f64)>,
    /// `Routes per micron, hor : h  ver : v`.
    pub routes_per_micron: Option<(f64, f64)>,
    /// `Routes used by macros, hor : h  ver : v`.
    pub macro_routing_alloc: Option<(f64, f64)>,
    /// `Smoothing factor : k`.
    pub smooth_range: Option<f64>,
    /// `Overlap threshold : t`.
    pub overlap_threshold: Option<f64>,
    /// `Block : name`.
    pub block: Option<String>,
    /// `Blockage : minx miny maxx maxy rate` lines.
    pub blockages: Vec<Blockage>,
}

/// A placement file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Placement {
    /// Header comment lines, without the leading `#` (kept verbatim for round trips).
    pub comments: Vec<String>,
    /// Values parsed from the comments.
    pub header: PlcHeader,
    /// Node lines in file order.
    pub entries: Vec<PlcEntry>,
}

/// The number after `key :` (NaN and infinities included).
fn num_after(s: &str, key: &str) -> Option<f64> {
    let rest = s.split(key).nth(1)?;
    let rest = rest.trim_start().strip_prefix(':')?.trim_start();
    rest.split_whitespace().next()?.parse().ok()
}

fn nums_after(s: &str, key: &str) -> Option<f64> {
    num_after(s, key).filter(|v: &f64| v.is_finite())
}

/// What is wrong with a canvas that header comments state (`FP bbox: {x0 y0} {W H}` or
/// `Width : W  Height : H`) when it is not a positive finite rectangle, or `None`.
///
/// circuit_training's regular expressions would skip such a line and fall back to another
/// canvas; a file that names a NaN, infinite, zero or negative canvas is broken, so it is
/// reported instead of placed on a canvas the file did not ask for.
///
/// ```
/// use a2perf_circuit::plc::canvas_problem;
/// let lines = |s: &str| vec![s.to_string()];
/// assert_eq!(canvas_problem(&lines("Width : 20.5  Height : 10")), None);
/// assert_eq!(canvas_problem(&lines("FP bbox: {0.0 0.0} {200.0 100.0}")), None);
/// assert!(canvas_problem(&lines("Width : nan  Height : 10")).is_some());
/// assert!(canvas_problem(&lines("FP bbox: {0.0 0.0} {200.0 -1}")).is_some());
/// ```
pub fn canvas_problem(comments: &[String]) -> Option<String> {
    let bad = |v: f64| !(v.is_finite() && v > 0.0);
    for c in comments {
        let c = c.trim();
        if let Some(rest) = c.split("FP bbox:").nth(1) {
            let nums: Vec<&str> = rest
                .split(|ch: char| ch == '{' || ch == '}' || ch.is_whitespace())
                .filter(|s| !s.is_empty())
                .collect();
            let size = match nums.as_slice() {
                [_, _, w, h, ..] => w.parse::<f64>().ok().zip(h.parse::<f64>().ok()),
                _ => None,
            };
            match size {
                Some((w, h)) if !bad(w) && !bad(h) => {}
                _ => return Some(format!("canvas `{c}` is not a positive finite rectangle")),
            }
        } else if c.starts_with("Width") {
            match (num_after(c, "Width"), num_after(c, "Height")) {
                (Some(w), Some(h)) if !bad(w) && !bad(h) => {}
                _ => return Some(format!("canvas `{c}` is not a positive finite rectangle")),
            }
        }
    }
    None
}

pub(crate) fn parse_header(comments: &[String]) -> PlcHeader {
    let mut h = PlcHeader::default();
    for c in comments {
        let c = c.trim();
        if c.starts_with("Columns") {
            if let (Some(cols), Some(rows)) = (nums_after(c, "Columns"), nums_after(c, "Rows"))
                && cols >= 1.0
                && rows >= 1.0
                && cols.fract() == 0.0
                && rows.fract() == 0.0
                && cols < 1e6
                && rows < 1e6
            {
                h.grid = Some((cols as usize, rows as usize));
            }
        } else if c.starts_with("Width") {
            if let (Some(w), Some(hh)) = (nums_after(c, "Width"), nums_after(c, "Height"))
                && w > 0.0
                && hh > 0.0
            {
                h.canvas = Some((w, hh));
            }
        } else if c.starts_with("Routes per micron") {
            if let (Some(a), Some(b)) = (nums_after(c, "hor"), nums_after(c, "ver")) {
                h.routes_per_micron = Some((a, b));
            }
        } else if c.starts_with("Routes used by macros") {
            if let (Some(a), Some(b)) = (nums_after(c, "hor"), nums_after(c, "ver")) {
                h.macro_routing_alloc = Some((a, b));
            }
        } else if c.starts_with("Smoothing factor") {
            h.smooth_range = nums_after(c, "Smoothing factor");
        } else if c.starts_with("Overlap threshold") {
            h.overlap_threshold = nums_after(c, "Overlap threshold");
        } else if let Some(rest) = c.strip_prefix("Blockage") {
            let v: Vec<f64> = rest
                .trim_start()
                .trim_start_matches(':')
                .split_whitespace()
                .filter_map(|t| t.parse().ok())
                .collect();
            if v.len() == 5 && v.iter().all(|x| x.is_finite()) {
                h.blockages.push(Blockage {
                    rect: [v[0], v[1], v[2], v[3], v[4]],
                });
            }
        } else if let Some(rest) = c.strip_prefix("Block")
            && let Some(name) = rest.trim_start().strip_prefix(':')
        {
            let name = name.trim();
            if !name.is_empty() {
                h.block = Some(name.to_string());
            }
        }
    }
    h
}

impl Placement {
    /// Reads a `.plc` file.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, PlcError> {
        let path = path.as_ref();
        let shown = path.display().to_string();
        let text = crate::netlist::read_maybe_gz(path).map_err(|source| PlcError::Io {
            path: shown.clone(),
            source,
        })?;
        Self::parse_named(&text, &shown)
    }

    /// Parses `.plc` text.
    ///
    /// ```
    /// use a2perf_circuit::Placement;
    /// let p = Placement::parse("# Columns : 2  Rows : 3\n0 1.5 2 N 0\n1 0 0 - 1\n").unwrap();
    /// assert_eq!(p.header.grid, Some((2, 3)));
    /// assert_eq!(p.entries.len(), 2);
    /// assert_eq!(Placement::parse(&p.to_text()).unwrap(), p);
    /// assert!(Placement::parse("0 1.5 x N 0").unwrap_err().to_string().contains(":1:"));
    /// ```
    pub fn parse(text: &str) -> Result<Self, PlcError> {
        Self::parse_named(text, "<text>")
    }

    fn parse_named(text: &str, source: &str) -> Result<Self, PlcError> {
        let mut comments = Vec::new();
        let mut entries = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let err = |reason: String| PlcError::Syntax {
                path: source.to_string(),
                line,
                reason,
            };
            let t = raw.trim();
            if let Some(c) = raw.trim_start().strip_prefix('#') {
                comments.push(c.strip_prefix(' ').unwrap_or(c).to_string());
                continue;
            }
            if t.is_empty() {
                continue;
            }
            let f: Vec<&str> = t.split_whitespace().collect();
            if f.len() < 3 || f.len() > 5 {
                return Err(err(format!(
                    "expected `node_index x y [orientation [fixed]]`, found {} fields",
                    f.len()
                )));
            }
            let index: usize = f[0]
                .parse()
                .map_err(|_| err(format!("`{}` is not a node index", f[0])))?;
            let num = |s: &str| {
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| err(format!("`{s}` is not a finite number")))
            };
            let x = num(f[1])?;
            let y = num(f[2])?;
            let orientation = match f.get(3) {
                None | Some(&"-") => None,
                Some(o) => Some(
                    Orientation::parse(o)
                        .ok_or_else(|| err(format!("unknown orientation `{o}`")))?,
                ),
            };
            let fixed = match f.get(4) {
                None | Some(&"0") => false,
                Some(&"1") => true,
                Some(o) => return Err(err(format!("fixed flag must be 0 or 1, found `{o}`"))),
            };
            entries.push(PlcEntry {
                index,
                x,
                y,
                orientation,
                fixed,
            });
        }
        let header = parse_header(&comments);
        Ok(Self {
            comments,
            header,
            entries,
        })
    }

    /// Writes the placement: comments, then one line per entry (coordinates in shortest
    /// round-trip form, so writing and reading back gives an identical placement).
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        for c in &self.comments {
            let _ = writeln!(s, "# {c}");
        }
        for e in &self.entries {
            let _ = writeln!(
                s,
                "{} {:?} {:?} {} {}",
                e.index,
                e.x,
                e.y,
                e.orientation.map_or("-", Orientation::as_str),
                u8::from(e.fixed)
            );
        }
        s
    }
}

//! The paper's findings as data: each claim carries a definition over table cells (sums,
//! comparisons, ratios with a bound, overlap within error bars), evaluated the same way on the
//! paper's figures and on a report's runs, so that a new paper's claims need no code.
//!
//! ```
//! use a2perf_pipeline::report::paper::findings::{Condition, Expr};
//! let c: Condition = serde_json::from_str(
//!     r#"{"less": [{"sum": [{"cell": "web/ppo/inference_time"}, {"const": 68}]}, {"const": 273}]}"#,
//! ).unwrap();
//! let Condition::Less([Expr::Sum(parts), Expr::Const(limit)]) = &c else { panic!("{c:?}") };
//! assert_eq!((parts.len(), *limit), (2, 273.0));
//! ```

use serde::{Deserialize, Serialize};

use super::super::format::{format_ratio, format_value};

/// One finding of the paper: the claim, and when it holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FindingDef {
    /// Short id (`F1`).
    pub id: String,
    /// The claim as the paper makes it.
    pub claim: String,
    /// The definition over cells that decides whether it holds.
    pub holds_when: Condition,
    /// How a loose word of the claim ("far more", "≈ 5×") is judged, or other remarks.
    #[serde(default)]
    pub note: Option<String>,
}

/// A checkable statement about cells.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Condition {
    /// Every condition holds.
    All(Vec<Condition>),
    /// At least one condition holds.
    Any(Vec<Condition>),
    /// The first value is below the second (the factor between them is reported, not judged).
    Less([Expr; 2]),
    /// The first value is above the second (the factor between them is reported, not judged).
    Greater([Expr; 2]),
    /// Two cells' error bars overlap: |a − b| ≤ std(a) + std(b).
    Overlap([Expr; 2]),
    /// The ratio of two values lies within the given bounds.
    Ratio(RatioBound),
}

/// `of[0] / of[1]` with at least one bound.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RatioBound {
    /// Numerator and denominator.
    pub of: [Expr; 2],
    /// The ratio must be at most this.
    #[serde(default)]
    pub at_most: Option<f64>,
    /// The ratio must be at least this.
    #[serde(default)]
    pub at_least: Option<f64>,
}

/// A number: a cell's mean, a sum, or a constant (in the cell's metric unit of our report:
/// kWh, W, GB, Hours, ms).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Expr {
    /// `task/algorithm/metric`: the mean of that cell (its paper task id, our algorithm name,
    /// our metric key).
    Cell(String),
    /// The sum of the values.
    Sum(Vec<Expr>),
    /// A constant.
    Const(f64),
}

/// A cell address, parsed from `task/algorithm/metric`.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct CellRef {
    /// Paper task id.
    pub task: String,
    /// Algorithm (our registered name).
    pub algorithm: String,
    /// Metric key.
    pub metric: String,
}

impl std::fmt::Display for CellRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}/{}", self.task, self.algorithm, self.metric)
    }
}

impl CellRef {
    /// Parses `task/algorithm/metric`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let parts: Vec<&str> = text.split('/').collect();
        match parts.as_slice() {
            [t, a, m] if !t.is_empty() && !a.is_empty() && !m.is_empty() => Ok(Self {
                task: (*t).into(),
                algorithm: (*a).into(),
                metric: (*m).into(),
            }),
            _ => Err(format!(
                "cell `{text}` is not of the form `task/algorithm/metric`"
            )),
        }
    }
}

/// A cell's value on one side (the paper's or ours).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellValue {
    /// Mean.
    pub mean: f64,
    /// Spread, when there is one.
    pub std: Option<f64>,
}

/// Where a finding's cells are looked up: the paper's tables or a report's runs. `Err` says why
/// the cell is missing.
pub trait CellSource {
    /// The value of `cell`.
    fn value(&self, cell: &CellRef) -> Result<CellValue, String>;
    /// The unit its values are in (empty for unitless metrics), for the text.
    fn unit(&self, cell: &CellRef) -> String;
}

/// A definition evaluated on one side.
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation {
    /// Whether it holds; `None` when a needed cell is missing.
    pub holds: Option<bool>,
    /// The numbers, as text (`48.28 + 0.11 = 48.39 < 108.20 kWh (×2.24)`).
    pub text: String,
    /// Why cells are missing.
    pub missing: Vec<String>,
}

impl FindingDef {
    /// Every cell the definition reads.
    pub fn cells(&self) -> Result<Vec<CellRef>, String> {
        let mut out = Vec::new();
        self.holds_when.cells(&mut out)?;
        Ok(out)
    }

    /// Structural rules: parsable cells, non-empty lists, bounded ratios, overlaps of cells.
    pub fn check(&self) -> Result<(), String> {
        if self.id.trim().is_empty() {
            return Err("finding with an empty `id`".into());
        }
        self.holds_when
            .check()
            .map_err(|why| format!("finding `{}`: {why}", self.id))
    }

    /// Evaluates the definition on `side`.
    pub fn evaluate(&self, side: &dyn CellSource) -> Evaluation {
        let mut missing = Vec::new();
        let (holds, text) = self.holds_when.eval(side, &mut missing);
        // A cell read twice (F1's sum is on both sides of two comparisons) is named once.
        let mut seen = std::collections::BTreeSet::new();
        missing.retain(|m| seen.insert(m.clone()));
        Evaluation {
            holds,
            text,
            missing,
        }
    }
}

impl Condition {
    fn cells(&self, out: &mut Vec<CellRef>) -> Result<(), String> {
        match self {
            Condition::All(cs) | Condition::Any(cs) => {
                for c in cs {
                    c.cells(out)?;
                }
            }
            Condition::Less(pair) | Condition::Greater(pair) | Condition::Overlap(pair) => {
                for e in pair {
                    e.cells(out)?;
                }
            }
            Condition::Ratio(r) => {
                for e in &r.of {
                    e.cells(out)?;
                }
            }
        }
        Ok(())
    }

    fn check(&self) -> Result<(), String> {
        match self {
            Condition::All(cs) | Condition::Any(cs) => {
                if cs.is_empty() {
                    return Err("`all`/`any` needs at least one condition".into());
                }
                cs.iter().try_for_each(Condition::check)
            }
            Condition::Less(pair) | Condition::Greater(pair) => {
                pair.iter().try_for_each(Expr::check)
            }
            Condition::Overlap(pair) => {
                if pair.iter().any(|e| !matches!(e, Expr::Cell(_))) {
                    return Err("`overlap` compares two cells (it needs their spreads)".into());
                }
                pair.iter().try_for_each(Expr::check)
            }
            Condition::Ratio(r) => {
                let bounds = [r.at_most, r.at_least];
                if bounds.iter().all(Option::is_none) {
                    return Err("`ratio` needs `at_most` or `at_least`".into());
                }
                if bounds.iter().flatten().any(|b| !b.is_finite()) {
                    return Err("a `ratio` bound is not a finite number".into());
                }
                r.of.iter().try_for_each(Expr::check)
            }
        }
    }

    fn eval(&self, side: &dyn CellSource, missing: &mut Vec<String>) -> (Option<bool>, String) {
        match self {
            Condition::All(cs) | Condition::Any(cs) => {
                let parts: Vec<(Option<bool>, String)> =
                    cs.iter().map(|c| c.eval(side, missing)).collect();
                let any = matches!(self, Condition::Any(_));
                // One true part settles `any`, one false part settles `all`, whatever else is
                // missing.
                let settling = any;
                let holds = if parts.iter().any(|(h, _)| *h == Some(settling)) {
                    Some(settling)
                } else if parts.iter().any(|(h, _)| h.is_none()) {
                    None
                } else {
                    Some(!settling)
                };
                let sep = if any { " or " } else { "; " };
                let text = parts
                    .into_iter()
                    .map(|(_, t)| t)
                    .collect::<Vec<_>>()
                    .join(sep);
                (holds, text)
            }
            Condition::Less([a, b]) | Condition::Greater([a, b]) => {
                let (va, ta) = a.eval(side, missing);
                let (vb, tb) = b.eval(side, missing);
                let unit = unit_suffix(self, side);
                match (va, vb) {
                    (Some(x), Some(y)) => {
                        let want_less = matches!(self, Condition::Less(_));
                        let holds = if want_less { x < y } else { x > y };
                        let op = if x < y {
                            "<"
                        } else if x > y {
                            ">"
                        } else {
                            "="
                        };
                        let (lo, hi) = (x.abs().min(y.abs()), x.abs().max(y.abs()));
                        let factor = if lo > 0.0 {
                            format!(" (×{})", format_ratio(hi / lo))
                        } else {
                            String::new()
                        };
                        (Some(holds), format!("{ta} {op} {tb}{unit}{factor}"))
                    }
                    _ => (None, format!("{ta} vs {tb}{unit}")),
                }
            }
            Condition::Overlap([a, b]) => {
                let cell = |e: &Expr| match e {
                    Expr::Cell(c) => CellRef::parse(c).ok(),
                    _ => None,
                };
                let value = |e: &Expr, missing: &mut Vec<String>| {
                    let c = cell(e)?;
                    match side.value(&c) {
                        Ok(v) if v.std.is_some() => Some(v),
                        Ok(_) => {
                            missing.push(format!("{c}: no spread (± std)"));
                            None
                        }
                        Err(why) => {
                            missing.push(format!("{c}: {why}"));
                            None
                        }
                    }
                };
                let (va, vb) = (value(a, missing), value(b, missing));
                let show = |v: Option<CellValue>| match v {
                    Some(CellValue { mean, std: Some(s) }) => {
                        format!("{} ± {}", format_value(mean), format_value(s))
                    }
                    Some(v) => format_value(v.mean),
                    None => "—".into(),
                };
                match (va, vb) {
                    (
                        Some(CellValue {
                            mean: ma,
                            std: Some(sa),
                        }),
                        Some(CellValue {
                            mean: mb,
                            std: Some(sb),
                        }),
                    ) => {
                        let gap = (ma - mb).abs();
                        let holds = gap <= sa + sb;
                        let op = if holds { "≤" } else { ">" };
                        (
                            Some(holds),
                            format!(
                                "{} vs {}: gap {} {op} {}",
                                show(va),
                                show(vb),
                                format_value(gap),
                                format_value(sa + sb)
                            ),
                        )
                    }
                    _ => (None, format!("{} vs {}", show(va), show(vb))),
                }
            }
            Condition::Ratio(r) => {
                let (va, ta) = r.of[0].eval(side, missing);
                let (vb, tb) = r.of[1].eval(side, missing);
                let bound = |holds_most: bool, holds_least: bool| {
                    let mut parts = Vec::new();
                    if let Some(m) = r.at_most {
                        let op = if holds_most { "≤" } else { ">" };
                        parts.push(format!("{op} {}", format_value(m)));
                    }
                    if let Some(l) = r.at_least {
                        let op = if holds_least { "≥" } else { "<" };
                        parts.push(format!("{op} {}", format_value(l)));
                    }
                    parts.join(", ")
                };
                match (va, vb) {
                    (Some(x), Some(y)) if y != 0.0 => {
                        let q = x / y;
                        let most = r.at_most.is_none_or(|m| q <= m);
                        let least = r.at_least.is_none_or(|l| q >= l);
                        (
                            Some(most && least),
                            format!("{ta} / {tb} = {} {}", format_ratio(q), bound(most, least)),
                        )
                    }
                    (Some(_), Some(_)) => {
                        missing.push("ratio with a zero denominator".into());
                        (None, format!("{ta} / {tb}"))
                    }
                    _ => (None, format!("{ta} / {tb}")),
                }
            }
        }
    }
}

/// ` kWh` when the comparison's cells have a physical unit.
fn unit_suffix(c: &Condition, side: &dyn CellSource) -> String {
    let mut cells = Vec::new();
    if c.cells(&mut cells).is_err() {
        return String::new();
    }
    cells
        .iter()
        .map(|cell| side.unit(cell))
        .find(|u| !u.is_empty())
        .map(|u| format!(" {u}"))
        .unwrap_or_default()
}

impl Expr {
    fn cells(&self, out: &mut Vec<CellRef>) -> Result<(), String> {
        match self {
            Expr::Cell(c) => out.push(CellRef::parse(c)?),
            Expr::Sum(es) => {
                for e in es {
                    e.cells(out)?;
                }
            }
            Expr::Const(_) => {}
        }
        Ok(())
    }

    fn check(&self) -> Result<(), String> {
        match self {
            Expr::Cell(c) => CellRef::parse(c).map(|_| ()),
            Expr::Sum(es) if es.is_empty() => Err("`sum` of nothing".into()),
            Expr::Sum(es) => es.iter().try_for_each(Expr::check),
            Expr::Const(v) if !v.is_finite() => Err("a `const` is not a finite number".into()),
            Expr::Const(_) => Ok(()),
        }
    }

    fn eval(&self, side: &dyn CellSource, missing: &mut Vec<String>) -> (Option<f64>, String) {
        match self {
            Expr::Const(v) => (Some(*v), format_value(*v)),
            Expr::Cell(c) => {
                let cell = match CellRef::parse(c) {
                    Ok(cell) => cell,
                    Err(why) => {
                        missing.push(why);
                        return (None, "—".into());
                    }
                };
                match side.value(&cell) {
                    Ok(v) => (Some(v.mean), format_value(v.mean)),
                    Err(why) => {
                        missing.push(format!("{cell}: {why}"));
                        (None, "—".into())
                    }
                }
            }
            Expr::Sum(es) => {
                let parts: Vec<(Option<f64>, String)> =
                    es.iter().map(|e| e.eval(side, missing)).collect();
                let text = parts
                    .iter()
                    .map(|(_, t)| t.as_str())
                    .collect::<Vec<_>>()
                    .join(" + ");
                let total: Option<f64> = parts.iter().map(|(v, _)| *v).sum();
                match total {
                    Some(t) if es.len() > 1 => (Some(t), format!("{text} = {}", format_value(t))),
                    Some(t) => (Some(t), text),
                    None => (None, text),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    struct Table(BTreeMap<String, CellValue>);

    impl CellSource for Table {
        fn value(&self, cell: &CellRef) -> Result<CellValue, String> {
            self.0
                .get(&cell.to_string())
                .copied()
                .ok_or_else(|| "not run".into())
        }
        fn unit(&self, cell: &CellRef) -> String {
            if cell.metric == "energy" {
                "kWh".into()
            } else {
                String::new()
            }
        }
    }

    fn table(cells: &[(&str, f64, Option<f64>)]) -> Table {
        Table(
            cells
                .iter()
                .map(|(k, mean, std)| {
                    (
                        (*k).to_string(),
                        CellValue {
                            mean: *mean,
                            std: *std,
                        },
                    )
                })
                .collect(),
        )
    }

    fn finding(json: &str) -> FindingDef {
        let def: FindingDef = serde_json::from_str(json).unwrap();
        def.check().unwrap();
        def
    }

    #[test]
    fn sums_comparisons_and_factors() {
        let f = finding(
            r#"{"id": "F1", "claim": "c", "holds_when": {"all": [
                {"less": [{"sum": [{"cell": "t/bc/cost"}, {"cell": "t/bc/energy"}]}, {"cell": "t/ppo/energy"}]},
                {"greater": [{"cell": "t/ppo/energy"}, {"const": 100}]}]}}"#,
        );
        let paper = table(&[
            ("t/bc/cost", 48.28, None),
            ("t/bc/energy", 0.11, None),
            ("t/ppo/energy", 120.53, None),
        ]);
        let e = f.evaluate(&paper);
        assert_eq!(e.holds, Some(true));
        assert_eq!(
            e.text,
            "48.28 + 0.11 = 48.39 < 120.53 kWh (×2.49); 120.53 > 100.00 kWh (×1.21)"
        );
        let ours = table(&[
            ("t/bc/cost", 200.0, None),
            ("t/bc/energy", 1.0, None),
            ("t/ppo/energy", 120.0, None),
        ]);
        let e = f.evaluate(&ours);
        assert_eq!(e.holds, Some(false));
        assert!(
            e.text.starts_with("200.00 + 1.00 = 201.00 > 120.00 kWh"),
            "{}",
            e.text
        );
    }

    #[test]
    fn a_missing_cell_leaves_the_outcome_open_unless_another_part_decides_it() {
        let all = finding(
            r#"{"id": "F", "claim": "c", "holds_when": {"all": [
                {"less": [{"cell": "t/a/x"}, {"cell": "t/b/x"}]},
                {"less": [{"cell": "t/a/y"}, {"cell": "t/b/y"}]}]}}"#,
        );
        let partial = table(&[("t/a/x", 1.0, None), ("t/b/x", 2.0, None)]);
        let e = all.evaluate(&partial);
        assert_eq!(e.holds, None);
        assert_eq!(e.missing, ["t/a/y: not run", "t/b/y: not run"]);
        let twice = finding(
            r#"{"id": "F", "claim": "c", "holds_when": {"all": [
                {"less": [{"cell": "t/a/y"}, {"cell": "t/b/x"}]},
                {"greater": [{"cell": "t/a/y"}, {"cell": "t/a/x"}]}]}}"#,
        );
        assert_eq!(twice.evaluate(&partial).missing, ["t/a/y: not run"]);
        assert!(e.text.ends_with("— vs —"), "{}", e.text);
        let failing = table(&[("t/a/x", 3.0, None), ("t/b/x", 2.0, None)]);
        assert_eq!(all.evaluate(&failing).holds, Some(false));

        let any = finding(
            r#"{"id": "F", "claim": "c", "holds_when": {"any": [
                {"less": [{"cell": "t/a/x"}, {"cell": "t/b/x"}]},
                {"less": [{"cell": "t/a/y"}, {"cell": "t/b/y"}]}]}}"#,
        );
        assert_eq!(any.evaluate(&partial).holds, Some(true));
        assert_eq!(any.evaluate(&failing).holds, None);
    }

    #[test]
    fn overlap_uses_both_spreads_and_ratio_its_bounds() {
        let f = finding(
            r#"{"id": "F7", "claim": "c", "holds_when": {"overlap": [{"cell": "t/a/r"}, {"cell": "t/b/r"}]}}"#,
        );
        let e = f.evaluate(&table(&[
            ("t/a/r", 9.94, Some(15.59)),
            ("t/b/r", 6.96, Some(6.72)),
        ]));
        assert_eq!(e.holds, Some(true));
        assert_eq!(e.text, "9.94 ± 15.59 vs 6.96 ± 6.72: gap 2.98 ≤ 22.31");
        let e = f.evaluate(&table(&[
            ("t/a/r", -0.99, Some(0.01)),
            ("t/b/r", -1.1, Some(0.04)),
        ]));
        assert_eq!(e.holds, Some(false));
        let e = f.evaluate(&table(&[("t/a/r", 1.0, None), ("t/b/r", 1.0, Some(0.1))]));
        assert_eq!(e.holds, None);
        assert_eq!(e.missing, ["t/a/r: no spread (± std)"]);

        let r = finding(
            r#"{"id": "F4", "claim": "c", "holds_when": {"ratio": {"of": [{"cell": "t/a/p"}, {"cell": "t/a/q"}], "at_least": 10}}}"#,
        );
        let e = r.evaluate(&table(&[("t/a/p", 2305.57, None), ("t/a/q", 2.19, None)]));
        assert_eq!(
            (e.holds, e.text.as_str()),
            (Some(true), "2305.57 / 2.19 = 1.05e3 ≥ 10.00")
        );
        let e = r.evaluate(&table(&[("t/a/p", 0.5, None), ("t/a/q", 0.25, None)]));
        assert_eq!(
            (e.holds, e.text.as_str()),
            (Some(false), "0.50 / 0.25 = 2.00 < 10.00")
        );
    }

    #[test]
    fn malformed_definitions_are_refused() {
        for (json, want) in [
            (
                r#"{"id": "F", "claim": "c", "holds_when": {"less": [{"cell": "t/a"}, {"const": 1}]}}"#,
                "cell `t/a` is not of the form `task/algorithm/metric`",
            ),
            (
                r#"{"id": "F", "claim": "c", "holds_when": {"all": []}}"#,
                "needs at least one condition",
            ),
            (
                r#"{"id": "F", "claim": "c", "holds_when": {"overlap": [{"const": 1}, {"cell": "t/a/x"}]}}"#,
                "`overlap` compares two cells",
            ),
            (
                r#"{"id": "F", "claim": "c", "holds_when": {"ratio": {"of": [{"const": 1}, {"cell": "t/a/x"}]}}}"#,
                "`ratio` needs `at_most` or `at_least`",
            ),
        ] {
            let def: FindingDef = serde_json::from_str(json).unwrap();
            let err = def.check().unwrap_err();
            assert!(
                err.starts_with("finding `F`: ") && err.contains(want),
                "{err}"
            );
        }
    }
}

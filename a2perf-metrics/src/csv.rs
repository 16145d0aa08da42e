//! Reading your own logs: small CSV formats with errors that name the file and line.
//!
//! - curves: header `run,step,value`, one evaluation per line (any run order; steps are sorted
//!   per run, duplicates rejected);
//! - rollouts: header `return`, one episode return per line;
//! - scores: header `algorithm,task,run,score` (rliable layout: each algorithm needs a score for
//!   every (task, run) pair it has, with the same runs for every task).
//!
//! Fields are separated by commas and trimmed; quoting is not supported (names must not contain
//! commas). Blank lines are ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::curve::Curve;
use crate::rliable::Scores;

/// A problem with an input file.
#[derive(Debug, Error)]
pub enum CsvError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The header is missing or different.
    #[error("{path}:{line}: expected header `{expected}`, found `{found}`")]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The required header.
        expected: &'static str,
        /// What the file has.
        found: String,
    },
    /// A data line is malformed.
    #[error("{path}:{line}: {message}")]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The file parsed but its content is unusable as a whole.
    #[error("{path}: {message}")]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// Learning curves read from a file, in order of first appearance of each run id.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedCurves {
    /// `(run id, curve)`.
    pub runs: Vec<(String, Curve)>,
}

impl NamedCurves {
    /// Just the curves.
    pub fn curves(&self) -> Vec<Curve> {
        self.runs.iter().map(|(_, c)| c.clone()).collect()
    }
}

/// Scores per algorithm, read from a file.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedScores {
    /// Task names (columns), in order of first appearance.
    pub tasks: Vec<String>,
    /// `(algorithm, runs × tasks scores)` in order of first appearance.
    pub algorithms: Vec<(String, Scores)>,
}

fn read(path: &Path) -> Result<String, CsvError> {
    std::fs::read_to_string(path).map_err(|source| CsvError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Non-blank lines with 1-based numbers; checks the header.
fn data_lines<'a>(
    path: &Path,
    text: &'a str,
    expected: &'static str,
) -> Result<Vec<(usize, Vec<&'a str>)>, CsvError> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty());
    let want: Vec<&str> = expected.split(',').collect();
    match lines.next() {
        Some((n, h)) => {
            let fields: Vec<&str> = h
                .trim_start_matches('\u{feff}')
                .split(',')
                .map(str::trim)
                .collect();
            if fields != want {
                return Err(CsvError::Header {
                    path: path.to_path_buf(),
                    line: n,
                    expected,
                    found: h.to_string(),
                });
            }
        }
        None => {
            return Err(CsvError::Header {
                path: path.to_path_buf(),
                line: 1,
                expected,
                found: String::new(),
            });
        }
    }
    lines
        .map(|(n, l)| {
            let fields: Vec<&str> = l.split(',').map(str::trim).collect();
            if fields.len() != want.len() {
                Err(CsvError::Line {
                    path: path.to_path_buf(),
                    line: n,
                    message: format!(
                        "expected {} fields ({expected}), found {}",
                        want.len(),
                        fields.len()
                    ),
                })
            } else {
                Ok((n, fields))
            }
        })
        .collect()
}

fn number(path: &Path, line: usize, what: &str, s: &str) -> Result<f64, CsvError> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(CsvError::Line {
            path: path.to_path_buf(),
            line,
            message: format!("{what} `{s}` is not finite"),
        }),
        Err(_) => Err(CsvError::Line {
            path: path.to_path_buf(),
            line,
            message: format!("{what} `{s}` is not a number"),
        }),
    }
}

/// Reads curves from a `run,step,value` file.
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let p = dir.path().join("c.csv");
/// std::fs::write(&p, "run,step,value\na,0,1\na,1,2\nb,0,3\n").unwrap();
/// let c = a2perf_metrics::csv::read_curves(&p).unwrap();
/// assert_eq!(c.runs.len(), 2);
/// std::fs::write(&p, "run,step,value\na,0,x\n").unwrap();
/// let err = a2perf_metrics::csv::read_curves(&p).unwrap_err().to_string();
/// assert!(err.contains(":2:"), "{err}");
/// ```
pub fn read_curves(path: &Path) -> Result<NamedCurves, CsvError> {
    let text = read(path)?;
    parse_curves(path, &text)
}

/// [`read_curves`] on text already in memory (`path` is only used in messages).
pub fn parse_curves(path: &Path, text: &str) -> Result<NamedCurves, CsvError> {
    let mut rows = Vec::new();
    for (n, f) in data_lines(path, text, "run,step,value")? {
        let step = number(path, n, "step", f[1])?;
        let value = number(path, n, "value", f[2])?;
        rows.push((n, f[0], step, value));
    }
    curves_from_records(path, rows)
}

/// Groups `(line, run, step, value)` records into curves by the rules of [`read_curves`]: runs in
/// order of first appearance, steps sorted per run, a step given twice for a run rejected. Used for
/// data that is not a file (a table in memory); `path` and `line` only name records in messages.
///
/// ```
/// use std::path::Path;
/// let c = a2perf_metrics::csv::curves_from_records(
///     Path::new("table"),
///     [(0, "a", 1.0, 5.0), (1, "a", 0.0, 4.0), (2, "b", 0.0, 1.0)],
/// )
/// .unwrap();
/// assert_eq!(c.runs[0].1.steps(), &[0.0, 1.0]);
/// let err = a2perf_metrics::csv::curves_from_records(Path::new("table"), [(7, "a", 0.0, f64::NAN)]);
/// assert!(err.unwrap_err().to_string().starts_with("table:7:"));
/// ```
pub fn curves_from_records<'a>(
    path: &Path,
    records: impl IntoIterator<Item = (usize, &'a str, f64, f64)>,
) -> Result<NamedCurves, CsvError> {
    let mut order: Vec<String> = Vec::new();
    let mut points: BTreeMap<String, Vec<(f64, f64, usize)>> = BTreeMap::new();
    for (n, run, step, value) in records {
        if run.is_empty() {
            return Err(CsvError::Line {
                path: path.to_path_buf(),
                line: n,
                message: "empty run id".into(),
            });
        }
        for (what, v) in [("step", step), ("value", value)] {
            if !v.is_finite() {
                return Err(CsvError::Line {
                    path: path.to_path_buf(),
                    line: n,
                    message: format!("{what} `{v}` is not finite"),
                });
            }
        }
        let entry = points.entry(run.to_string()).or_insert_with(|| {
            order.push(run.to_string());
            Vec::new()
        });
        entry.push((step, value, n));
    }
    if order.is_empty() {
        return Err(CsvError::Content {
            path: path.to_path_buf(),
            message: "no data lines".into(),
        });
    }
    let mut runs = Vec::with_capacity(order.len());
    for id in order {
        let mut pts = points.remove(&id).unwrap_or_default();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        if let Some(w) = pts.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(CsvError::Line {
                path: path.to_path_buf(),
                line: w[0].2.max(w[1].2),
                message: format!(
                    "run `{id}` has step {} twice (also on line {})",
                    w[1].0,
                    w[0].2.min(w[1].2)
                ),
            });
        }
        let (steps, values): (Vec<f64>, Vec<f64>) = pts.iter().map(|p| (p.0, p.1)).unzip();
        let curve = Curve::new(steps, values).map_err(|e| CsvError::Content {
            path: path.to_path_buf(),
            message: format!("run `{id}`: {e}"),
        })?;
        runs.push((id, curve));
    }
    Ok(NamedCurves { runs })
}

/// Reads episode returns from a `return` file.
pub fn read_rollouts(path: &Path) -> Result<Vec<f64>, CsvError> {
    let text = read(path)?;
    parse_rollouts(path, &text)
}

/// [`read_rollouts`] on text already in memory.
pub fn parse_rollouts(path: &Path, text: &str) -> Result<Vec<f64>, CsvError> {
    let out: Vec<f64> = data_lines(path, text, "return")?
        .into_iter()
        .map(|(n, f)| number(path, n, "return", f[0]))
        .collect::<Result<_, _>>()?;
    if out.is_empty() {
        return Err(CsvError::Content {
            path: path.to_path_buf(),
            message: "no returns".into(),
        });
    }
    Ok(out)
}

/// Reads rliable scores from an `algorithm,task,run,score` file.
pub fn read_scores(path: &Path) -> Result<NamedScores, CsvError> {
    let text = read(path)?;
    parse_scores(path, &text)
}

/// [`read_scores`] on text already in memory.
pub fn parse_scores(path: &Path, text: &str) -> Result<NamedScores, CsvError> {
    let mut rows = Vec::new();
    for (n, f) in data_lines(path, text, "algorithm,task,run,score")? {
        let score = number(path, n, "score", f[3])?;
        rows.push((n, f[0], f[1], f[2], score));
    }
    scores_from_records(path, rows)
}

/// Groups `(line, algorithm, task, run, score)` records by the rules of [`read_scores`]. Used for
/// data that is not a file; `path` and `line` only name records in messages.
///
/// ```
/// use std::path::Path;
/// let s = a2perf_metrics::csv::scores_from_records(
///     Path::new("table"),
///     [(0, "A", "t", "0", 1.0), (1, "A", "t", "1", 2.0)],
/// )
/// .unwrap();
/// assert_eq!(s.algorithms[0].1.runs(), 2);
/// ```
pub fn scores_from_records<'a>(
    path: &Path,
    records: impl IntoIterator<Item = (usize, &'a str, &'a str, &'a str, f64)>,
) -> Result<NamedScores, CsvError> {
    let mut tasks: Vec<String> = Vec::new();
    let mut algos: Vec<String> = Vec::new();
    // (algo, task, run) → (score, line)
    let mut cells: BTreeMap<(String, String, String), (f64, usize)> = BTreeMap::new();
    let mut runs_of: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (n, algo, task, run, score) in records {
        let f = [algo, task, run];
        if !score.is_finite() {
            return Err(CsvError::Line {
                path: path.to_path_buf(),
                line: n,
                message: format!("score `{score}` is not finite"),
            });
        }
        if f[0].is_empty() || f[1].is_empty() || f[2].is_empty() {
            return Err(CsvError::Line {
                path: path.to_path_buf(),
                line: n,
                message: "empty algorithm, task or run".into(),
            });
        }
        if !tasks.iter().any(|t| t == f[1]) {
            tasks.push(f[1].to_string());
        }
        if !algos.iter().any(|a| a == f[0]) {
            algos.push(f[0].to_string());
        }
        let runs = runs_of.entry(f[0].to_string()).or_default();
        if !runs.iter().any(|r| r == f[2]) {
            runs.push(f[2].to_string());
        }
        let key = (f[0].to_string(), f[1].to_string(), f[2].to_string());
        if let Some((_, first)) = cells.get(&key) {
            return Err(CsvError::Line {
                path: path.to_path_buf(),
                line: n,
                message: format!(
                    "duplicate score for algorithm `{}`, task `{}`, run `{}` (first on line {first})",
                    f[0], f[1], f[2]
                ),
            });
        }
        cells.insert(key, (score, n));
    }
    if algos.is_empty() {
        return Err(CsvError::Content {
            path: path.to_path_buf(),
            message: "no scores".into(),
        });
    }
    let mut algorithms = Vec::with_capacity(algos.len());
    for a in algos {
        let runs = runs_of.remove(&a).unwrap_or_default();
        let mut data = Vec::with_capacity(runs.len() * tasks.len());
        for r in &runs {
            for t in &tasks {
                match cells.get(&(a.clone(), t.clone(), r.clone())) {
                    Some((v, _)) => data.push(*v),
                    None => {
                        return Err(CsvError::Content {
                            path: path.to_path_buf(),
                            message: format!(
                                "algorithm `{a}` has no score for task `{t}`, run `{r}`"
                            ),
                        });
                    }
                }
            }
        }
        let scores = Scores::new(runs.len(), tasks.len(), data).map_err(|e| CsvError::Content {
            path: path.to_path_buf(),
            message: format!("algorithm `{a}`: {e}"),
        })?;
        algorithms.push((a, scores));
    }
    Ok(NamedScores { tasks, algorithms })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("x.csv")
    }

    #[test]
    fn curves_are_grouped_and_sorted() {
        let c = parse_curves(p(), "run,step,value\nb,2,1\na,1,5\nb,1,0\n\n").unwrap();
        assert_eq!(c.runs[0].0, "b");
        assert_eq!(c.runs[0].1.steps(), &[1.0, 2.0]);
        assert_eq!(c.runs[1].1.values(), &[5.0]);
    }

    #[test]
    fn errors_name_file_and_line() {
        let e = parse_curves(p(), "run,step\n").unwrap_err().to_string();
        assert!(e.starts_with("x.csv:1:"), "{e}");
        let e = parse_curves(p(), "run,step,value\na,1,2\na,1,3\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:3:"), "{e}");
        let e = parse_curves(p(), "run,step,value\na,1,inf\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains(":2:") && e.contains("finite"), "{e}");
        let e = parse_rollouts(p(), "return\n1\n\n2,3\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:4:"), "{e}");
        let e = parse_scores(p(), "algorithm,task,run,score\nA,t1,0,1\nA,t2,1,1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no score for task"), "{e}");
    }

    #[test]
    fn scores_layout() {
        let s = parse_scores(
            p(),
            "algorithm,task,run,score\nA,t1,0,1\nA,t2,0,2\nA,t1,1,3\nA,t2,1,4\nB,t1,0,5\nB,t2,0,6\n",
        )
        .unwrap();
        assert_eq!(s.tasks, vec!["t1", "t2"]);
        let a = &s.algorithms[0].1;
        assert_eq!((a.runs(), a.tasks()), (2, 2));
        assert_eq!(a.get(1, 1), 4.0);
        assert_eq!(s.algorithms[1].1.runs(), 1);
    }
}

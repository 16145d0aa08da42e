//! Website designs (primitives per page), A2Perf's difficulty formula and level bins.

use std::path::Path;

use serde::Deserialize;

use crate::error::WebError;
use crate::primitives::{NEXT_PAGE, Primitive, STOP};

/// A website design: the primitives of each page, in insertion order (duplicates allowed, as the
/// original sampler produces them).
///
/// ```
/// use a2perf_web::{Design, Primitive};
/// let p = |n| Primitive::from_name(n).unwrap();
/// let d = Design { pages: vec![vec![p("username"), p("password"), p("submit")]] };
/// // Two active primitives on one page, no distractor-weighted DOM is removed:
/// // −ln(1/2! · (1 − 12/44)) ≈ 1.0116.
/// assert!((d.difficulty() - 1.0116).abs() < 1e-3);
/// assert_eq!(d.level(), Some(2));
/// ```
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Design {
    /// Primitives of each page.
    pub pages: Vec<Vec<Primitive>>,
}

/// Success-probability bins of A2Perf's generator: level 1 ⇔ p ∈ [0.5, 0.75), level 2 ⇔
/// [0.25, 0.5), level 3 ⇔ [0, 0.25); p ≥ 0.75 is discarded.
pub const LEVEL_BINS: [f64; 4] = [0.0, 0.25, 0.5, 0.75];

fn factorial(k: usize) -> f64 {
    (1..=k).map(|i| i as f64).product()
}

/// `−ln((1/k!)·(1 − passive/all) + 1e-8)` of one page (A2Perf `Page.calculate_difficulty`), where
/// k = number of active primitives (duplicates included) and passive/all is the share of
/// `num_dom_elements` belonging to non-active primitives. An empty page has difficulty 0.
pub fn page_difficulty(page: &[Primitive]) -> f64 {
    if page.is_empty() {
        return 0.0;
    }
    let k = page.iter().filter(|p| p.info().active).count();
    let all: u32 = page.iter().map(|p| p.info().n_dom).sum();
    let passive: u32 = page
        .iter()
        .filter(|p| !p.info().active)
        .map(|p| p.info().n_dom)
        .sum();
    let p_distract = f64::from(passive) / f64::from(all);
    -((1.0 / factorial(k)) * (1.0 - p_distract) + 1e-8).ln()
}

/// Maps a success probability to a level (1–3), `None` for p ≥ 0.75 (too easy, dropped).
///
/// ```
/// assert_eq!(a2perf_web::level_of_probability(0.6), Some(1));
/// assert_eq!(a2perf_web::level_of_probability(0.3), Some(2));
/// assert_eq!(a2perf_web::level_of_probability(0.0), Some(3));
/// assert_eq!(a2perf_web::level_of_probability(0.9), None);
/// ```
pub fn level_of_probability(p: f64) -> Option<u8> {
    if p >= LEVEL_BINS[3] {
        None
    } else if p >= LEVEL_BINS[2] {
        Some(1)
    } else if p >= LEVEL_BINS[1] {
        Some(2)
    } else {
        Some(3)
    }
}

#[derive(Deserialize)]
struct RawDesign {
    #[serde(default)]
    number_of_pages: Option<u64>,
    action: Vec<String>,
    action_page: Vec<u64>,
}

impl Design {
    /// Website difficulty: the sum of [`page_difficulty`] over pages.
    pub fn difficulty(&self) -> f64 {
        self.pages.iter().map(|p| page_difficulty(p)).sum()
    }

    /// `exp(−difficulty)`.
    pub fn success_probability(&self) -> f64 {
        (-self.difficulty()).exp()
    }

    /// Difficulty level 1–3 (`None` when too easy for any level).
    pub fn level(&self) -> Option<u8> {
        level_of_probability(self.success_probability())
    }

    /// Active primitives in page order, each concept once (later duplicates are not rendered).
    pub fn unique_active(&self) -> Vec<Primitive> {
        let mut out: Vec<Primitive> = Vec::new();
        for p in self.pages.iter().flatten() {
            if p.info().active && !out.contains(p) {
                out.push(*p);
            }
        }
        out
    }

    /// Steps an optimal agent needs: one per unique profile field, one `next` per page change and
    /// the final submit.
    pub fn oracle_steps(&self) -> usize {
        self.unique_active().len() + self.pages.len().max(1)
    }

    /// Builds a design from A2Perf's representation (`action` names with their `action_page`).
    /// As in `design_environment`, `#none#` entries are skipped, the page count is
    /// `max(action_page) + 1` (so trailing empty pages vanish) and `number_of_pages` is ignored.
    pub fn from_actions(actions: &[String], pages: &[u64]) -> Result<Self, String> {
        if actions.len() != pages.len() {
            return Err(format!(
                "`action` has {} entries but `action_page` has {}",
                actions.len(),
                pages.len()
            ));
        }
        let mut out: Vec<Vec<Primitive>> = Vec::new();
        for (i, (name, &page)) in actions.iter().zip(pages).enumerate() {
            if name == STOP || name == NEXT_PAGE {
                continue;
            }
            let prim = Primitive::from_name(name)
                .ok_or_else(|| format!("action {i}: unknown primitive `{name}`"))?;
            let page = usize::try_from(page)
                .ok()
                .filter(|p| *p < 1000)
                .ok_or_else(|| format!("action {i}: page index {page} out of range"))?;
            if out.len() <= page {
                out.resize(page + 1, Vec::new());
            }
            out[page].push(prim);
        }
        Ok(Design { pages: out })
    }

    /// The A2Perf JSON form of this design.
    pub fn to_a2perf_json(&self) -> serde_json::Value {
        let mut action = Vec::new();
        let mut action_page = Vec::new();
        for (i, page) in self.pages.iter().enumerate() {
            for p in page {
                action.push(p.name());
                action_page.push(i);
            }
        }
        serde_json::json!({
            "number_of_pages": self.pages.len(),
            "action": action,
            "action_page": action_page,
        })
    }
}

/// Parses a JSON list of A2Perf designs (the format of `environment_generation/data/0N.json`).
pub fn parse_designs(text: &str, source: &str) -> Result<Vec<Design>, WebError> {
    let raw: Vec<RawDesign> = serde_json::from_str(text).map_err(|e| WebError::BadFile {
        path: source.to_string(),
        reason: format!("line {} column {}: {e}", e.line(), e.column()),
    })?;
    raw.iter()
        .enumerate()
        .map(|(i, r)| {
            let _ = r.number_of_pages;
            Design::from_actions(&r.action, &r.action_page).map_err(|reason| WebError::BadFile {
                path: source.to_string(),
                reason: format!("design {i}: {reason}"),
            })
        })
        .collect()
}

/// Loads a JSON file of A2Perf designs.
pub fn load_designs(path: &Path) -> Result<Vec<Design>, WebError> {
    let text = std::fs::read_to_string(path).map_err(|e| WebError::BadFile {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    parse_designs(&text, &path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(n: &str) -> Primitive {
        Primitive::from_name(n).unwrap()
    }

    #[test]
    fn difficulty_matches_hand_computation() {
        // One active primitive alone: p = 1 − 0 → difficulty ≈ −ln(1 + 1e-8).
        let d = Design {
            pages: vec![vec![p("username")]],
        };
        assert!(d.difficulty().abs() < 1e-7);
        assert_eq!(d.level(), None);
        // Only passive primitives: p = 1·(1−1) → −ln(1e-8) = 18.42.
        let d = Design {
            pages: vec![vec![p("navbar"), p("submit")]],
        };
        assert!((d.difficulty() - 18.420_680_7).abs() < 1e-6);
        assert_eq!(d.level(), Some(3));
        // Sum over pages, with duplicates counted: three actives → 1/3!.
        let page = vec![p("city"), p("city"), p("zipcode"), p("header")];
        let all = 12.0 + 12.0 + 13.0 + 13.0;
        let expect = -((1.0 / 6.0) * (1.0 - 13.0 / all) + 1e-8_f64).ln();
        let d = Design {
            pages: vec![page.clone(), vec![], page],
        };
        assert!((d.difficulty() - 2.0 * expect).abs() < 1e-9);
    }

    #[test]
    fn from_actions_follows_design_environment() {
        let a: Vec<String> = ["#none#", "username", "submit"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let d = Design::from_actions(&a, &[0, 0, 2]).unwrap();
        assert_eq!(d.pages.len(), 3);
        assert!(d.pages[1].is_empty());
        assert!(Design::from_actions(&a, &[0]).is_err());
        let bad = vec!["nope".to_string()];
        assert!(
            Design::from_actions(&bad, &[0])
                .unwrap_err()
                .contains("nope")
        );
        let rt = d.to_a2perf_json();
        let back = parse_designs(&format!("[{rt}]"), "x").unwrap();
        assert_eq!(back[0], d);
    }

    #[test]
    fn malformed_json_names_the_file_and_line() {
        let err = parse_designs("[\n{\"action\": 3}]", "designs.json").unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("designs.json") && msg.contains("line 2"),
            "{msg}"
        );
    }
}

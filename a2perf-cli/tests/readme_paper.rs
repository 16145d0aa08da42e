//! The README's summary of the paper suite ("The paper, side by side") is
//! `docs/paper/comparison.json`, the file `a2perf report --paper` wrote from the committed run:
//! every return cell with its verdict, the count of cells at or above the paper's mean − std,
//! and every finding's outcome. A README edited by hand, or a report re-run without updating
//! the README, fails here.

use std::path::{Path, PathBuf};

use serde_json::Value as Json;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

const SECTION: &str = "## The paper, side by side";

/// The README's section, up to the next `## ` heading.
fn section() -> String {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let start = readme
        .find(SECTION)
        .unwrap_or_else(|| panic!("README.md has no `{SECTION}` section"));
    let rest = &readme[start + SECTION.len()..];
    let end = rest.find("\n## ").unwrap_or(rest.len());
    rest[..end].to_string()
}

/// The cells of a markdown table row (`| a | b |` → `["a", "b"]`).
fn cells(line: &str) -> Vec<String> {
    let t = line.trim();
    t.trim_start_matches('|')
        .trim_end_matches('|')
        .split('|')
        .map(|c| c.trim().to_string())
        .collect()
}

/// A number as the README prints it (`−1.02`, `8.61`), with its count of decimals.
fn number(s: &str) -> Option<(f64, usize)> {
    // Brackets, bold and a note marker (`¹`) around the figure are not part of it.
    let t = s
        .trim()
        .trim_start_matches(['(', '*'])
        .trim_end_matches(|c: char| !c.is_ascii_digit())
        .replace('−', "-");
    let decimals = t.split_once('.').map_or(0, |(_, d)| d.len());
    t.parse().ok().map(|v| (v, decimals))
}

/// A returns cell: `**verdict** ours (paper ± std)`, perhaps with a note marker after it.
struct Cell {
    verdict: String,
    ours: (f64, usize),
    paper_mean: f64,
    paper_std: f64,
}

fn parse_cell(text: &str) -> Cell {
    let words: Vec<&str> = text.split_whitespace().collect();
    let verdict = words
        .first()
        .map(|w| w.trim_matches('*').to_string())
        .unwrap_or_default();
    let nums: Vec<(f64, usize)> = words[1..].iter().filter_map(|w| number(w)).collect();
    assert!(
        ["beats", "within", "trails"].contains(&verdict.as_str()) && nums.len() >= 3,
        "README cell `{text}`: expected `**verdict** ours (paper ± std)`"
    );
    Cell {
        verdict,
        ours: nums[0],
        paper_mean: nums[1].0,
        paper_std: nums[2].0,
    }
}

/// The README's row label of each of the paper's tasks (as `comparison.json` names them).
const TASKS: [(&str, &str); 8] = [
    ("circuit_toy_macro", "circuit, toy macro"),
    ("circuit_ariane", "circuit, Ariane"),
    ("locomotion_dog_pace", "dog pace"),
    ("locomotion_dog_trot", "dog trot"),
    ("locomotion_dog_spin", "dog spin"),
    ("web_difficulty_1_websites_1", "web, 1 website"),
    ("web_difficulty_1_websites_5", "web, 5 websites"),
    ("web_difficulty_1_websites_10", "web, 10 websites"),
];

#[test]
fn the_readme_paper_summary_is_the_committed_comparison() {
    let path = root().join("docs/paper/comparison.json");
    let comparison: Json = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let text = section();
    let rows: Vec<Vec<String>> = text
        .lines()
        .filter(|l| l.trim_start().starts_with('|'))
        .map(cells)
        .collect();
    let returns: Vec<&Json> = comparison["cells"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["metric"] == "Returns" && c["phase"] == "training")
        .collect();
    assert_eq!(returns.len(), 24, "{}", path.display());
    let mut at_or_above = 0;
    for c in &returns {
        let task = c["task"].as_str().unwrap();
        let algo = c["algorithm"].as_str().unwrap();
        let label = TASKS
            .iter()
            .find(|(id, _)| *id == task)
            .unwrap_or_else(|| panic!("task `{task}` has no README label"))
            .1;
        let row = rows
            .iter()
            .find(|r| r[0] == label)
            .unwrap_or_else(|| panic!("README: no row `{label}`"));
        let column = match algo {
            "bc" => 1,
            "ddqn" | "sac" => 2,
            "ppo" => 3,
            other => panic!("algorithm `{other}`"),
        };
        let cell = parse_cell(&row[column]);
        let verdict = c["verdict"].as_str().unwrap();
        assert_eq!(cell.verdict, verdict, "{label} / {algo}");
        let ours = c["ours_mean"].as_f64().unwrap();
        let (printed, decimals) = cell.ours;
        assert!(
            (printed - ours).abs() <= 0.5 * 10f64.powi(-(decimals as i32)) + 1e-12,
            "{label} / {algo}: README says {printed}, comparison.json {ours}"
        );
        assert_eq!(cell.paper_mean, c["paper_mean"].as_f64().unwrap());
        assert_eq!(cell.paper_std, c["paper_std"].as_f64().unwrap());
        if verdict != "trails" {
            at_or_above += 1;
        }
    }
    let count = format!("**{at_or_above} of 24**");
    assert!(text.contains(&count), "README should state {count}");

    let findings = comparison["findings"].as_array().unwrap();
    assert_eq!(findings.len(), 9);
    for f in findings {
        let id = f["id"].as_str().unwrap();
        let row = rows
            .iter()
            .find(|r| r[0] == id)
            .unwrap_or_else(|| panic!("README: no row for finding {id}"));
        let outcome = match f["holds"].as_bool() {
            Some(true) => "holds",
            Some(false) => "does not hold",
            None => "not checked",
        };
        assert_eq!(
            row.last().unwrap().trim_matches('*'),
            outcome,
            "finding {id}"
        );
    }
}

#[test]
fn every_paper_value_in_the_committed_comparison_is_the_papers_tables() {
    // comparison.json's paper figures come from docs/paper/tables.json (itself checked against
    // the shared transcription in a2perf-pipeline/tests/paper_tables.rs), cell for cell.
    let read = |rel: &str| -> Json {
        serde_json::from_str(&std::fs::read_to_string(root().join(rel)).unwrap()).unwrap()
    };
    let comparison = read("docs/paper/comparison.json");
    let tables = read("docs/paper/tables.json");
    let cells = comparison["cells"].as_array().unwrap();
    let mut checked = 0;
    for c in cells {
        let task = tables["tasks"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["id"] == c["task"])
            .unwrap_or_else(|| panic!("task {} not in tables.json", c["task"]));
        let paper =
            &task["algorithms"][c["algorithm"].as_str().unwrap()][c["key"].as_str().unwrap()];
        assert!(paper.is_object(), "{c}");
        assert_eq!(paper["mean"], c["paper_mean"], "{c}");
        assert_eq!(paper["std"], c["paper_std"], "{c}");
        assert_eq!(paper["paper_metric"], c["metric"], "{c}");
        assert_eq!(paper["phase"], c["phase"], "{c}");
        checked += 1;
    }
    // Every cell of the paper's tables is in the comparison, printed or N/A.
    let in_tables: usize = tables["tasks"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|t| t["algorithms"].as_object().unwrap().values())
        .map(|a| a.as_object().unwrap().len())
        .sum();
    assert_eq!(checked, in_tables);
}

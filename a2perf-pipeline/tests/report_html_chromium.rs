//! The report page in a real headless Chromium (the web crate's WebDriver client): it loads from
//! `file://` with no console error and no network request, sorts, filters and toggles curves,
//! shows the paper's column with verdicts, runs no code from result names, and a large report
//! (8 tasks × 4 algorithms × 10 seeds) opens and sorts quickly (figures printed).
//!
//! They SKIP (with a printed reason) when Chromium or chromedriver is missing, unless
//! `A2PERF_REQUIRE_CHROME=1`, then a missing browser fails. Screenshots go to
//! `$CARGO_TARGET_TMPDIR/a2perf-report-screens/` (printed).

mod html_fixture;

use std::path::{Path, PathBuf};
use std::time::Instant;

use a2perf_pipeline::report::html::{self, RunView};
use a2perf_pipeline::report::paper::PaperTables;
use a2perf_pipeline::report::{self, ReportOptions};
use a2perf_web::{ChromiumBackend, ChromiumOptions, chromium_for_tests};
use serde_json::{Value as Json, json};

const PAYLOAD: &str = "<img src=x onerror=window.__xss=1>\"'";

fn chrome_or_skip() -> bool {
    chromium_for_tests().unwrap_or_else(|e| panic!("A2PERF_REQUIRE_CHROME=1 but {e}"))
}

/// A browser with a window large enough to look at, recording every error and console error
/// of the pages it opens in `window.__errors`.
fn browser() -> ChromiumBackend {
    let mut opts = ChromiumOptions::from_env();
    opts.extra_args = vec!["--window-size=1280,1000".into(), "--hide-scrollbars".into()];
    let mut b = ChromiumBackend::launch(&opts).expect("launch chromium");
    let hook = "window.__errors = [];\
        window.addEventListener('error', function (e) { window.__errors.push('error: ' + (e.message || (e.target && e.target.outerHTML) || e.type)); }, true);\
        window.addEventListener('securitypolicyviolation', function (e) { window.__errors.push('csp: ' + e.violatedDirective + ' ' + e.blockedURI); });\
        var ce = console.error; console.error = function () { window.__errors.push('console: ' + Array.prototype.join.call(arguments, ' ')); return ce.apply(console, arguments); };";
    b.cdp("Page.enable", json!({})).expect("Page.enable");
    b.cdp(
        "Page.addScriptToEvaluateOnNewDocument",
        json!({ "source": hook }),
    )
    .expect("install the error hook");
    b
}

fn file_url(p: &Path) -> String {
    format!("file://{}", p.canonicalize().unwrap().display())
}

fn run(b: &mut ChromiumBackend, script: &str) -> Json {
    b.execute(script, "[]")
        .unwrap_or_else(|e| panic!("{e}\n{script}"))
}

fn screens_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("a2perf-report-screens");
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn no_errors_no_requests(b: &mut ChromiumBackend) {
    let errors = run(b, "return window.__errors;");
    assert_eq!(errors, json!([]), "errors on the page");
    let resources = run(
        b,
        "return performance.getEntriesByType('resource').map(function (e) { return e.name; });",
    );
    assert_eq!(resources, json!([]), "the page fetched something");
}

/// The leaderboard column whose header starts with `label`: its cells' `data-sort`.
const COLUMN: &str = "var board = document.getElementById('leaderboard');\
    var ths = Array.prototype.slice.call(board.tHead.rows[0].cells);\
    var label = LABEL;\
    var col = ths.findIndex(function (h) { return h.textContent.trim().indexOf(label) === 0; });\
    var th = ths[col];";

fn column_script(label: &str, tail: &str) -> String {
    COLUMN.replace("LABEL", &Json::String(label.into()).to_string()) + tail
}

fn sort_order(b: &mut ChromiumBackend, label: &str) -> (String, Vec<Option<f64>>) {
    let v = run(
        b,
        &column_script(
            label,
            "th.querySelector('button').click();\
             return [th.getAttribute('aria-sort'), Array.prototype.map.call(board.tBodies[0].rows, function (r) { var s = r.cells[col].getAttribute('data-sort'); return s === '' ? null : parseFloat(s); })];",
        ),
    );
    let dir = v[0].as_str().unwrap().to_string();
    let values = v[1].as_array().unwrap().iter().map(Json::as_f64).collect();
    (dir, values)
}

fn is_sorted(values: &[Option<f64>], ascending: bool) -> bool {
    let present: Vec<f64> = values.iter().map_while(|v| *v).collect();
    // Missing values come last whatever the direction.
    values[present.len()..].iter().all(Option::is_none)
        && present.windows(2).all(|w| {
            if ascending {
                w[0] <= w[1]
            } else {
                w[0] >= w[1]
            }
        })
}

#[test]
fn the_page_works_in_chromium_and_runs_no_code_from_results() {
    if !chrome_or_skip() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    // Two plain tasks and one whose names carry markup.
    let algorithms = ["ppo", "ddqn", "sac"];
    let tasks = html_fixture::tasks(2);
    html_fixture::write_tree(&root.join("results"), &tasks, &algorithms, 3, 60);
    let evil = html_fixture::SynthTask {
        name: format!("</script>{PAYLOAD}"),
        env_id: "WebNavigation-Difficulty-01-v0".into(),
        domain: "web_navigation".into(),
    };
    for seed in 0..3 {
        let mut r = html_fixture::SynthRun::new(
            &format!("exp{PAYLOAD}"),
            &evil,
            &format!("bc{PAYLOAD}"),
            seed,
        );
        r.energy_note = format!("note {PAYLOAD}</script>");
        r.write(&root.join("results"));
    }
    let failed = html_fixture::SynthRun::new("broken", &tasks[0], "ppo", 7);
    html_fixture::write_failed_run(
        &failed,
        &root.join("results"),
        &format!("failed: {PAYLOAD}"),
    );
    let tables = PaperTables::from_json(
        &html_fixture::paper_tables(&tasks[0].env_id, &algorithms),
        Path::new("tables.json"),
    )
    .unwrap();
    let dirs = vec![root.join("results")];
    let out = root.join("report");
    let opts = ReportOptions {
        bootstrap_reps: 200,
        seed: 0,
    };
    report::write_report_with_paper(&dirs, &out, &opts, Some(&tables)).unwrap();
    // The page as written, with the verdicts the paper comparison computed.
    let (rep, groups) = report::build_report_with_paper(&dirs, &opts, Some(&tables)).unwrap();
    let verdicts = html_fixture::count_verdicts(&rep);
    assert!(verdicts > 0);
    let page = out.join("index.html");
    std::fs::write(&page, html::page(&rep, &RunView::of_groups(&groups, &out))).unwrap();

    let mut b = browser();
    b.navigate(&file_url(&page)).unwrap();
    no_errors_no_requests(&mut b);
    assert_eq!(
        run(&mut b, "return typeof window.__xss;"),
        json!("undefined")
    );
    // The markup in names is shown as text.
    // textContent: the notes sit in closed <details>.
    let text = run(&mut b, "return document.body.textContent;");
    let text = text.as_str().unwrap();
    assert!(
        text.contains(&format!("</script>{PAYLOAD}")),
        "task name not shown"
    );
    assert!(
        text.contains(&format!("note {PAYLOAD}</script>")),
        "note not shown"
    );
    assert!(
        text.contains(&format!("failed: {PAYLOAD}")),
        "skipped run's reason not shown"
    );
    assert_eq!(run(&mut b, "return document.images.length;"), json!(0));

    // Paper column and verdicts.
    let paper = run(
        &mut b,
        "return [document.querySelectorAll('#leaderboard div.paper').length, Array.prototype.map.call(document.querySelectorAll('#leaderboard .verdict'), function (v) { return v.textContent; })];",
    );
    assert!(paper[0].as_u64().unwrap() >= 3, "{paper}");
    let badges = paper[1].as_array().unwrap();
    assert_eq!(badges.len(), verdicts);
    assert!(badges.iter().all(|v| {
        let v = v.as_str().unwrap();
        v.starts_with("▲ beats") || v.starts_with("≈ within") || v.starts_with("▼ trails")
    }));

    // Sorting: ascending, then descending, by return; by algorithm name as text.
    let (dir, values) = sort_order(&mut b, "Return");
    assert_eq!(dir, "ascending");
    assert!(is_sorted(&values, true), "{values:?}");
    assert!(values.windows(2).any(|w| w[0] != w[1]), "nothing to sort");
    let (dir, values) = sort_order(&mut b, "Return");
    assert_eq!(dir, "descending");
    assert!(is_sorted(&values, false), "{values:?}");
    let v = run(
        &mut b,
        &column_script(
            "Algorithm",
            "th.querySelector('button').click();\
             return [ths.map(function (h) { return h.getAttribute('aria-sort'); }), Array.prototype.map.call(board.tBodies[0].rows, function (r) { return r.getAttribute('data-algorithm'); })];",
        ),
    );
    let names: Vec<&str> = v[1]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    let mut sorted = names.clone();
    sorted.sort();
    assert_eq!(names, sorted);
    let sorts = v[0].as_array().unwrap();
    assert_eq!(sorts.iter().filter(|s| *s == "ascending").count(), 1);
    assert_eq!(
        sorts.iter().filter(|s| *s == "none").count(),
        sorts.len() - 1
    );

    // Filtering by algorithm (a name with markup), then by domain.
    let evil_algo = format!("bc{PAYLOAD}");
    let v = b
        .execute(
            "var s = document.getElementById('filter-algorithm'); s.value = arguments[0];\
             s.dispatchEvent(new Event('change'));\
             var rows = Array.prototype.slice.call(document.getElementById('leaderboard').tBodies[0].rows);\
             return [s.value, rows.filter(function (r) { return !r.hidden; }).map(function (r) { return r.getAttribute('data-algorithm'); }), rows.length];",
            &json!([evil_algo]).to_string(),
        )
        .unwrap();
    assert_eq!(v[0], json!(evil_algo), "the option exists");
    assert_eq!(v[1], json!([evil_algo]));
    assert_eq!(v[2], json!(rep.groups.len()));
    let v = run(
        &mut b,
        "var a = document.getElementById('filter-algorithm'); a.value = ''; a.dispatchEvent(new Event('change'));\
         var s = document.getElementById('filter-domain'); s.value = 'circuit_training'; s.dispatchEvent(new Event('change'));\
         var rows = Array.prototype.slice.call(document.getElementById('leaderboard').tBodies[0].rows);\
         return rows.filter(function (r) { return !r.hidden; }).map(function (r) { return r.getAttribute('data-domain'); });",
    );
    let shown = v.as_array().unwrap();
    let expected = rep
        .groups
        .iter()
        .filter(|g| g.domain == "circuit_training")
        .count();
    assert_eq!(shown.len(), expected);
    assert!(shown.iter().all(|d| d == "circuit_training"));

    // Hiding an algorithm's curve.
    let v = run(
        &mut b,
        "var set = Array.prototype.find.call(document.querySelectorAll('fieldset[data-plot]'), function (f) { return f.querySelectorAll('input').length === 3; });\
         var plot = document.getElementById(set.getAttribute('data-plot'));\
         set.querySelector('input[data-series=\"1\"]').click();\
         return Array.prototype.map.call(plot.querySelectorAll('g.series'), function (g) { return getComputedStyle(g).display; });",
    );
    assert_eq!(v, json!(["inline", "none", "inline"]));
    run(
        &mut b,
        "Array.prototype.find.call(document.querySelectorAll('fieldset[data-plot]'), function (f) { return f.querySelectorAll('input').length === 3; }).querySelector('input[data-series=\"1\"]').click(); return 0;",
    );
    no_errors_no_requests(&mut b);

    // Screenshots to look at, filters back to `all`.
    let dir = screens_dir();
    run(
        &mut b,
        "document.querySelectorAll('select[data-facet]').forEach(function (s) { s.value = ''; s.dispatchEvent(new Event('change')); });\
         window.scrollTo(0, 0); return 0;",
    );
    std::fs::write(dir.join("top.png"), b.screenshot_png().unwrap()).unwrap();
    run(
        &mut b,
        "document.querySelectorAll('section.task')[1].scrollIntoView(); return 0;",
    );
    std::fs::write(dir.join("task.png"), b.screenshot_png().unwrap()).unwrap();
    run(
        &mut b,
        "document.querySelectorAll('section.task')[1].querySelector('.plots').scrollIntoView(); return 0;",
    );
    std::fs::write(dir.join("plots.png"), b.screenshot_png().unwrap()).unwrap();
    run(
        &mut b,
        "document.querySelectorAll('section.task')[1].querySelector('figure.inference').scrollIntoView(); return 0;",
    );
    std::fs::write(dir.join("inference.png"), b.screenshot_png().unwrap()).unwrap();
    println!("screenshots in {}", dir.display());
    for f in ["top.png", "task.png", "plots.png", "inference.png"] {
        let png = std::fs::read(dir.join(f)).unwrap();
        assert!(png.starts_with(b"\x89PNG") && png.len() > 10_000, "{f}");
    }
    b.shutdown();
}

#[test]
fn a_large_report_opens_and_sorts_quickly() {
    if !chrome_or_skip() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let results = tmp.path().join("results");
    let tasks = html_fixture::tasks(8);
    let algorithms = ["ppo", "ddqn", "sac", "bc"];
    html_fixture::write_tree(&results, &tasks, &algorithms, 10, 200);
    let out = tmp.path().join("report");
    let t0 = Instant::now();
    let rep = report::write_report(
        &[results],
        &out,
        &ReportOptions {
            bootstrap_reps: 10_000,
            seed: 0,
        },
    )
    .unwrap();
    let report_s = t0.elapsed().as_secs_f64();
    assert_eq!(rep.groups.len(), 32);
    let page = out.join("index.html");
    let bytes = std::fs::metadata(&page).unwrap().len();
    assert!(bytes < 4_000_000, "index.html is {bytes} bytes");

    let mut b = browser();
    let mut loads = Vec::new();
    let mut sorts = Vec::new();
    for _ in 0..3 {
        b.navigate(&file_url(&page)).unwrap();
        no_errors_no_requests(&mut b);
        let nav = run(
            &mut b,
            "var n = performance.getEntriesByType('navigation')[0]; return [n.domContentLoadedEventEnd, n.loadEventEnd];",
        );
        loads.push(nav[1].as_f64().unwrap());
        let t = run(
            &mut b,
            "var ths = document.getElementById('leaderboard').tHead.rows[0].cells; var out = [];\
             for (var i = 0; i < ths.length; i++) { var t0 = performance.now(); ths[i].querySelector('button').click(); out.push(performance.now() - t0); }\
             return Math.max.apply(null, out);",
        );
        sorts.push(t.as_f64().unwrap());
    }
    b.shutdown();
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "scale: 8 tasks x 4 algorithms x 10 seeds (200 curve points each): report {report_s:.2} s \
         (10,000 bootstrap resamples), index.html {:.2} MB, load (navigation start to load end) \
         median {:.0} ms of 3, slowest column sort median {:.1} ms of 3",
        bytes as f64 / 1e6,
        median(&mut loads),
        median(&mut sorts)
    );
}

//! Real-browser tests: backend parity, restart after a crash, no orphan processes, screenshot.
//!
//! They SKIP (with a printed reason) when Chromium or chromedriver is missing, unless
//! `A2PERF_REQUIRE_CHROME=1`, then a missing browser fails.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use a2perf_core::{Action, Env, Observation, RngStream, Step};
use a2perf_web::site::Behaviour;
use a2perf_web::{
    ActionSemantics, BackendKind, ChromiumBackend, ChromiumOptions, Design, Limits, Primitive,
    TreeMemory, Vocabulary, WebNavConfig, WebNavEnv, Website, chromium_for_tests, generate,
};

/// Geometry tolerance of the parity test, in normalised units (≈ 0.4 px on a 375 px page).
const GEOMETRY_TOLERANCE: f32 = 1e-3;

fn chrome_or_skip() -> bool {
    chromium_for_tests().unwrap_or_else(|e| panic!("A2PERF_REQUIRE_CHROME=1 but {e}"))
}

fn pool() -> Vec<Design> {
    let l = Limits::default();
    (1..=3)
        .flat_map(|level| generate(level, 7, 20, &l).into_iter().map(|g| g.design))
        .collect()
}

fn compare(sim: &Observation, real: &Observation, ctx: &str) -> f32 {
    assert_eq!(
        sim.action_mask, real.action_mask,
        "{ctx}: action masks differ"
    );
    let mut worst = 0.0f32;
    for (a, b) in sim.tensors.iter().zip(&real.tensors) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.shape, b.shape);
        if a.name == "dom_features" {
            let (xa, xb) = (a.data.to_f32_vec(), b.data.to_f32_vec());
            for (k, (x, y)) in xa.iter().zip(&xb).enumerate() {
                if k % 8 < 4 {
                    assert_eq!(x, y, "{ctx}: dom_features[{}][{}]", k / 8, k % 8);
                } else {
                    let d = (x - y).abs();
                    worst = worst.max(d);
                    assert!(
                        d <= GEOMETRY_TOLERANCE,
                        "{ctx}: geometry [{}][{}] {x} vs {y}",
                        k / 8,
                        k % 8
                    );
                }
            }
        } else {
            assert_eq!(a.data, b.data, "{ctx}: tensor {} differs", a.name);
        }
    }
    worst
}

/// The page as the `"html"` render mode gives it (the Chromium backend's from the state the
/// browser reported).
fn html(env: &mut WebNavEnv) -> String {
    match env.render("html").unwrap() {
        a2perf_core::Frame::Text(t) => t,
        a2perf_core::Frame::Rgb { .. } => panic!("html is text"),
    }
}

/// Steps both environments with `a` and checks that rewards, flags, info, observations and
/// rendered pages agree; returns the largest geometry difference.
fn step_both(
    sim: &mut WebNavEnv,
    real: &mut WebNavEnv,
    a: usize,
    ss: &mut Step,
    rs: &mut Step,
    ctx: &str,
) -> f32 {
    sim.step_into(&Action::Discrete(a), ss).unwrap();
    real.step_into(&Action::Discrete(a), rs).unwrap();
    assert_eq!(ss.reward, rs.reward, "{ctx}: reward");
    assert_eq!(ss.terminated, rs.terminated, "{ctx}: terminated");
    assert_eq!(ss.truncated, rs.truncated, "{ctx}: truncated");
    assert_eq!(ss.info, rs.info, "{ctx}: info");
    assert_eq!(html(sim), html(real), "{ctx}: rendered page");
    compare(&ss.observation, &rs.observation, ctx)
}

fn pick_action(obs: &Observation, rng: &mut RngStream) -> usize {
    let mask = obs.action_mask.as_ref().expect("mask");
    let types: Vec<usize> = (0..mask.len()).filter(|&i| mask[i] && i % 2 == 1).collect();
    let clicks: Vec<usize> = (0..mask.len()).filter(|&i| mask[i] && i % 2 == 0).collect();
    if !types.is_empty() && rng.bernoulli(0.5) {
        types[rng.index(types.len())]
    } else {
        clicks[rng.index(clicks.len())]
    }
}

/// DevTools' DOM counters of the page plus its JS heap use after a full GC (`usedSize`).
fn page_counters(env: &mut WebNavEnv) -> serde_json::Value {
    let chrome = env.chromium().unwrap();
    let none = serde_json::json!({});
    let mut c = chrome.cdp("Memory.getDOMCounters", none.clone()).unwrap();
    chrome
        .cdp("HeapProfiler.collectGarbage", none.clone())
        .unwrap();
    let heap = chrome.cdp("Runtime.getHeapUsage", none).unwrap();
    c["usedSize"] = heap["usedSize"].clone();
    c
}

#[test]
fn simulated_and_chromium_backends_agree() {
    if !chrome_or_skip() {
        return;
    }
    let pool = pool();
    let mut sim = WebNavEnv::with_pool(pool.clone(), WebNavConfig::new(1), "parity-sim").unwrap();
    let mut cfg = WebNavConfig::new(1);
    cfg.backend = BackendKind::Chromium;
    let mut real = WebNavEnv::with_pool(pool.clone(), cfg, "parity-chromium").unwrap();
    let (mut so, mut ro) = (Observation::default(), Observation::default());
    let (mut ss, mut rs) = (Step::default(), Step::default());
    let episodes = 210;
    let (mut steps, mut worst, mut successes, mut distractors) = (0, 0.0f32, 0, 0);
    let t0 = Instant::now();
    let mut start = serde_json::Value::Null;
    for ep in 0..episodes {
        if ep == 10 {
            start = page_counters(&mut real);
        }
        let index = ep % pool.len();
        sim.reset_to_website(index, ep as u64, &mut so).unwrap();
        real.reset_to_website(index, ep as u64, &mut ro).unwrap();
        worst = worst.max(compare(&so, &ro, &format!("episode {ep} reset")));
        assert_eq!(
            html(&mut sim),
            html(&mut real),
            "episode {ep} reset: rendered page"
        );
        if ep < 30 {
            // The static attributes in the real DOM equal the model's.
            let snap = real.chromium().unwrap().snapshot().unwrap();
            let site = real.website();
            assert_eq!(snap.len(), sim.dom().order.len());
            for e in snap {
                let node = &site.nodes[e.index];
                assert_eq!(e.tag, node.tag.token(), "episode {ep} element {}", e.index);
                assert_eq!(e.text, node.text, "episode {ep} element {}", e.index);
                assert_eq!(e.placeholder, node.placeholder);
                assert_eq!(e.classes, node.classes);
            }
        }
        // Even episodes: oracle (with a random detour every few steps); odd: random actions.
        let mut rng = RngStream::new(ep as u64, "parity-actions");
        for t in 0..30 {
            let a = if ep % 2 == 0 && t % 4 != 3 {
                match sim.oracle_action() {
                    Some(a) => a,
                    None => break,
                }
            } else {
                pick_action(&so, &mut rng)
            };
            steps += 1;
            let ctx = format!("episode {ep} step {t} action {a}");
            worst = worst.max(step_both(&mut sim, &mut real, a, &mut ss, &mut rs, &ctx));
            so.copy_from(&ss.observation);
            if ss.done() {
                successes += usize::from(ss.info.get("success") == Some(1.0));
                distractors += usize::from(ss.info.get("distractor") == Some(1.0));
                break;
            }
        }
    }
    println!(
        "parity: {episodes} episodes, {steps} steps, {successes} successes, {distractors} distractor ends, \
         max geometry difference {worst} (tolerance {GEOMETRY_TOLERANCE}), {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    assert!(successes > 50 && distractors > 10);
    // Nothing of past episodes stays alive in the page: after 200 more episodes (two page-shell
    // reloads) the DOM counters and the JS heap after a full GC are where they were after the
    // first ten (the page script keeps no per-episode objects). Deltas, because the full
    // browser's single process also counts its built-in pages.
    let end = page_counters(&mut real);
    let grew = |k: &str| end[k].as_f64().unwrap_or(f64::MAX) - start[k].as_f64().unwrap_or(0.0);
    println!("page counters after 10 episodes {start}, after {episodes} {end}");
    assert!(
        grew("documents") <= 1.0
            && grew("nodes") < 1_000.0
            && grew("jsEventListeners") < 100.0
            && grew("usedSize") < 4e6,
        "page counters after 10 episodes {start}, after {episodes} {end}"
    );
    real.close().unwrap();
}

/// The original's semantics (A2Perf's `visitGroup`, the `cc` bug, empty placeholders, the
/// step limit as termination) agree step by step in both backends: values set and cleared,
/// checkboxes toggled, radios checked (or, for `cc`, never), ids shared by buttons, stale steps;
/// and so does the `cc` bug alone under the default click/type semantics.
#[test]
fn a2perf_semantics_agree_in_both_backends() {
    if !chrome_or_skip() {
        return;
    }
    let mut profile = WebNavConfig::a2perf(1, "unused".into());
    profile.designs_file = None;
    semantics_parity(profile.clone(), "a2perf");
    let mut cc = WebNavConfig::new(1);
    cc.cc_bug = true;
    semantics_parity(cc.clone(), "cc_bug");
    // Every (control, field, kind) on one form, for profiles with every value of
    // `numberofpeople` ("1" is loosely true: typed into a checkbox, it clicks it).
    profile.step_limit = 1000;
    cc.step_limit = 1000;
    for cfg in [profile, cc] {
        exhaustive_control_parity(cfg);
    }
}

fn exhaustive_control_parity(mut cfg: WebNavConfig) {
    // Two pages; the second repeats four of the first's fields (rendered with
    // `duplicate_fields`: inputs sharing the first copy's id, a second cc and cabin group).
    let pages: [&[&str]; 2] = [
        &[
            "numberofpeople",
            "rememberme",
            "stayloggedin",
            "cc",
            "cabin",
            "state",
            "username",
            "city",
            "next_login",
        ],
        &["username", "cabin", "cc", "rememberme", "state", "submit"],
    ];
    let design = Design {
        pages: pages
            .iter()
            .map(|p| p.iter().map(|n| Primitive::from_name(n).unwrap()).collect())
            .collect(),
    };
    let mut sim = WebNavEnv::with_pool(vec![design.clone()], cfg.clone(), "sim").unwrap();
    cfg.backend = BackendKind::Chromium;
    let mut real = WebNavEnv::with_pool(vec![design], cfg, "chromium").unwrap();
    let (mut so, mut ro) = (Observation::default(), Observation::default());
    let (mut ss, mut rs) = (Step::default(), Step::default());
    let mut people = Vec::new();
    let mut steps = 0;
    for seed in 0..40 {
        sim.reset_to_website(0, seed, &mut so).unwrap();
        let value = |env: &WebNavEnv| {
            let f = env
                .website()
                .fields
                .iter()
                .find(|f| f.key == "numberofpeople");
            f.map(|f| f.value.clone()).unwrap_or_default()
        };
        if people.contains(&value(&sim)) {
            continue;
        }
        people.push(value(&sim));
        real.reset_to_website(0, seed, &mut ro).unwrap();
        compare(&so, &ro, &format!("seed {seed} reset"));
        let fields = sim.website().fields.len();
        for page in 0..2 {
            let controls: Vec<usize> = (0..sim.dom().order.len())
                .filter(|&e| {
                    sim.website().nodes[sim.dom().order[e] as usize]
                        .tag
                        .is_control()
                })
                .collect();
            for &e in &controls {
                for f in 0..=fields {
                    for kind in 0..2 {
                        let a = sim.action_index(e, f, kind);
                        if !so.is_legal(a) && sim.config().actions == ActionSemantics::Masked {
                            continue;
                        }
                        let ctx =
                            format!("seed {seed} page {page}: element {e} field {f} kind {kind}");
                        step_both(&mut sim, &mut real, a, &mut ss, &mut rs, &ctx);
                        so.copy_from(&ss.observation);
                        steps += 1;
                    }
                }
            }
            if page == 0 {
                let next = (0..sim.dom().order.len())
                    .find(|&e| {
                        let n = sim.dom().order[e] as usize;
                        matches!(sim.website().nodes[n].behaviour, Behaviour::Next(_))
                    })
                    .unwrap();
                let a = sim.action_index(next, 0, 0);
                step_both(&mut sim, &mut real, a, &mut ss, &mut rs, "next page");
                so.copy_from(&ss.observation);
                assert_eq!(sim.dom().page, 1);
            }
        }
    }
    people.sort();
    assert_eq!(people, ["1", "2", "3", "4", "5"]);
    println!("exhaustive control parity: {steps} steps");
    real.close().unwrap();
}

fn semantics_parity(mut cfg: WebNavConfig, label: &str) {
    let l = Limits::default();
    let has = |d: &Design, name: &str| d.pages.iter().flatten().any(|p| p.name() == name);
    // Generated designs, those holding a radio group (cc among them) first.
    let mut pool: Vec<Design> = (1..=3)
        .flat_map(|level| generate(level, 11, 40, &l).into_iter().map(|g| g.design))
        .collect();
    pool.sort_by_key(|d| !(has(d, "cc") || has(d, "cabin") || has(d, "flighttype")));
    pool.truncate(30);
    assert!(pool.iter().filter(|d| has(d, "cc")).count() >= 3);
    let mut sim = WebNavEnv::with_pool(pool.clone(), cfg.clone(), "parity-sim").unwrap();
    cfg.backend = BackendKind::Chromium;
    let mut real = WebNavEnv::with_pool(pool.clone(), cfg, "parity-chromium").unwrap();
    let (mut so, mut ro) = (Observation::default(), Observation::default());
    let (mut ss, mut rs) = (Step::default(), Step::default());
    let (mut steps, mut worst, mut successes, mut stale) = (0, 0.0f32, 0, 0);
    let a2perf = sim.config().actions == ActionSemantics::A2Perf;
    let episodes = 90;
    for ep in 0..episodes {
        let index = ep % pool.len();
        sim.reset_to_website(index, ep as u64, &mut so).unwrap();
        real.reset_to_website(index, ep as u64, &mut ro).unwrap();
        worst = worst.max(compare(&so, &ro, &format!("{label} episode {ep} reset")));
        let mut rng = RngStream::new(ep as u64, "semantics-parity-actions");
        for t in 0..30 {
            let shown = sim.dom().order.len().min(250);
            let fields = sim.website().fields.len();
            // A visible control, to set, clear, toggle and check values.
            let control = sim.dom().order[..shown]
                .iter()
                .position(|&n| sim.website().nodes[n as usize].tag.is_control())
                .map(|first| {
                    let controls: Vec<usize> = (first..shown)
                        .filter(|&e| {
                            let n = sim.dom().order[e] as usize;
                            sim.website().nodes[n].tag.is_control()
                        })
                        .collect();
                    controls[rng.index(controls.len())]
                });
            let a = match (rng.index(20), control) {
                // The oracle alone in a third of the episodes.
                _ if ep % 3 == 0 => match sim.oracle_action() {
                    Some(a) => a,
                    None => break,
                },
                // A2Perf: an element beyond the page (the stale reward), or anywhere.
                (0, _) if a2perf => {
                    stale += 1;
                    sim.action_index(shown + rng.index(250 - shown), 0, rng.index(2))
                }
                (1, _) if a2perf => rng.index(12_500),
                // A control with any field (`_dummy` = no value) or, masked, a legal action.
                (2..=11, Some(e)) => {
                    let a = sim.action_index(e, rng.index(fields + 1), rng.index(2));
                    if so.is_legal(a) {
                        a
                    } else {
                        pick_action(&so, &mut rng)
                    }
                }
                _ => pick_action(&so, &mut rng),
            };
            steps += 1;
            let ctx = format!("{label} episode {ep} step {t} action {a}");
            worst = worst.max(step_both(&mut sim, &mut real, a, &mut ss, &mut rs, &ctx));
            so.copy_from(&ss.observation);
            if ss.done() {
                successes += usize::from(ss.info.get("success") == Some(1.0));
                break;
            }
        }
    }
    println!(
        "{label} parity: {episodes} episodes, {steps} steps ({stale} stale), {successes} \
         successes, max geometry difference {worst}"
    );
    assert!(successes >= 10 && (stale > 0 || !a2perf));
    real.close().unwrap();
}

fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map(|s| {
            // State is the field after the parenthesised command name; zombies are dead.
            s.rsplit(')')
                .next()
                .and_then(|r| r.split_whitespace().next())
                .is_some_and(|st| st != "Z" && st != "X")
        })
        .unwrap_or(false)
}

fn live_with(tag: &str) -> Vec<u32> {
    std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()))
        .filter(|&p| {
            std::fs::read(format!("/proc/{p}/cmdline"))
                .map(|c| String::from_utf8_lossy(&c).contains(tag))
                .unwrap_or(false)
                && alive(p)
        })
        .collect()
}

#[test]
fn shutdown_leaves_no_browser_processes() {
    if !chrome_or_skip() {
        return;
    }
    let mut cfg = WebNavConfig::new(2);
    cfg.backend = BackendKind::Chromium;
    let mut env = WebNavEnv::new(cfg.clone()).unwrap();
    env.reset(Some(0)).unwrap();
    let a = env.oracle_action().unwrap();
    env.step(&Action::Discrete(a)).unwrap();
    let chrome = env.chromium().unwrap();
    let pids = chrome.pids();
    let tag = chrome.profile_tag().to_string();
    assert!(
        pids.len() >= 2,
        "expected chromedriver + browser processes, got {pids:?}"
    );
    assert!(pids.iter().all(|&p| alive(p)));
    env.close().unwrap();
    let still: Vec<u32> = pids.iter().copied().filter(|&p| alive(p)).collect();
    assert!(still.is_empty(), "alive after close: {still:?}");
    assert!(live_with(&tag).is_empty());
    assert!(!Path::new(&tag).exists(), "profile directory left behind");
    // Drop without close cleans up too.
    let mut env = WebNavEnv::new(cfg).unwrap();
    env.reset(Some(1)).unwrap();
    let chrome = env.chromium().unwrap();
    let (pids, tag) = (chrome.pids(), chrome.profile_tag().to_string());
    drop(env);
    assert!(pids.iter().all(|&p| !alive(p)));
    assert!(live_with(&tag).is_empty());
}

#[test]
fn a_dead_browser_is_restarted_and_the_episode_reported_interrupted() {
    if !chrome_or_skip() {
        return;
    }
    let mut cfg = WebNavConfig::new(1);
    cfg.backend = BackendKind::Chromium;
    let mut env = WebNavEnv::new(cfg).unwrap();
    env.reset(Some(5)).unwrap();
    let chrome = env.chromium().unwrap();
    let tag = chrome.profile_tag().to_string();
    // Kill the browser (not chromedriver): every process started with our profile directory.
    for pid in live_with(&tag) {
        let _ = Command::new("kill").arg("-9").arg(pid.to_string()).status();
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    while !live_with(&tag).is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let a = env.oracle_action().unwrap();
    let step = env.step(&Action::Discrete(a)).unwrap();
    assert!(step.truncated && !step.terminated);
    assert_eq!(step.info.get("interrupted"), Some(1.0));
    assert_eq!(env.browser_restarts(), 1);
    assert!(
        env.step(&Action::Discrete(a)).is_err(),
        "episode must need a reset"
    );
    // The new browser works.
    env.reset(Some(6)).unwrap();
    let mut ok = false;
    while let Some(a) = env.oracle_action() {
        let s = env.step(&Action::Discrete(a)).unwrap();
        if s.done() {
            ok = s.info.get("success") == Some(1.0);
            break;
        }
    }
    assert!(ok);
    let new_tag = env.chromium().unwrap().profile_tag().to_string();
    env.close().unwrap();
    assert!(live_with(&new_tag).is_empty());
    assert!(live_with(&tag).is_empty());
}

#[test]
fn rendered_website_screenshot_shows_the_form() {
    if !chrome_or_skip() {
        return;
    }
    let design = generate(2, 3, 1, &Limits::default()).remove(0).design;
    let site = Website::build(
        &design,
        &mut RngStream::new(3, "render"),
        Vocabulary::standard(),
    );
    let html = site.to_html(true);
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("site.html");
    std::fs::write(&page, &html).unwrap();
    let shot = dir.path().join("site.png");
    let profile = dir.path().join("profile");
    let opts = ChromiumOptions::from_env();
    let mut child = Command::new(&opts.chromium)
        .args(a2perf_web::chromium::CHROMIUM_FLAGS)
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", shot.display()))
        .arg("--window-size=400,900")
        .arg("--hide-scrollbars")
        .arg(format!("file://{}", page.display()))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium --screenshot did not finish in 60 s");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let png = std::fs::read(&shot).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert!(
        png.len() > 5_000,
        "screenshot suspiciously small: {} bytes",
        png.len()
    );
    // DOM check through the backend: every field's control and the submit button are rendered.
    let mut chrome = ChromiumBackend::launch(&opts).unwrap();
    chrome.load_html(html).unwrap();
    let snap = chrome.snapshot().unwrap();
    for f in &site.fields {
        for &n in &f.nodes {
            assert!(
                snap.iter().any(|e| e.index == n as usize),
                "field {} not rendered",
                f.key
            );
        }
    }
    assert!(snap.iter().any(|e| e.tag == "button"));
    assert!(
        snap.iter().filter(|e| e.tag.starts_with("input_")).count() >= site.fields.len().min(1)
    );
    chrome.shutdown();
}

/// Parent pid of a live process.
fn parent(pid: u32) -> Option<u32> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    s.rsplit(')')
        .next()?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

#[test]
fn memory_counts_the_whole_process_tree_in_the_normal_process_model() {
    if !chrome_or_skip() {
        return;
    }
    // Chromium's normal model: zygote, renderer, GPU and utility processes, some of which do not
    // carry the profile directory on their command line.
    let mut opts = ChromiumOptions::from_env();
    opts.extra_args.clear();
    let mut chrome = ChromiumBackend::launch(&opts).unwrap();
    let design = generate(1, 4, 1, &Limits::default()).remove(0).design;
    let site = Website::build(
        &design,
        &mut RngStream::new(4, "tree"),
        Vocabulary::standard(),
    );
    chrome.load_html(site.to_html(false)).unwrap();
    let pids = chrome.pids();
    assert!(
        pids.len() >= 3,
        "expected a multi-process tree, got {pids:?}"
    );
    // Closed under "child of": every live child of a counted process is counted.
    let all: Vec<u32> = std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()))
        .filter(|&p| alive(p))
        .collect();
    let children: Vec<(u32, u32)> = all
        .into_iter()
        .filter_map(|p| parent(p).map(|pp| (p, pp)))
        .filter(|(_, pp)| pids.contains(pp))
        .collect();
    // A later snapshot, so that a process started while scanning is not a false alarm.
    let later = chrome.pids();
    for (p, pp) in children {
        assert!(
            later.contains(&p) || !alive(p),
            "child {p} of {pp} not counted in {later:?}"
        );
    }
    // Chromium starts and ends helper processes at any time: measure the listed ones.
    let m = TreeMemory::of(&pids);
    assert_eq!(m.processes, pids.len());
    assert!(m.uss_bytes > 0 && m.uss_bytes <= m.pss_bytes && m.pss_bytes <= m.rss_bytes);
    assert!(m.pss_anon_bytes + m.pss_file_bytes + m.pss_shmem_bytes <= m.pss_bytes + 1024 * 1024);
    let by_process = chrome.memory_by_process();
    assert!(by_process.iter().any(|(_, role, _)| role == "chromedriver"));
    assert!(by_process.iter().any(|(_, role, _)| role == "renderer"));
    let tag = chrome.profile_tag().to_string();
    chrome.shutdown();
    let still: Vec<u32> = pids.iter().copied().filter(|&p| alive(p)).collect();
    assert!(still.is_empty(), "alive after shutdown: {still:?}");
    assert!(live_with(&tag).is_empty());
}

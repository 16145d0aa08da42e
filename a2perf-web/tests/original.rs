//! The switches that reproduce the original A2Perf environment, one test per switch: with the
//! A2Perf-compatible setting the deviation behaves as the original, without it the corrected
//! default holds. Tests that need A2Perf's design files read them from `../shared/data` and skip
//! (with a printed reason) when absent, unless `A2PERF_REQUIRE_SHARED=1`.

mod common;

use a2perf_core::{Action, Env, EnvError, Observation, RngStream, Space, Step};
use a2perf_web::site::{Behaviour, Tag};
use a2perf_web::{
    ActionSemantics, Design, Limits, Vocabulary, WebNavConfig, WebNavEnv, check_solvable, generate,
    load_designs, report,
};
use common::{env_on, oracle_episode, shared, slot};

fn step(env: &mut WebNavEnv, a: usize) -> Step {
    env.step(&Action::Discrete(a)).unwrap()
}

/// Steps with the action (element slot, field, kind).
fn act(env: &mut WebNavEnv, (e, f, kind): (usize, usize, usize)) -> Step {
    let a = env.action_index(e, f, kind);
    step(env, a)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

fn has_cc(d: &Design) -> bool {
    d.pages.iter().flatten().any(|p| p.name() == "cc")
}

/// Observation field of the website's profile key `key` (field 0 is `_dummy`).
fn field_of(env: &WebNavEnv, key: &str) -> usize {
    1 + env
        .website()
        .fields
        .iter()
        .position(|f| f.key == key)
        .unwrap()
}

fn a2perf_actions() -> WebNavConfig {
    let mut cfg = WebNavConfig::new(1);
    cfg.actions = ActionSemantics::A2Perf;
    cfg
}

#[test]
fn field_0_is_a2perf_dummy_and_time_step_counts_steps() {
    let mut env = env_on(
        &[&["username", "password", "city", "header"]],
        WebNavConfig::new(1),
    );
    let obs = env.reset(Some(0)).unwrap();
    let v = Vocabulary::standard();
    let pk = obs.tensor("profile_keys").unwrap().data.to_f32_vec();
    let pv = obs.tensor("profile_values").unwrap().data.to_f32_vec();
    let pm = obs.tensor("profile_mask").unwrap().data.to_f32_vec();
    // Field 0: `_dummy`, present, its value None has no token.
    assert_eq!(pk[0], v.id("_dummy") as f32);
    assert!(pk[1..10].iter().chain(&pv[0..10]).all(|&x| x == 0.0));
    assert_eq!(pm[0], 1.0);
    // Fields 1..: the profile sorted by key; the rest absent.
    for (k, key) in ["city", "password", "username"].iter().enumerate() {
        let ids: Vec<f32> = v.encode(key).iter().map(|&i| i as f32).collect();
        assert_eq!(&pk[(k + 1) * 10..(k + 1) * 10 + ids.len()], &ids[..]);
        assert_eq!(pm[k + 1], 1.0);
    }
    assert!(pm[4..].iter().all(|&x| x == 0.0));
    // time_step = steps / step_limit: 0 at reset, k/25 after k steps, 1 at the limit.
    assert_eq!(obs.tensor("time_step").unwrap().data.to_f32_vec(), [0.0]);
    let h = slot(&env, |n| n.tag == Tag::H5);
    for k in 1..=25 {
        let s = act(&mut env, (h, 0, 0));
        assert_eq!(
            s.observation.tensor("time_step").unwrap().data.to_f32_vec(),
            [k as f32 / 25.0]
        );
    }
}

#[test]
fn placeholders_are_filled_by_default_and_empty_with_the_switch() {
    let pages: &[&[&str]] = &[&["username", "password", "addressline2", "submit"]];
    let placeholder_slots = |obs: &Observation| -> Vec<f32> {
        let dt = obs.tensor("dom_tokens").unwrap().data.to_f32_vec();
        (0..250)
            .flat_map(|e| dt[(e * 5 + 3) * 10..(e * 5 + 4) * 10].to_vec())
            .collect()
    };
    // Default: the username input shows "Username" (the original's MiniWoB never sent it).
    let mut env = env_on(pages, WebNavConfig::new(1));
    let obs = env.reset(Some(0)).unwrap();
    let u = slot(&env, |n| n.html_id == "actionable_username");
    let ph = placeholder_slots(&obs);
    assert_eq!(
        ph[u * 10],
        Vocabulary::standard().id("username") as f32,
        "placeholder slot of the username input"
    );
    assert!(ph.iter().filter(|&&x| x != 0.0).count() >= 3);
    // placeholders = false: the slot is empty for every element, the rest is unchanged.
    let mut cfg = WebNavConfig::new(1);
    cfg.placeholders = false;
    let mut bare = env_on(pages, cfg);
    let obs2 = bare.reset(Some(0)).unwrap();
    assert!(placeholder_slots(&obs2).iter().all(|&x| x == 0.0));
    let other = |o: &Observation| {
        let dt = o.tensor("dom_tokens").unwrap().data.to_f32_vec();
        (0..250 * 5)
            .filter(|k| k % 5 != 3)
            .flat_map(|k| dt[k * 10..(k + 1) * 10].to_vec())
            .collect::<Vec<f32>>()
    };
    assert_eq!(other(&obs), other(&obs2));
}

#[test]
fn the_cc_bug_makes_a_design_of_01_json_unsolvable_only_with_the_switch() {
    let Some(path) = shared("01.json") else {
        return;
    };
    let designs = load_designs(&path).unwrap();
    // The first design with `cc` that an optimal agent could otherwise finish in 25 steps.
    let (index, design) = designs
        .iter()
        .enumerate()
        .find(|(_, d)| has_cc(d) && check_solvable(d, &Limits::default()).is_ok())
        .unwrap();
    println!("01.json design {index}: {} steps", design.oracle_steps());
    let play = |cfg: WebNavConfig| {
        let mut env = WebNavEnv::with_pool(vec![design.clone()], cfg, "t").unwrap();
        (0..4)
            .map(|s| oracle_episode(&mut env, 0, s).0)
            .collect::<Vec<_>>()
    };
    assert_eq!(play(WebNavConfig::new(1)), [true; 4], "fixed by default");
    let mut bug = WebNavConfig::new(1);
    bug.cc_bug = true;
    assert_eq!(play(bug), [false; 4], "cc_bug = true");
    assert_eq!(
        play(WebNavConfig::a2perf(1, path.clone())),
        [false; 4],
        "the whole A2Perf profile"
    );
}

#[test]
fn the_cc_bug_checks_nothing_and_marks_only_the_acted_radio() {
    for actions in [ActionSemantics::Masked, ActionSemantics::A2Perf] {
        for bug in [false, true] {
            let mut cfg = WebNavConfig::new(1);
            cfg.cc_bug = bug;
            cfg.actions = actions;
            let mut env = env_on(&[&["cc", "header", "submit"]], cfg);
            env.reset(Some(4)).unwrap();
            let radios = env.website().fields[0].nodes.clone();
            let gold = env.website().fields[0].value_id;
            let r = radios
                .iter()
                .copied()
                .find(|&r| env.website().nodes[r as usize].radio_value == gold)
                .unwrap();
            let s_r = slot(&env, |n| n.radio_value == gold && n.tag == Tag::InputRadio);
            let s = act(&mut env, (s_r, 1, 1));
            let dom = env.dom();
            let visited: Vec<bool> = radios.iter().map(|&n| dom.visited[n as usize]).collect();
            let ctx = format!("{actions:?}, cc_bug {bug}");
            if bug {
                assert!(radios.iter().all(|&n| !dom.checked[n as usize]), "{ctx}");
                assert_eq!(
                    visited,
                    radios.iter().map(|&n| n == r).collect::<Vec<_>>(),
                    "{ctx}"
                );
                assert!(close(s.reward, -0.05), "{ctx}: {}", s.reward);
                // A click does not check it either.
                let s = act(&mut env, (s_r, 0, 0));
                assert!(!env.dom().checked[r as usize], "{ctx}");
                assert!(close(s.reward, -0.55), "{ctx}: {}", s.reward);
            } else {
                assert!(dom.checked[r as usize], "{ctx}");
                assert!(visited.iter().all(|&v| v), "{ctx}");
                assert!(close(s.reward, 0.95), "{ctx}: {}", s.reward);
            }
            let submit = slot(&env, |n| n.behaviour == Behaviour::Submit);
            let s = act(&mut env, (submit, 0, 0));
            assert_eq!(
                s.info.get("success"),
                Some(if bug { 0.0 } else { 1.0 }),
                "{ctx}"
            );
        }
    }
    // The bug is cc's alone: the other radio groups' concepts read from their ids are right.
    let mut cfg = WebNavConfig::new(1);
    cfg.cc_bug = true;
    let mut env = env_on(&[&["cabin", "flighttype", "submit"]], cfg);
    assert!(oracle_episode(&mut env, 0, 0).0);
}

#[test]
fn a2perf_pool_plays_the_design_file_as_it_is_with_the_original_draw() {
    let Some(path) = shared("01.json") else {
        return;
    };
    let designs = load_designs(&path).unwrap();
    // numpy 1.26 and 2.x: RandomState(seed) → randint(0, 1000), choice(1000, 10, replace=False).
    let draws: [(u64, [usize; 10]); 2] = [
        (0, [708, 533, 298, 356, 833, 553, 27, 231, 306, 994]),
        (37, [747, 685, 301, 911, 276, 983, 166, 648, 663, 11]),
    ];
    for (seed, want) in draws {
        let mut cfg = WebNavConfig::a2perf(1, path.clone());
        cfg.seed = seed;
        let env = WebNavEnv::new(cfg).unwrap();
        let list: Vec<String> = want.iter().map(usize::to_string).collect();
        assert_eq!(env.spec().metadata["pool_indices"], list.join(","));
        assert_eq!(env.spec().metadata["pool"], "a2perf");
        let expect: Vec<Design> = want.iter().map(|&i| designs[i].clone()).collect();
        assert_eq!(env.pool(), &expect[..]);
    }
    // The whole file, unfiltered: levels mixed and about half the designs contain cc; under the
    // A2Perf profile the oracle finishes exactly the designs the original could (no cc, at most
    // 25 steps): 481 of 1000 (reference §5).
    let mut cfg = WebNavConfig::a2perf(1, path.clone());
    cfg.num_websites = 1000;
    let mut env = WebNavEnv::new(cfg).unwrap();
    let pool = env.pool().to_vec();
    assert!(pool.iter().any(|d| d.level() == Some(3)));
    assert!(pool.iter().filter(|d| has_cc(d)).count() > 400);
    let solved: Vec<bool> = (0..pool.len())
        .map(|i| oracle_episode(&mut env, i, i as u64).0)
        .collect();
    let limits = Limits::default();
    for (i, d) in pool.iter().enumerate() {
        let original = !has_cc(d) && check_solvable(d, &limits).is_ok();
        assert_eq!(solved[i], original, "pool website {i}");
    }
    let r = report(&designs, &limits);
    assert_eq!(solved.iter().filter(|&&s| s).count(), r.original_solvable);
    assert_eq!(r.original_solvable, 481);
    // The corrected pool from the same file keeps only solvable designs of the recomputed
    // level: 7 at level 1, so 10 is an error that points at the switch.
    let mut filtered = WebNavConfig::new(1);
    filtered.designs_file = Some(path.clone());
    let err = WebNavEnv::new(filtered).err().unwrap().to_string();
    assert!(err.contains("only 7") && err.contains("a2perf"), "{err}");
    // Bad requests name the parameter or the file.
    let mut big = WebNavConfig::a2perf(1, path.clone());
    big.num_websites = 1001;
    let err = WebNavEnv::new(big).err().unwrap().to_string();
    assert!(err.contains("01.json") && err.contains("1001"), "{err}");
    let mut seed = WebNavConfig::a2perf(1, path);
    seed.seed = 1 << 32;
    let err = WebNavEnv::new(seed).err().unwrap().to_string();
    assert!(err.contains("seed") && err.contains("2^32"), "{err}");
}

#[test]
fn the_step_limit_terminates_only_with_the_switch() {
    for limit_terminates in [false, true] {
        let mut cfg = WebNavConfig::new(1);
        cfg.limit_terminates = limit_terminates;
        let mut env = env_on(&[&["header", "submit"]], cfg.clone());
        env.reset(Some(0)).unwrap();
        let h = slot(&env, |n| n.tag == Tag::H5);
        for t in 1..=25 {
            let s = act(&mut env, (h, 0, 0));
            assert_eq!(s.truncated, t == 25);
            assert_eq!(s.terminated, limit_terminates && t == 25);
        }
        // A submit on the last step: the original reports both flags (`done or truncated`).
        let mut env = env_on(&[&["header", "submit"]], cfg);
        env.reset(Some(0)).unwrap();
        for _ in 1..25 {
            act(&mut env, (h, 0, 0));
        }
        let submit = slot(&env, |n| n.behaviour == Behaviour::Submit);
        let s = act(&mut env, (submit, 0, 0));
        assert_eq!(s.info.get("success"), Some(1.0));
        assert!(s.terminated);
        assert_eq!(s.truncated, limit_terminates);
    }
}

#[test]
fn a2perf_actions_follow_visit_group() {
    let pages: &[&[&str]] = &[&[
        "username",
        "rememberme",
        "cabin",
        "city",
        "header",
        "submit",
    ]];
    // A seed whose profile wants `rememberme` checked.
    let mut env = env_on(pages, a2perf_actions());
    let seed = (0..100)
        .find(|&s| {
            env.reset(Some(s)).unwrap();
            env.website()
                .fields
                .iter()
                .any(|f| f.key == "rememberme" && f.value == "true")
        })
        .unwrap();
    let obs = env.reset(Some(seed)).unwrap();
    let fields = env.website().fields.len();
    assert_eq!(fields, 4);
    // The mask is the original network's joint mask: every visible element with every present
    // field (`_dummy` included), for both kinds.
    let shown = env.dom().order.len();
    let mask = obs.action_mask.clone().unwrap();
    for (a, &m) in mask.iter().enumerate() {
        let (e, f, _) = env.decode_action(a);
        assert_eq!(m, e < shown && f <= fields, "action {a}");
    }
    let node = |env: &WebNavEnv, id: &str| {
        env.website()
            .nodes
            .iter()
            .position(|n| n.html_id == id)
            .unwrap()
    };
    // Typing username's value: +1/4 − 0.05; nothing takes the focus.
    let u = slot(&env, |n| n.html_id == "actionable_username");
    let fu = field_of(&env, "username");
    let s = act(&mut env, (u, fu, 1));
    assert!(close(s.reward, 0.25 - 0.05), "{}", s.reward);
    let feats = s
        .observation
        .tensor("dom_features")
        .unwrap()
        .data
        .to_f32_vec();
    assert!((0..250).all(|e| feats[e * 8] == 0.0));
    // Acting without a value (kind 0, or kind 1 with `_dummy`) clears the input: −1/4 − 0.05,
    // then nothing changes: −0.55.
    let s = act(&mut env, (u, 0, 0));
    assert!(close(s.reward, -0.25 - 0.05), "{}", s.reward);
    assert_eq!(env.dom().value[node(&env, "actionable_username")], 0);
    let s = act(&mut env, (u, 0, 1));
    assert!(close(s.reward, -0.55), "{}", s.reward);
    // A checkbox is clicked when typed a true value: typing `true` twice toggles it twice.
    let r = slot(&env, |n| n.html_id == "actionable_rememberme");
    let rm = node(&env, "actionable_rememberme");
    let a = env.action_index(r, field_of(&env, "rememberme"), 1);
    let s = step(&mut env, a);
    assert!(env.dom().checked[rm] && close(s.reward, 0.25 - 0.05));
    let s = step(&mut env, a);
    assert!(!env.dom().checked[rm] && close(s.reward, -0.25 - 0.05));
    // Any other value leaves it (but marks it): typing the city into it changes nothing now.
    let fc = field_of(&env, "city");
    let s = act(&mut env, (r, fc, 1));
    assert!(!env.dom().checked[rm] && close(s.reward, -0.55));
    // A radio acted on without a value checks nothing and marks its whole group visited.
    let c = slot(&env, |n| n.tag == Tag::InputRadio);
    let group = env.website().fields[field_of(&env, "cabin") - 1]
        .nodes
        .clone();
    let s = act(&mut env, (c, 0, 0));
    assert!(close(s.reward, -0.05));
    assert!(
        group
            .iter()
            .all(|&g| env.dom().visited[g as usize] && !env.dom().checked[g as usize])
    );
    // An element with an id but no behaviour (the city label) is marked visited: −0.05; one
    // without an id is left alone: −0.55.
    let l = slot(&env, |n| n.html_id == "label_city");
    let s = act(&mut env, (l, 0, 0));
    assert!(close(s.reward, -0.05) && env.dom().visited[node(&env, "label_city")]);
    let anon = slot(&env, |n| n.html_id.is_empty() && n.tag == Tag::Div);
    let s = act(&mut env, (anon, 0, 0));
    assert!(close(s.reward, -0.55));
    // A field beyond the profile is outside the mask but accepted: no value (a click).
    let s = act(&mut env, (anon, 20, 1));
    assert!(close(s.reward, -0.55));
    // Typing a value into a button clicks it: the incomplete form is submitted, −1.
    let sb = slot(&env, |n| n.behaviour == Behaviour::Submit);
    let s = act(&mut env, (sb, fc, 1));
    assert!(s.terminated && s.info.get("success") == Some(0.0));
    assert!(close(s.reward, -1.0), "{}", s.reward);
    // Masked semantics refuse the same out-of-mask action.
    let mut masked = env_on(pages, WebNavConfig::new(1));
    masked.reset(Some(seed)).unwrap();
    assert!(matches!(
        masked.step(&Action::Discrete(masked.action_index(anon, 20, 1))),
        Err(EnvError::InvalidAction { .. })
    ));
    // The oracle still solves the page with A2Perf's semantics.
    assert!(oracle_episode(&mut env, 0, seed).0);
}

#[test]
fn a2perf_actions_repeat_the_stale_reward_on_a_missing_element() {
    let mut env = env_on(&[&["city", "header", "submit"]], a2perf_actions());
    let obs = env.reset(Some(0)).unwrap();
    let shown = env.dom().order.len();
    let beyond = env.action_index(shown, 0, 0);
    assert!(!obs.is_legal(beyond));
    // The original's `current_reward` (0 at reset) stays and is shaped again: −0.55 each time.
    let s1 = step(&mut env, beyond);
    assert!(close(s1.reward, -0.55), "{}", s1.reward);
    let s2 = step(&mut env, beyond);
    assert!(close(s2.reward, -1.1), "{}", s2.reward);
    let a = env.oracle_action().unwrap();
    let s3 = step(&mut env, a);
    assert!(close(s3.reward, 0.95));
    let s4 = step(&mut env, beyond);
    assert!(close(s4.reward, 0.40), "{}", s4.reward);
    assert!(!s4.terminated && !s4.truncated);
    assert_eq!(
        s4.observation
            .tensor("time_step")
            .unwrap()
            .data
            .to_f32_vec(),
        [4.0 / 25.0]
    );
    // The page is unchanged.
    assert_eq!(
        s4.observation
            .tensor("dom_tokens")
            .unwrap()
            .data
            .to_f32_vec(),
        s3.observation
            .tensor("dom_tokens")
            .unwrap()
            .data
            .to_f32_vec()
    );
    // Outside the action space is an error in both semantics.
    assert!(matches!(
        env.step(&Action::Discrete(250 * 25 * 2)),
        Err(EnvError::InvalidAction { .. })
    ));
    // Masked semantics: the same action is refused.
    let mut masked = env_on(&[&["city", "header", "submit"]], WebNavConfig::new(1));
    masked.reset(Some(0)).unwrap();
    assert!(masked.step(&Action::Discrete(beyond)).is_err());
}

#[test]
fn actions_map_one_to_one_onto_the_original_layout() {
    let env = WebNavEnv::new(WebNavConfig::new(1)).unwrap();
    let n = 250 * 25 * 2;
    let mut seen = vec![false; n];
    for a in 0..n {
        let o = env.a2perf_action(a);
        assert!(o < n && !seen[o]);
        seen[o] = true;
        assert_eq!(env.from_a2perf_action(o), Some(a));
        // A2Perf: type 0 (value of field key) = our kind 1; key = o / 250 % 25, element = o % 250.
        let (e, f, kind) = env.decode_action(a);
        assert_eq!((o % 250, (o / 250) % 25, o / 6250), (e, f, 1 - kind));
    }
    assert_eq!(env.from_a2perf_action(n), None);
}

#[test]
fn the_a2perf_switches_keep_episodes_reproducible() {
    let pool: Vec<Design> = generate(3, 5, 8, &Limits::default())
        .into_iter()
        .map(|g| g.design)
        .collect();
    let run = |seed: u64| {
        let mut cfg = WebNavConfig::a2perf(3, "unused".into());
        cfg.designs_file = None;
        let mut env = WebNavEnv::with_pool(pool.clone(), cfg, "t").unwrap();
        let mut rng = RngStream::new(seed, "actions");
        let mut trace = Vec::new();
        let mut obs = env.reset(Some(seed)).unwrap();
        for _ in 0..4 {
            for _ in 0..25 {
                // Mostly in the mask, sometimes anywhere in the space (stale steps included).
                let a = if rng.bernoulli(0.9) {
                    Space::Discrete { n: 12_500 }
                        .sample(&mut rng, obs.action_mask.as_deref())
                        .unwrap()
                } else {
                    a2perf_core::Action::Discrete(rng.index(12_500))
                };
                let s = env.step(&a).unwrap();
                trace.push((env.pool_index(), s.observation.flat_values(), s.reward));
                let done = s.done();
                obs = s.observation;
                if done {
                    break;
                }
            }
            obs = env.reset(None).unwrap();
        }
        trace
    };
    assert_eq!(run(3), run(3));
    assert_ne!(run(3), run(4));
}

#[test]
fn a2perf_checkboxes_are_clicked_by_loosely_true_values_only() {
    // JavaScript's `value == true` holds for `true` and for the string "1" (numberofpeople).
    let mut env = env_on(
        &[&["numberofpeople", "rememberme", "submit"]],
        a2perf_actions(),
    );
    let mut seen = Vec::new();
    for seed in 0..60 {
        env.reset(Some(seed)).unwrap();
        let people = env.website().fields[0].value.clone();
        let r = slot(&env, |n| n.tag == Tag::InputCheckbox);
        let box_node = env.dom().order[r] as usize;
        let f = field_of(&env, "numberofpeople");
        let s = act(&mut env, (r, f, 1));
        assert_eq!(env.dom().checked[box_node], people == "1", "value {people}");
        // Marked visited either way: the page changed.
        assert!(env.dom().visited[box_node] && s.reward > -0.5);
        seen.push(people);
    }
    seen.sort();
    seen.dedup();
    assert_eq!(seen, ["1", "2", "3", "4", "5"]);
}

#[test]
fn duplicate_fields_render_dead_inputs_and_working_radio_groups() {
    let pages: &[&[&str]] = &[
        &["username", "cabin", "next_login"],
        &["username", "cabin", "submit"],
    ];
    let ids = |env: &WebNavEnv| -> Vec<String> {
        env.dom()
            .order
            .iter()
            .map(|&n| env.website().nodes[n as usize].html_id.clone())
            .collect()
    };
    let to_page_1 = |env: &mut WebNavEnv| {
        let next = slot(env, |n| matches!(n.behaviour, Behaviour::Next(_)));
        act(env, (next, 0, 0));
        assert_eq!(env.dom().page, 1);
    };
    // Default: the second page shows no copy of a field.
    let mut env = env_on(pages, WebNavConfig::new(1));
    env.reset(Some(0)).unwrap();
    to_page_1(&mut env);
    assert!(
        !ids(&env)
            .iter()
            .any(|i| i.contains("username") || i.contains("cabin"))
    );
    for actions in [ActionSemantics::Masked, ActionSemantics::A2Perf] {
        let mut cfg = WebNavConfig::new(1);
        cfg.duplicate_fields = true;
        cfg.actions = actions;
        let mut env = env_on(pages, cfg);
        env.reset(Some(0)).unwrap();
        assert_eq!(env.website().fields.len(), 2);
        // Check the cabin radio that is *not* the gold value on page 0.
        let cabin = field_of(&env, "cabin");
        let gold = env.website().fields[cabin - 1].value_id;
        let wrong = slot(&env, |n| n.tag == Tag::InputRadio && n.radio_value != gold);
        act(&mut env, (wrong, 0, 0));
        to_page_1(&mut env);
        let on_page_1 = ids(&env);
        assert!(on_page_1.contains(&"actionable_username".to_string()));
        assert!(on_page_1.contains(&"actionable_cabin_p1_i0".to_string()));
        // The username copy holds no field: typing into it does not move the potential.
        let u = slot(&env, |n| n.html_id == "actionable_username");
        let fu = field_of(&env, "username");
        let s = act(&mut env, (u, fu, 1));
        let expect = match actions {
            // A2Perf acts on the first copy, hidden on page 0: nothing happens.
            ActionSemantics::A2Perf => -0.55,
            // A user types into the copy: the page changes, the profile field does not.
            ActionSemantics::Masked => -0.05,
        };
        assert!(close(s.reward, expect), "{actions:?}: {}", s.reward);
        // The cabin copy works and shares the group's name: checking the gold value there
        // unchecks page 0's wrong choice and fills the field (+1/2 − 0.05).
        let g1 = slot(&env, |n| n.tag == Tag::InputRadio && n.radio_value == gold);
        let s = act(&mut env, (g1, cabin, 1));
        assert!(close(s.reward, 0.5 - 0.05), "{actions:?}: {}", s.reward);
        let checked: Vec<u32> = env.website().fields[cabin - 1]
            .nodes
            .iter()
            .copied()
            .filter(|&n| env.dom().checked[n as usize])
            .collect();
        assert_eq!(checked.len(), 1, "{actions:?}");
    }
}

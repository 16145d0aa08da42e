//! The web-navigation environment (`WebNavigation-Difficulty-0N-v0`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use a2perf_core::{Action, Env, EnvError, EnvSpec, Observation, RngStream, Space, Step, Tensor};

use crate::chromium::{ChromiumBackend, ChromiumOptions};
use crate::design::{Design, load_designs};
use crate::dom::{ActionKind, DomState, Event};
use crate::error::WebError;
use crate::generator::{Limits, check_solvable, generate};
use crate::site::{Behaviour, Tag, Website};
use crate::vocab::{Vocabulary, vocab_size};

/// Default number of profile fields in the observation.
pub const DEFAULT_FIELDS: usize = 25;
/// Default number of DOM elements in the observation.
pub const DEFAULT_ELEMENTS: usize = 250;
/// Default number of tokens per attribute.
pub const DEFAULT_TOKENS: usize = 10;
/// A2Perf's step limit.
pub const STEP_LIMIT: usize = 25;
/// Attributes per element, in this order: tag, value, text, placeholder, classes.
pub const DOM_ATTRIBUTES: usize = 5;
/// Features per element: focused, tampered, new, is_div, x, y, w, h.
pub const DOM_FEATURES: usize = 8;
/// Per-step penalty.
pub const TIMESTEP_PENALTY: f64 = 0.05;
/// Penalty when the page did not change.
pub const NO_CHANGE_PENALTY: f64 = 0.5;

/// Which browser runs the pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendKind {
    /// The in-process DOM model.
    Simulated,
    /// Headless Chromium through chromedriver.
    Chromium,
}

/// Configuration of a [`WebNavEnv`].
#[derive(Clone, Debug, PartialEq)]
pub struct WebNavConfig {
    /// Difficulty level 1–3.
    pub difficulty: u8,
    /// Size of the website pool.
    pub num_websites: usize,
    /// Seed of the pool and of the episodes.
    pub seed: u64,
    /// Backend.
    pub backend: BackendKind,
    /// Profile fields in the observation (F).
    pub num_fields: usize,
    /// Elements in the observation (E).
    pub num_elements: usize,
    /// Tokens per attribute (T).
    pub num_tokens: usize,
    /// Episode step limit.
    pub step_limit: usize,
    /// Draw the pool from this A2Perf design file instead of the generator (designs of the
    /// id's recomputed level that are solvable within the limits).
    pub designs_file: Option<PathBuf>,
}

impl WebNavConfig {
    /// Defaults of A2Perf for `difficulty` (10 websites, seed 0, simulated backend).
    ///
    /// ```
    /// let c = a2perf_web::WebNavConfig::new(2);
    /// assert_eq!((c.num_fields, c.num_elements, c.num_tokens, c.step_limit), (25, 250, 10, 25));
    /// ```
    pub fn new(difficulty: u8) -> Self {
        Self {
            difficulty,
            num_websites: 10,
            seed: 0,
            backend: BackendKind::Simulated,
            num_fields: DEFAULT_FIELDS,
            num_elements: DEFAULT_ELEMENTS,
            num_tokens: DEFAULT_TOKENS,
            step_limit: STEP_LIMIT,
            designs_file: None,
        }
    }

    /// The generator limits implied by the observation sizes.
    pub fn limits(&self) -> Limits {
        Limits {
            step_limit: self.step_limit,
            max_elements: self.num_elements,
            max_fields: self.num_fields,
        }
    }

    fn validate(&self) -> Result<(), WebError> {
        let bad = |name: &str, reason: &str| {
            Err(WebError::Config {
                name: name.into(),
                reason: reason.into(),
            })
        };
        if !(1..=3).contains(&self.difficulty) {
            return bad("difficulty", "must be 1, 2 or 3");
        }
        if self.num_websites == 0 || self.num_websites > 100_000 {
            return bad("num_websites", "must be in 1..=100000");
        }
        if self.num_fields == 0 || self.num_fields > 1000 {
            return bad("num_fields", "must be in 1..=1000");
        }
        if self.num_elements < 16 || self.num_elements > 10_000 {
            return bad("num_elements", "must be in 16..=10000");
        }
        if self.num_tokens == 0 || self.num_tokens > 100 {
            return bad("num_tokens", "must be in 1..=100");
        }
        if self.step_limit == 0 || self.step_limit > 10_000 {
            return bad("step_limit", "must be in 1..=10000");
        }
        Ok(())
    }

    /// The pool of designs this configuration plays.
    pub fn pool(&self) -> Result<Vec<Design>, WebError> {
        self.validate()?;
        let limits = self.limits();
        match &self.designs_file {
            None => Ok(
                generate(self.difficulty, self.seed, self.num_websites, &limits)
                    .into_iter()
                    .map(|g| g.design)
                    .collect(),
            ),
            Some(path) => {
                let all = load_designs(path)?;
                let mut ok: Vec<Design> = all
                    .into_iter()
                    .filter(|d| {
                        d.level() == Some(self.difficulty) && check_solvable(d, &limits).is_ok()
                    })
                    .collect();
                if ok.len() < self.num_websites {
                    return Err(WebError::BadFile {
                        path: path.display().to_string(),
                        reason: format!(
                            "only {} designs are solvable and of level {} (recomputed), {} requested",
                            ok.len(),
                            self.difficulty,
                            self.num_websites
                        ),
                    });
                }
                // Like A2Perf, a seeded choice without replacement.
                let mut rng = RngStream::new(self.seed, "web-design-file-pool");
                rng.shuffle(&mut ok);
                ok.truncate(self.num_websites);
                Ok(ok)
            }
        }
    }
}

/// The environment. See the crate documentation for the observation and action contract.
pub struct WebNavEnv {
    spec: EnvSpec,
    cfg: WebNavConfig,
    pool: Vec<Design>,
    rng: RngStream,
    site: Website,
    pool_index: usize,
    state: DomState,
    prev: DomState,
    was_visible: Vec<bool>,
    potential: f64,
    steps: usize,
    active: bool,
    done: bool,
    chrome: Option<Box<ChromiumBackend>>,
    chrome_opts: ChromiumOptions,
    restarts: u64,
}

fn box_space(shape: &[usize], high: f32) -> Space {
    Space::uniform_box(shape, 0.0, high)
}

impl WebNavEnv {
    /// Builds the environment from a configuration (launching Chromium for that backend).
    pub fn new(cfg: WebNavConfig) -> Result<Self, WebError> {
        let pool = cfg.pool()?;
        let id = crate::env_id(cfg.difficulty);
        Self::with_pool(pool, cfg, &id)
    }

    /// Builds the environment on an explicit pool of designs (the configuration's pool settings
    /// are ignored).
    pub fn with_pool(pool: Vec<Design>, cfg: WebNavConfig, id: &str) -> Result<Self, WebError> {
        if pool.is_empty() {
            return Err(WebError::Config {
                name: "num_websites".into(),
                reason: "the website pool is empty".into(),
            });
        }
        let (f, e, t) = (cfg.num_fields, cfg.num_elements, cfg.num_tokens);
        let v = (vocab_size() - 1) as f32;
        let observation_space = Space::Dict(vec![
            ("profile_keys".into(), box_space(&[f, t], v)),
            ("profile_values".into(), box_space(&[f, t], v)),
            ("profile_mask".into(), box_space(&[f], 1.0)),
            ("dom_tokens".into(), box_space(&[e, DOM_ATTRIBUTES, t], v)),
            ("dom_features".into(), box_space(&[e, DOM_FEATURES], 1.0)),
            ("dom_mask".into(), box_space(&[e], 1.0)),
        ]);
        let mut metadata = BTreeMap::new();
        metadata.insert("vocab_size".into(), vocab_size().to_string());
        metadata.insert("difficulty".into(), cfg.difficulty.to_string());
        metadata.insert("num_websites".into(), pool.len().to_string());
        metadata.insert("seed".into(), cfg.seed.to_string());
        metadata.insert(
            "backend".into(),
            match cfg.backend {
                BackendKind::Simulated => "simulated".into(),
                BackendKind::Chromium => "chromium".into(),
            },
        );
        metadata.insert(
            "source".into(),
            cfg.designs_file
                .as_ref()
                .map_or("generator".into(), |p| p.display().to_string()),
        );
        metadata.insert("pool_hash".into(), format!("{:016x}", pool_hash(&pool)));
        metadata.insert(
            "action_layout".into(),
            "(element*F+field)*2+kind; kind 0 click (field 0 only), 1 type field value".into(),
        );
        let spec = EnvSpec {
            id: id.into(),
            observation_space,
            action_space: Space::Discrete { n: e * f * 2 },
            max_episode_steps: Some(cfg.step_limit),
            metadata,
        };
        let chrome_opts = ChromiumOptions::from_env();
        let chrome = match cfg.backend {
            BackendKind::Simulated => None,
            BackendKind::Chromium => Some(Box::new(ChromiumBackend::launch(&chrome_opts)?)),
        };
        let site = Website::build(
            &pool[0],
            &mut RngStream::new(0, "placeholder"),
            Vocabulary::standard(),
        );
        Ok(Self {
            spec,
            rng: RngStream::new(cfg.seed, "web-episodes"),
            cfg,
            pool,
            site,
            pool_index: 0,
            state: DomState::default(),
            prev: DomState::default(),
            was_visible: Vec::new(),
            potential: 0.0,
            steps: 0,
            active: false,
            done: false,
            chrome,
            chrome_opts,
            restarts: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &WebNavConfig {
        &self.cfg
    }

    /// The website pool.
    pub fn pool(&self) -> &[Design] {
        &self.pool
    }

    /// The current episode's website.
    pub fn website(&self) -> &Website {
        &self.site
    }

    /// Index in the pool of the current episode's website.
    pub fn pool_index(&self) -> usize {
        self.pool_index
    }

    /// The current DOM state.
    pub fn dom(&self) -> &DomState {
        &self.state
    }

    /// How often the browser was restarted after dying.
    pub fn browser_restarts(&self) -> u64 {
        self.restarts
    }

    /// The Chromium backend, if this environment uses it.
    pub fn chromium(&mut self) -> Option<&mut ChromiumBackend> {
        self.chrome.as_deref_mut()
    }

    /// Flat action index of (element slot, field, kind 0 = click / 1 = type).
    pub fn action_index(&self, element: usize, field: usize, kind: usize) -> usize {
        (element * self.cfg.num_fields + field) * 2 + kind
    }

    /// Decodes a flat action into (element slot, field, kind).
    pub fn decode_action(&self, a: usize) -> (usize, usize, usize) {
        let kind = a % 2;
        let field = (a / 2) % self.cfg.num_fields;
        (a / (2 * self.cfg.num_fields), field, kind)
    }

    /// Whether flat action `a` is legal now: the element slot holds a visible element; clicks
    /// use field 0 only (the field is irrelevant to a click); typing needs a control (input or
    /// select) and a present profile field.
    pub fn is_legal(&self, a: usize) -> bool {
        if a >= self.cfg.num_elements * self.cfg.num_fields * 2 {
            return false;
        }
        let (e, f, kind) = self.decode_action(a);
        let Some(&node) = self.state.order.get(e) else {
            return false;
        };
        if kind == 0 {
            f == 0
        } else {
            f < self.site.fields.len().min(self.cfg.num_fields)
                && self.site.nodes[node as usize].tag.is_control()
        }
    }

    /// The action an optimal agent takes now (privileged: reads the website model): type the
    /// gold value into the first unfinished field of the page, else click next/submit.
    pub fn oracle_action(&self) -> Option<usize> {
        if !self.active || self.done {
            return None;
        }
        let visible = self
            .state
            .order
            .iter()
            .take(self.cfg.num_elements)
            .enumerate();
        for (slot, &n) in visible.clone() {
            let node = &self.site.nodes[n as usize];
            if let Some(f) = node.field {
                let f = usize::from(f);
                if f < self.cfg.num_fields
                    && !(self.state.field_correct(&self.site, f)
                        && self.state.field_visited(&self.site, f))
                {
                    return Some(self.action_index(slot, f, 1));
                }
            }
        }
        for (slot, &n) in visible {
            match self.site.nodes[n as usize].behaviour {
                Behaviour::Next(p) if p == self.state.page => {
                    return Some(self.action_index(slot, 0, 0));
                }
                Behaviour::Submit => return Some(self.action_index(slot, 0, 0)),
                _ => {}
            }
        }
        None
    }

    fn write_observation(&mut self, obs: &mut Observation) {
        let (f, e, t) = (
            self.cfg.num_fields,
            self.cfg.num_elements,
            self.cfg.num_tokens,
        );
        let names = [
            "profile_keys",
            "profile_values",
            "profile_mask",
            "dom_tokens",
            "dom_features",
            "dom_mask",
        ];
        let shapes: [&[usize]; 6] = [
            &[f, t],
            &[f, t],
            &[f],
            &[e, DOM_ATTRIBUTES, t],
            &[e, DOM_FEATURES],
            &[e],
        ];
        let fits = obs.tensors.len() == 6
            && obs
                .tensors
                .iter()
                .zip(names.iter().zip(shapes.iter()))
                .all(|(tn, (n, s))| tn.name == *n && tn.shape == *s);
        if !fits {
            obs.tensors = names
                .iter()
                .zip(shapes.iter())
                .map(|(n, s)| Tensor::zeros(n, s))
                .collect();
        }
        let [pk, pv, pm, dt, df, dm] = &mut obs.tensors[..] else {
            return;
        };
        fn put(dst: &mut [f32], src: &[u32]) {
            for (i, d) in dst.iter_mut().enumerate() {
                *d = src.get(i).map_or(0.0, |&x| x as f32);
            }
        }
        for k in 0..f {
            let (keys, vals) = (
                &mut pk.data[k * t..(k + 1) * t],
                &mut pv.data[k * t..(k + 1) * t],
            );
            match self.site.profile_tokens.get(k) {
                Some((ka, va)) => {
                    put(keys, ka);
                    put(vals, va);
                    pm.data[k] = 1.0;
                }
                None => {
                    put(keys, &[]);
                    put(vals, &[]);
                    pm.data[k] = 0.0;
                }
            }
        }
        let (mut max_w, mut max_h) = (1.0f32, 1.0f32);
        for &n in &self.state.order {
            let r = self.state.rect[n as usize];
            max_w = max_w.max(r[0] + r[2]);
            max_h = max_h.max(r[1] + r[3]);
        }
        let shown = self.state.order.len().min(e);
        for slot in 0..e {
            let toks = &mut dt.data[slot * DOM_ATTRIBUTES * t..(slot + 1) * DOM_ATTRIBUTES * t];
            let feats = &mut df.data[slot * DOM_FEATURES..(slot + 1) * DOM_FEATURES];
            if slot >= shown {
                toks.iter_mut().for_each(|x| *x = 0.0);
                feats.iter_mut().for_each(|x| *x = 0.0);
                dm.data[slot] = 0.0;
                continue;
            }
            let n = self.state.order[slot] as usize;
            let nt = &self.site.tokens[n];
            let visited = self.state.visited[n];
            let value = self.state.value_id(&self.site, n) as usize;
            put(&mut toks[0..t], &nt.tag);
            put(&mut toks[t..2 * t], &self.site.string_tokens[value]);
            put(&mut toks[2 * t..3 * t], &nt.text);
            put(&mut toks[3 * t..4 * t], &nt.placeholder);
            put(&mut toks[4 * t..5 * t], &nt.classes[usize::from(visited)]);
            let r = self.state.rect[n];
            feats[0] = f32::from(u8::from(self.state.focused == Some(n as u32)));
            feats[1] = f32::from(u8::from(visited));
            feats[2] = f32::from(u8::from(!self.was_visible[n]));
            feats[3] = f32::from(u8::from(self.site.nodes[n].tag == Tag::Div));
            feats[4] = r[0] / max_w;
            feats[5] = r[1] / max_h;
            feats[6] = r[2] / max_w;
            feats[7] = r[3] / max_h;
            dm.data[slot] = 1.0;
        }
        self.was_visible.clone_from(&self.state.visible);
        let n_actions = e * f * 2;
        let mask = obs.action_mask.get_or_insert_with(Vec::new);
        mask.clear();
        mask.resize(n_actions, false);
        let fields = self.site.fields.len().min(f);
        for slot in 0..shown {
            mask[(slot * f) * 2] = true;
            let n = self.state.order[slot] as usize;
            if self.site.nodes[n].tag.is_control() {
                for k in 0..fields {
                    mask[(slot * f + k) * 2 + 1] = true;
                }
            }
        }
    }

    fn relaunch(&mut self) -> Result<(), WebError> {
        if let Some(c) = self.chrome.as_deref_mut() {
            c.shutdown();
        }
        self.chrome = Some(Box::new(ChromiumBackend::launch(&self.chrome_opts)?));
        self.restarts += 1;
        Ok(())
    }

    fn load_in_browser(&mut self) -> Result<(), WebError> {
        let Some(chrome) = self.chrome.as_deref_mut() else {
            return Ok(());
        };
        match chrome.load(&mut self.site, &mut self.state) {
            Ok(()) => Ok(()),
            Err(e) if e.is_browser_death() => {
                self.relaunch()?;
                match self.chrome.as_deref_mut() {
                    Some(c) => c.load(&mut self.site, &mut self.state),
                    None => Err(e),
                }
            }
            Err(e) => Err(e),
        }
    }
}

fn pool_hash(pool: &[Design]) -> u64 {
    // FNV-1a over the canonical JSON, so the hash is stable across builds and platforms.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for d in pool {
        for b in d.to_a2perf_json().to_string().bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01B3);
        }
    }
    h
}

const INFO_KEYS: [&str; 5] = [
    "success",
    "distractor",
    "interrupted",
    "potential",
    "pool_index",
];

fn set_info(step: &mut Step, values: [f64; 5]) {
    let ours = step
        .info
        .iter()
        .map(|(k, _)| k)
        .eq(INFO_KEYS.iter().copied());
    if !ours {
        step.info.clear();
    }
    for (k, v) in INFO_KEYS.iter().zip(values) {
        step.info.set(k, v);
    }
}

impl Env for WebNavEnv {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        if let Some(s) = seed {
            self.rng = RngStream::new(s, "web-episodes");
        }
        let index = self.rng.index(self.pool.len());
        self.start_episode(index, obs)
    }

    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        self.step_impl(action, out)
    }

    fn close(&mut self) -> Result<(), EnvError> {
        if let Some(c) = self.chrome.as_deref_mut() {
            c.shutdown();
        }
        self.chrome = None;
        Ok(())
    }
}

impl WebNavEnv {
    /// Starts an episode on pool website `index` (instead of a random one), with the episode's
    /// random content drawn from `seed`.
    pub fn reset_to_website(
        &mut self,
        index: usize,
        seed: u64,
        obs: &mut Observation,
    ) -> Result<(), EnvError> {
        if index >= self.pool.len() {
            return Err(EnvError::InvalidParameter {
                name: "index".into(),
                reason: format!("pool has {} websites", self.pool.len()),
            });
        }
        self.rng = RngStream::new(seed, "web-episodes");
        self.start_episode(index, obs)
    }

    fn start_episode(&mut self, index: usize, obs: &mut Observation) -> Result<(), EnvError> {
        self.pool_index = index;
        self.site = Website::build(
            &self.pool[self.pool_index],
            &mut self.rng,
            Vocabulary::standard(),
        );
        self.state.reset(&self.site);
        self.load_in_browser()?;
        self.prev.copy_from(&self.state);
        self.was_visible.clear();
        self.was_visible.resize(self.site.nodes.len(), false);
        self.potential = self.state.potential(&self.site);
        self.steps = 0;
        self.active = true;
        self.done = false;
        self.write_observation(obs);
        Ok(())
    }

    fn step_impl(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        if !self.active || self.done {
            return Err(EnvError::NeedsReset);
        }
        let a = match action {
            Action::Discrete(a) => *a,
            Action::Continuous(_) => {
                return Err(EnvError::InvalidAction {
                    action: action.clone(),
                    reason: "expected a discrete action".into(),
                });
            }
        };
        if !self.is_legal(a) {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "masked out (no such element, click with field > 0, or typing into a \
                         non-input / absent field)"
                    .into(),
            });
        }
        let (slot, field, kind) = self.decode_action(a);
        let node = self.state.order[slot] as usize;
        let kind = if kind == 0 {
            ActionKind::Click
        } else {
            ActionKind::Type(self.site.fields[field].value_id)
        };
        self.prev.copy_from(&self.state);
        let event_before = self.state.event;
        match self.chrome.as_deref_mut() {
            None => self.state.apply(&self.site, node, kind),
            Some(chrome) => {
                if let Err(e) = chrome.step(&mut self.site, &mut self.state, node, kind) {
                    if !e.is_browser_death() {
                        return Err(e.into());
                    }
                    // The episode cannot continue: restart the browser, report an interrupted
                    // (truncated) episode with the last good observation.
                    self.relaunch()?;
                    self.state.copy_from(&self.prev);
                    self.done = true;
                    self.steps += 1;
                    out.reward = 0.0;
                    out.terminated = false;
                    out.truncated = true;
                    self.write_observation(&mut out.observation);
                    set_info(out, [0.0, 0.0, 1.0, self.potential, self.pool_index as f64]);
                    return Ok(());
                }
            }
        }
        self.steps += 1;
        let new_event = if event_before == Event::None {
            self.state.event
        } else {
            Event::None
        };
        let phi = self.state.potential(&self.site);
        let mut reward = phi - self.potential;
        self.potential = phi;
        let (mut success, mut distractor) = (0.0, 0.0);
        let terminated = match new_event {
            Event::Distractor => {
                reward -= 1.0;
                distractor = 1.0;
                true
            }
            Event::Submit => {
                if self.state.all_correct(&self.site) {
                    reward += 1.0;
                    success = 1.0;
                } else {
                    reward -= 1.0;
                }
                true
            }
            Event::None => {
                reward -= TIMESTEP_PENALTY;
                if self.state.same_view(&self.prev) {
                    reward -= NO_CHANGE_PENALTY;
                }
                false
            }
        };
        let truncated = !terminated && self.steps >= self.cfg.step_limit;
        self.done = terminated || truncated;
        out.reward = reward;
        out.terminated = terminated;
        out.truncated = truncated;
        self.write_observation(&mut out.observation);
        set_info(out, [success, distractor, 0.0, phi, self.pool_index as f64]);
        Ok(())
    }
}

//! The web-navigation environment (`WebNavigation-Difficulty-0N-v0`).
//!
//! Rendering: [`Env::render`] with `"html"` returns the current page as a standalone HTML
//! document ([`Website::state_html`] of the episode's website and DOM state), with either
//! backend: under Chromium the state is the one the browser reported after the last step, so
//! rendering costs no browser round trip.

use std::collections::BTreeMap;
use std::path::PathBuf;

use a2perf_core::{
    Action, DType, Env, EnvError, EnvSpec, Frame, Observation, RngStream, Space, Step, Tensor,
};

use crate::chromium::{ChromiumBackend, ChromiumOptions};
use crate::design::{Design, load_designs};
use crate::dom::{ActionKind, DomState, Event, Quirks};
use crate::error::WebError;
use crate::generator::{Limits, check_solvable, generate};
use crate::legacy_random::a2perf_pool_indices;
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
/// Observation field of the website's first profile field: field 0 is A2Perf's `_dummy`
/// (present, key `_dummy`, no value), which A2Perf adds so that a profile is never empty.
pub const FIELD_OFFSET: usize = 1;

/// Which browser runs the pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendKind {
    /// The in-process DOM model.
    Simulated,
    /// Headless Chromium through chromedriver.
    Chromium,
}

/// Where the website pool comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoolKind {
    /// Websites of the id's level that an optimal agent can finish within the limits: from the
    /// generator, or from `designs_file` filtered by recomputed level and solvability.
    Generated,
    /// A2Perf's design file (`designs_file`, required) as it is, unfiltered, with the original's
    /// seeded draw: the same designs as A2Perf's `WebNavigationEnv` for the same seed.
    A2Perf,
}

/// How actions act on the page.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActionSemantics {
    /// A user's click or typing; only meaningful actions are legal (the mask) and an illegal one
    /// is an error.
    Masked,
    /// A2Perf's `visitGroup` (see [`ActionKind::Visit`]): kind 1 with field f ≥ 1 acts with that
    /// field's value, every other action with none; every (element, field ≤ fields) pair is in
    /// the mask for both kinds, as in the original network's joint mask; any action of the space
    /// is accepted, and one naming no element repeats the previous step's reward − 0.55 (the
    /// original's stale `current_reward`).
    A2Perf,
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
    /// Profile fields in the observation (F), field 0 being A2Perf's `_dummy`.
    pub num_fields: usize,
    /// Elements in the observation (E).
    pub num_elements: usize,
    /// Tokens per attribute (T).
    pub num_tokens: usize,
    /// Episode step limit.
    pub step_limit: usize,
    /// An A2Perf design file: with [`PoolKind::Generated`] the pool is drawn from its designs of
    /// the id's recomputed level that are solvable within the limits; with [`PoolKind::A2Perf`]
    /// from all of them.
    pub designs_file: Option<PathBuf>,
    /// Where the pool comes from.
    pub pool: PoolKind,
    /// Reproduce A2Perf's unselectable `cc` radio group (see [`Quirks::cc_bug`]).
    pub cc_bug: bool,
    /// Render an active primitive repeated on a later page, as A2Perf did (see
    /// [`Quirks::duplicate_fields`]).
    pub duplicate_fields: bool,
    /// Fill the observation's placeholder slot from the element's `placeholder` (A2Perf's is
    /// always empty: its patched MiniWoB reads a key the page never sends).
    pub placeholders: bool,
    /// At the step limit, report `terminated` as well as `truncated` (A2Perf's
    /// `terminated = done or truncated`).
    pub limit_terminates: bool,
    /// How actions act on the page.
    pub actions: ActionSemantics,
}

impl WebNavConfig {
    /// Defaults for `difficulty` (10 websites, seed 0, simulated backend, A2Perf's sizes and
    /// step limit, generated pool, corrected behaviour).
    ///
    /// ```
    /// let c = a2perf_web::WebNavConfig::new(2);
    /// assert_eq!((c.num_fields, c.num_elements, c.num_tokens, c.step_limit), (25, 250, 10, 25));
    /// assert!(!c.cc_bug && c.placeholders);
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
            pool: PoolKind::Generated,
            cc_bug: false,
            duplicate_fields: false,
            placeholders: true,
            limit_terminates: false,
            actions: ActionSemantics::Masked,
        }
    }

    /// The original's environment for `difficulty`: A2Perf's design file `designs_file` as it
    /// is, and every switch that reproduces a behaviour of the original turned on.
    ///
    /// ```
    /// let c = a2perf_web::WebNavConfig::a2perf(1, "01.json".into());
    /// assert_eq!(c.pool, a2perf_web::PoolKind::A2Perf);
    /// assert!(c.cc_bug && !c.placeholders && c.limit_terminates);
    /// ```
    pub fn a2perf(difficulty: u8, designs_file: PathBuf) -> Self {
        Self {
            designs_file: Some(designs_file),
            pool: PoolKind::A2Perf,
            cc_bug: true,
            duplicate_fields: true,
            placeholders: false,
            limit_terminates: true,
            actions: ActionSemantics::A2Perf,
            ..Self::new(difficulty)
        }
    }

    /// The generator limits implied by the observation sizes (one profile slot is `_dummy`).
    pub fn limits(&self) -> Limits {
        Limits {
            step_limit: self.step_limit,
            max_elements: self.num_elements,
            max_fields: self.num_fields.saturating_sub(FIELD_OFFSET),
        }
    }

    /// The page behaviours of the original this configuration reproduces.
    pub fn quirks(&self) -> Quirks {
        Quirks {
            cc_bug: self.cc_bug,
            duplicate_fields: self.duplicate_fields,
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
        if self.num_fields < 2 || self.num_fields > 1000 {
            return bad(
                "num_fields",
                "must be in 2..=1000 (field 0 is A2Perf's `_dummy`)",
            );
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
        self.pool_from_source().map(|(pool, _)| pool)
    }

    /// The pool and, when it comes from a design file, each design's index in that file.
    pub fn pool_from_source(&self) -> Result<(Vec<Design>, Option<Vec<usize>>), WebError> {
        self.validate()?;
        let limits = self.limits();
        let Some(path) = &self.designs_file else {
            if self.pool == PoolKind::A2Perf {
                return Err(WebError::Config {
                    name: "designs".into(),
                    reason: "pool = \"a2perf\" plays A2Perf's design files as they are: give the \
                             path of the original's 01.json, 02.json or 03.json (this program \
                             ships no third-party data)"
                        .into(),
                });
            }
            let pool = generate(self.difficulty, self.seed, self.num_websites, &limits)
                .into_iter()
                .map(|g| g.design)
                .collect();
            return Ok((pool, None));
        };
        let file = path.display().to_string();
        let all = load_designs(path)?;
        let picked: Vec<usize> = match self.pool {
            PoolKind::A2Perf => {
                if self.seed > u64::from(u32::MAX) {
                    return Err(WebError::Config {
                        name: "seed".into(),
                        reason: format!(
                            "{}: pool = \"a2perf\" draws like numpy's RandomState, whose seed \
                             must be below 2^32",
                            self.seed
                        ),
                    });
                }
                a2perf_pool_indices(self.seed, all.len(), self.num_websites).ok_or_else(|| {
                    WebError::BadFile {
                        path: file.clone(),
                        reason: format!(
                            "{} designs, {} websites requested",
                            all.len(),
                            self.num_websites
                        ),
                    }
                })?
            }
            PoolKind::Generated => {
                let mut ok: Vec<usize> = (0..all.len())
                    .filter(|&i| {
                        all[i].level() == Some(self.difficulty)
                            && check_solvable(&all[i], &limits).is_ok()
                    })
                    .collect();
                if ok.len() < self.num_websites {
                    return Err(WebError::BadFile {
                        path: file,
                        reason: format!(
                            "only {} designs are solvable and of level {} (recomputed), {} \
                             requested (pool = \"a2perf\" plays the file as it is)",
                            ok.len(),
                            self.difficulty,
                            self.num_websites
                        ),
                    });
                }
                // A seeded choice without replacement.
                let mut rng = RngStream::new(self.seed, "web-design-file-pool");
                rng.shuffle(&mut ok);
                ok.truncate(self.num_websites);
                ok
            }
        };
        let pool: Vec<Design> = picked.iter().map(|&i| all[i].clone()).collect();
        // Unfiltered designs must still fit the observation's profile (the original crashed).
        for (&i, d) in picked.iter().zip(&pool) {
            let fields = d.unique_active().len();
            if fields > limits.max_fields {
                return Err(WebError::BadFile {
                    path: file,
                    reason: format!(
                        "design {i} has {fields} profile fields; the observation holds {} \
                         (num_fields − 1, field 0 being `_dummy`)",
                        limits.max_fields
                    ),
                });
            }
        }
        Ok((pool, Some(picked)))
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
    /// The last step's reward (A2Perf's `current_reward`, repeated by a stale step).
    last_reward: f64,
    steps: usize,
    active: bool,
    done: bool,
    /// Tokens of the `_dummy` key.
    dummy_key: Vec<u32>,
    chrome: Option<Box<ChromiumBackend>>,
    chrome_opts: ChromiumOptions,
    restarts: u64,
}

fn box_space(shape: &[usize], high: f32) -> Space {
    Space::uniform_box(shape, 0.0, high)
}

/// A box of token ids (int32 as in A2Perf, `0..=last_id`).
fn token_space(shape: &[usize], last_id: f64) -> Space {
    Space::uniform_box_of(shape, DType::I32, 0.0, last_id)
}

impl WebNavEnv {
    /// Builds the environment from a configuration (launching Chromium for that backend).
    pub fn new(cfg: WebNavConfig) -> Result<Self, WebError> {
        let (pool, indices) = cfg.pool_from_source()?;
        let id = crate::env_id(cfg.difficulty);
        let mut env = Self::with_pool(pool, cfg, &id)?;
        if let Some(idx) = indices {
            let list: Vec<String> = idx.iter().map(usize::to_string).collect();
            env.spec
                .metadata
                .insert("pool_indices".into(), list.join(","));
        }
        Ok(env)
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
        let v = (vocab_size() - 1) as f64;
        let observation_space = Space::Dict(vec![
            ("profile_keys".into(), token_space(&[f, t], v)),
            ("profile_values".into(), token_space(&[f, t], v)),
            ("profile_mask".into(), box_space(&[f], 1.0)),
            ("dom_tokens".into(), token_space(&[e, DOM_ATTRIBUTES, t], v)),
            ("dom_features".into(), box_space(&[e, DOM_FEATURES], 1.0)),
            ("dom_mask".into(), box_space(&[e], 1.0)),
            ("time_step".into(), box_space(&[1], 1.0)),
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
        let flag = |b: bool| if b { "true" } else { "false" }.to_string();
        metadata.insert(
            "pool".into(),
            match cfg.pool {
                PoolKind::Generated => "generated",
                PoolKind::A2Perf => "a2perf",
            }
            .into(),
        );
        metadata.insert("cc_bug".into(), flag(cfg.cc_bug));
        metadata.insert("duplicate_fields".into(), flag(cfg.duplicate_fields));
        metadata.insert("placeholders".into(), flag(cfg.placeholders));
        metadata.insert("limit_terminates".into(), flag(cfg.limit_terminates));
        let (actions, layout) = match cfg.actions {
            ActionSemantics::Masked => (
                "masked",
                "(element*F+field)*2+kind; field 0 is _dummy; kind 0 click (field 0 only), \
                 1 type field value (field >= 1)",
            ),
            ActionSemantics::A2Perf => (
                "a2perf",
                "(element*F+field)*2+kind; field 0 is _dummy; A2Perf's visitGroup with field \
                 value (kind 1, field >= 1) or none (other); A2Perf index = (1-kind)*F*E + \
                 field*E + element",
            ),
        };
        metadata.insert("actions".into(), actions.into());
        metadata.insert("action_layout".into(), layout.into());
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
            last_reward: 0.0,
            steps: 0,
            active: false,
            done: false,
            dummy_key: Vocabulary::standard().encode("_dummy"),
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

    /// Steps taken in the current episode.
    pub fn steps(&self) -> usize {
        self.steps
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

    /// The index of flat action `a` in the original's layout, `type·F·E + field·E + element`,
    /// where A2Perf's type 0 acts with the field's value and type 1 with none (our kind 1 and 0).
    ///
    /// ```
    /// let env = a2perf_web::WebNavEnv::new(a2perf_web::WebNavConfig::new(1)).unwrap();
    /// let ours = env.action_index(7, 3, 1); // type field 3 into element 7
    /// assert_eq!(env.a2perf_action(ours), 3 * 250 + 7);
    /// assert_eq!(env.from_a2perf_action(3 * 250 + 7), Some(ours));
    /// ```
    pub fn a2perf_action(&self, a: usize) -> usize {
        let (e, f, kind) = self.decode_action(a);
        (1 - kind) * self.cfg.num_fields * self.cfg.num_elements + f * self.cfg.num_elements + e
    }

    /// The flat action of the original's index `a` (inverse of [`Self::a2perf_action`]); `None`
    /// outside the action space.
    pub fn from_a2perf_action(&self, a: usize) -> Option<usize> {
        let (f, e) = (self.cfg.num_fields, self.cfg.num_elements);
        (a < 2 * f * e).then(|| self.action_index(a % e, (a / e) % f, 1 - a / (f * e)))
    }

    /// Number of elements the observation shows now.
    fn shown(&self) -> usize {
        self.state.order.len().min(self.cfg.num_elements)
    }

    /// Whether flat action `a` is in the mask now. [`ActionSemantics::Masked`]: the element
    /// slot holds a visible element; clicks use field 0 (`_dummy`) only; typing needs a control
    /// (input or select) and a present profile field (≥ 1). [`ActionSemantics::A2Perf`]: the
    /// original network's joint mask, a visible element and a present field (`_dummy`
    /// included), both kinds.
    pub fn is_legal(&self, a: usize) -> bool {
        if a >= self.cfg.num_elements * self.cfg.num_fields * 2 {
            return false;
        }
        let (e, f, kind) = self.decode_action(a);
        if e >= self.shown() {
            return false;
        }
        let fields = self.site.fields.len() + FIELD_OFFSET;
        match self.cfg.actions {
            ActionSemantics::A2Perf => f < fields,
            ActionSemantics::Masked if kind == 0 => f == 0,
            ActionSemantics::Masked => {
                (FIELD_OFFSET..fields).contains(&f)
                    && self.site.nodes[self.state.order[e] as usize]
                        .tag
                        .is_control()
            }
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
                if f + FIELD_OFFSET < self.cfg.num_fields
                    && !(self.state.field_correct(&self.site, f)
                        && self.state.field_visited(&self.site, f))
                {
                    return Some(self.action_index(slot, f + FIELD_OFFSET, 1));
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
            "time_step",
        ];
        let shapes: [&[usize]; 7] = [
            &[f, t],
            &[f, t],
            &[f],
            &[e, DOM_ATTRIBUTES, t],
            &[e, DOM_FEATURES],
            &[e],
            &[1],
        ];
        use DType::{F32, I32};
        let dtypes = [I32, I32, F32, I32, F32, F32, F32];
        let fits = obs.tensors.len() == names.len()
            && obs
                .tensors
                .iter()
                .zip(names.iter().zip(shapes.iter()).zip(dtypes))
                .all(|(tn, ((n, s), d))| tn.name == *n && tn.shape == *s && tn.dtype() == d);
        if !fits {
            obs.tensors = names
                .iter()
                .zip(shapes.iter())
                .zip(dtypes)
                .map(|((n, s), d)| Tensor::zeros_of(n, s, d))
                .collect();
        }
        let [pk, pv, pm, dt, df, dm, ts] = &mut obs.tensors[..] else {
            return;
        };
        // Every slot has its type (checked or rebuilt just above).
        let (Some(pk), Some(pv), Some(pm), Some(dt), Some(df), Some(dm), Some(ts)) = (
            pk.data.as_i32_mut(),
            pv.data.as_i32_mut(),
            pm.data.as_f32_mut(),
            dt.data.as_i32_mut(),
            df.data.as_f32_mut(),
            dm.data.as_f32_mut(),
            ts.data.as_f32_mut(),
        ) else {
            return;
        };
        fn put(dst: &mut [i32], src: &[u32]) {
            for (i, d) in dst.iter_mut().enumerate() {
                // Ids are below the vocabulary size (15 000), far inside int32.
                *d = src.get(i).map_or(0, |&x| x as i32);
            }
        }
        for k in 0..f {
            let (keys, vals) = (&mut pk[k * t..(k + 1) * t], &mut pv[k * t..(k + 1) * t]);
            // `_dummy`'s value is None, which the original's tokenizer maps to no token.
            let field = match k.checked_sub(FIELD_OFFSET) {
                None => Some((self.dummy_key.as_slice(), &[][..])),
                Some(j) => self
                    .site
                    .profile_tokens
                    .get(j)
                    .map(|(ka, va)| (ka.as_slice(), va.as_slice())),
            };
            let (ka, va) = field.unwrap_or((&[], &[]));
            put(keys, ka);
            put(vals, va);
            pm[k] = f32::from(u8::from(field.is_some()));
        }
        // A2Perf: `float(num_steps) / float(step_limit)`.
        ts[0] = self.steps as f32 / self.cfg.step_limit as f32;
        let (mut max_w, mut max_h) = (1.0f32, 1.0f32);
        for &n in &self.state.order {
            let r = self.state.rect[n as usize];
            max_w = max_w.max(r[0] + r[2]);
            max_h = max_h.max(r[1] + r[3]);
        }
        let shown = self.shown();
        for slot in 0..e {
            let toks = &mut dt[slot * DOM_ATTRIBUTES * t..(slot + 1) * DOM_ATTRIBUTES * t];
            let feats = &mut df[slot * DOM_FEATURES..(slot + 1) * DOM_FEATURES];
            if slot >= shown {
                toks.iter_mut().for_each(|x| *x = 0);
                feats.iter_mut().for_each(|x| *x = 0.0);
                dm[slot] = 0.0;
                continue;
            }
            let n = self.state.order[slot] as usize;
            let nt = &self.site.tokens[n];
            let visited = self.state.visited[n];
            let value = self.state.value_id(&self.site, n) as usize;
            let placeholder: &[u32] = if self.cfg.placeholders {
                &nt.placeholder
            } else {
                &[]
            };
            put(&mut toks[0..t], &nt.tag);
            put(&mut toks[t..2 * t], &self.site.string_tokens[value]);
            put(&mut toks[2 * t..3 * t], &nt.text);
            put(&mut toks[3 * t..4 * t], placeholder);
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
            dm[slot] = 1.0;
        }
        self.was_visible.clone_from(&self.state.visible);
        let n_actions = e * f * 2;
        let mask = obs.action_mask.get_or_insert_with(Vec::new);
        mask.clear();
        mask.resize(n_actions, false);
        let fields = (self.site.fields.len() + FIELD_OFFSET).min(f);
        for slot in 0..shown {
            match self.cfg.actions {
                ActionSemantics::Masked => {
                    mask[(slot * f) * 2] = true;
                    let n = self.state.order[slot] as usize;
                    if self.site.nodes[n].tag.is_control() {
                        for k in FIELD_OFFSET..fields {
                            mask[(slot * f + k) * 2 + 1] = true;
                        }
                    }
                }
                ActionSemantics::A2Perf => {
                    mask[slot * f * 2..(slot * f + fields) * 2].fill(true);
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
    let mut h = a2perf_core::hash::Fnv1a::new();
    for d in pool {
        h.write(d.to_a2perf_json().to_string().as_bytes());
    }
    h.finish()
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

    fn render_modes(&self) -> &'static [&'static str] {
        &["html"]
    }

    /// `"html"`: the current page ([`Website::state_html`]); before the first reset, the first
    /// website of the pool as it starts.
    fn render(&mut self, mode: &str) -> Result<Frame, EnvError> {
        if mode != "html" {
            return Err(EnvError::unsupported_render_mode(mode, self.render_modes()));
        }
        Ok(Frame::Text(self.site.state_html(&self.state)))
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
        self.site = Website::build_with(
            &self.pool[self.pool_index],
            &mut self.rng,
            Vocabulary::standard(),
            self.cfg.quirks(),
        );
        self.state.reset(&self.site);
        self.load_in_browser()?;
        self.prev.copy_from(&self.state);
        self.was_visible.clear();
        self.was_visible.resize(self.site.nodes.len(), false);
        self.potential = self.state.potential(&self.site);
        self.last_reward = 0.0;
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
        let n_actions = self.cfg.num_elements * self.cfg.num_fields * 2;
        let a2perf = self.cfg.actions == ActionSemantics::A2Perf;
        if !(self.is_legal(a) || a2perf && a < n_actions) {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: if a >= n_actions {
                    format!("outside Discrete({n_actions})")
                } else {
                    "masked out (no such element, click with field > 0, or typing into a \
                     non-input / absent field)"
                        .into()
                },
            });
        }
        let (slot, field, kind) = self.decode_action(a);
        if slot >= self.shown() {
            // Only A2Perf's semantics get here: the original looked the element up, found none
            // and returned early, leaving the page and `current_reward` as they were.
            self.stale_step(out);
            return Ok(());
        }
        let node = self.state.order[slot] as usize;
        let value = field
            .checked_sub(FIELD_OFFSET)
            .and_then(|f| self.site.fields.get(f))
            .map(|f| f.value_id)
            .filter(|_| kind == 1);
        let kind = match (self.cfg.actions, value) {
            (ActionSemantics::A2Perf, v) => ActionKind::Visit(v),
            (ActionSemantics::Masked, Some(v)) => ActionKind::Type(v),
            (ActionSemantics::Masked, None) => ActionKind::Click,
        };
        let quirks = self.cfg.quirks();
        self.prev.copy_from(&self.state);
        let event_before = self.state.event;
        match self.chrome.as_deref_mut() {
            None => self.state.apply(&self.site, node, kind, quirks),
            Some(chrome) => {
                if let Err(e) = chrome.step(&mut self.site, &mut self.state, node, kind, quirks) {
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
        self.finish_step(out, reward, terminated, [success, distractor, 0.0, phi]);
        Ok(())
    }

    /// A step that changed nothing and repeats the previous step's reward − 0.55 (A2Perf's
    /// early return for an element index beyond the page's elements).
    fn stale_step(&mut self, out: &mut Step) {
        self.steps += 1;
        // The page is unchanged: ΔΦ = 0, no event, and the diff is empty.
        let reward = self.last_reward - NO_CHANGE_PENALTY - TIMESTEP_PENALTY;
        self.finish_step(out, reward, false, [0.0, 0.0, 0.0, self.potential]);
    }

    /// Termination flags, the observation and info of a step whose reward is known.
    fn finish_step(&mut self, out: &mut Step, reward: f64, event: bool, info: [f64; 4]) {
        let at_limit = self.steps >= self.cfg.step_limit;
        // A2Perf: `truncated = num_steps >= step_limit; terminated = done or truncated`.
        let (terminated, truncated) = if self.cfg.limit_terminates {
            (event || at_limit, at_limit)
        } else {
            (event, !event && at_limit)
        };
        self.done = terminated || truncated;
        self.last_reward = reward;
        out.reward = reward;
        out.terminated = terminated;
        out.truncated = truncated;
        self.write_observation(&mut out.observation);
        let [success, distractor, interrupted, phi] = info;
        set_info(
            out,
            [
                success,
                distractor,
                interrupted,
                phi,
                self.pool_index as f64,
            ],
        );
    }
}

#[cfg(test)]
mod tests {
    use a2perf_core::{Action, Env, EnvError, Frame, Observation, Step};

    use super::*;

    fn html(env: &mut WebNavEnv) -> String {
        match env.render("html").unwrap() {
            Frame::Text(t) => t,
            Frame::Rgb { .. } => panic!("html is text"),
        }
    }

    /// An episode of oracle actions (with a random legal click every third step) from `seed`;
    /// the page after the reset and after every step.
    fn pages(difficulty: u8, seed: u64) -> Vec<String> {
        let mut env = WebNavEnv::new(WebNavConfig::new(difficulty)).unwrap();
        let mut obs = Observation::default();
        env.reset_into(Some(seed), &mut obs).unwrap();
        let mut out = vec![html(&mut env)];
        let mut step = Step::default();
        let mut rng = RngStream::new(seed, "test/render");
        for t in 0..STEP_LIMIT {
            let mask = obs.action_mask.clone().unwrap();
            let a = match env.oracle_action() {
                Some(a) if t % 3 != 2 => a,
                _ => {
                    let clicks: Vec<usize> =
                        (0..mask.len()).step_by(2).filter(|&i| mask[i]).collect();
                    clicks[rng.index(clicks.len())]
                }
            };
            env.step_into(&Action::Discrete(a), &mut step).unwrap();
            out.push(html(&mut env));
            if step.done() {
                break;
            }
            obs.copy_from(&step.observation);
        }
        out
    }

    #[test]
    fn the_page_starts_as_the_website_and_follows_the_episode() {
        let mut env = WebNavEnv::new(WebNavConfig::new(2)).unwrap();
        // Before any reset: the first website of the pool as it starts.
        assert!(html(&mut env).starts_with("<!DOCTYPE html>"));
        let mut obs = Observation::default();
        for seed in 0..10 {
            env.reset_into(Some(seed), &mut obs).unwrap();
            assert_eq!(html(&mut env), env.website().to_html(false), "seed {seed}");
        }
        let mut changed = 0;
        for seed in 0..6 {
            let p = pages(1 + (seed % 3) as u8, seed);
            assert_eq!(p, pages(1 + (seed % 3) as u8, seed), "deterministic");
            changed += p.windows(2).filter(|w| w[0] != w[1]).count();
            assert!(
                p.iter().skip(1).any(|h| h.contains("visited")),
                "seed {seed}"
            );
        }
        assert!(changed > 10);
    }

    #[test]
    fn a_state_read_back_from_chromium_renders_the_same() {
        // Chromium reports what is displayed (`visible`) but not the own `display: none` flags,
        // which stay as the reset left them, nor the `visited` class of elements that are not
        // displayed and not controls, which stays as last seen: the page depends on neither.
        let mut differed = 0;
        for seed in 0..20 {
            let mut env = WebNavEnv::new(WebNavConfig::new(3)).unwrap();
            let mut obs = Observation::default();
            env.reset_into(Some(seed), &mut obs).unwrap();
            let initial_hidden = env.dom().hidden.clone();
            let mut step = Step::default();
            while let Some(a) = env.oracle_action() {
                env.step_into(&Action::Discrete(a), &mut step).unwrap();
                let mut reported = env.dom().clone();
                reported.hidden.clone_from(&initial_hidden);
                for (i, n) in env.website().nodes.iter().enumerate() {
                    if !reported.visible[i] && !n.tag.is_control() {
                        reported.visited[i] = !reported.visited[i];
                    }
                }
                differed += usize::from(reported.hidden != env.dom().hidden);
                assert_eq!(env.website().state_html(&reported), html(&mut env));
                if step.done() {
                    break;
                }
            }
        }
        assert!(differed > 0, "no page turned: the test tests nothing");
    }

    #[test]
    fn unknown_modes_name_the_supported_one() {
        let mut env = WebNavEnv::new(WebNavConfig::new(1)).unwrap();
        assert_eq!(env.render_modes(), &["html"]);
        let err = env.render("rgb_array").unwrap_err();
        assert!(matches!(err, EnvError::InvalidParameter { .. }));
        assert!(err.to_string().contains("supported modes: html"), "{err}");
    }
}

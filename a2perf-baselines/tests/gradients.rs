//! Gradient checks of every layer, network and loss against central finite differences.

mod common;

use a2perf_baselines::batch::{ObsBatch, ObsLayout};
use a2perf_baselines::model::{DiscreteNet, NetOptions, WebPath};
use a2perf_baselines::nn::dist::{gaussian, masked, tanh_gaussian};
use a2perf_baselines::nn::embed::Embedding;
use a2perf_baselines::nn::{Activation, Linear, Mlp, MlpWs, ParamAlloc};
use a2perf_core::RngStream;
use proptest::prelude::*;

/// Compares analytic and numeric derivatives; f32 nets, so tolerances are relative 3e-2 plus
/// absolute 2e-3, and `allowed_misses` lets a ReLU kink crossed by the finite difference pass.
fn compare(analytic: &[f64], numeric: &[f64], allowed_misses: usize) -> Result<(), TestCaseError> {
    let mut misses = Vec::new();
    for (i, (a, n)) in analytic.iter().zip(numeric).enumerate() {
        let tol = 3e-2 * a.abs().max(n.abs()) + 2e-3;
        if (a - n).abs() > tol {
            misses.push((i, *a, *n));
        }
    }
    prop_assert!(
        misses.len() <= allowed_misses,
        "{} of {} derivatives disagree: {:?}",
        misses.len(),
        analytic.len(),
        &misses[..misses.len().min(5)]
    );
    Ok(())
}

fn fd(mut f: impl FnMut(f32) -> f64, x0: f32, h: f32) -> f64 {
    (f(x0 + h) - f(x0 - h)) / (2.0 * f64::from(h))
}

/// Central difference at step `h`; when it disagrees with `analytic`, the central, forward and
/// backward differences at `h/10` are tried and the closest one returned. A ReLU kink inside
/// `[x0 − h, x0 + h]` spoils the central estimate, but the one-sided difference taken on the
/// kink-free side still measures the true derivative (which the analytic one must match).
fn fd_checked(mut f: impl FnMut(f32) -> f64, x0: f32, h: f32, analytic: f64) -> f64 {
    let n = fd(&mut f, x0, h);
    if (analytic - n).abs() <= 3e-2 * analytic.abs().max(n.abs()) + 2e-3 {
        return n;
    }
    let h = h / 10.0;
    let (lo, mid, hi) = (f(x0 - h), f(x0), f(x0 + h));
    let hh = f64::from(h);
    [(hi - lo) / (2.0 * hh), (hi - mid) / hh, (mid - lo) / hh]
        .into_iter()
        .min_by(|a, b| (a - analytic).abs().total_cmp(&(b - analytic).abs()))
        .unwrap_or(n)
}

fn rand_vec(rng: &mut RngStream, n: usize, s: f64) -> Vec<f32> {
    (0..n).map(|_| (rng.normal() * s) as f32).collect()
}

fn dot(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| f64::from(*x) * f64::from(*y))
        .sum()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn linear_gradients(seed in 0u64..1000, inp in 1usize..6, out in 1usize..5, batch in 1usize..4) {
        let mut rng = RngStream::new(seed, "lin");
        let mut alloc = ParamAlloc::new();
        let layer = Linear::new(&mut alloc, inp, out);
        let mut p = rand_vec(&mut rng, alloc.len(), 0.5);
        let mut x = rand_vec(&mut rng, batch * inp, 1.0);
        let c = rand_vec(&mut rng, batch * out, 1.0);
        let mut y = vec![0.0; batch * out];
        let mut g = vec![0.0; p.len()];
        let mut dx = vec![0.0; x.len()];
        layer.forward(&p, &x, batch, &mut y);
        layer.backward(&p, &mut g, &x, &c, batch, Some(&mut dx));
        let mut num = Vec::new();
        for i in 0..p.len() {
            let p0 = p[i];
            num.push(fd(|v| { p[i] = v; layer.forward(&p, &x, batch, &mut y); dot(&y, &c) }, p0, 1e-2));
            p[i] = p0;
        }
        compare(&g.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(), &num, 0)?;
        let mut numx = Vec::new();
        for i in 0..x.len() {
            let x0 = x[i];
            numx.push(fd(|v| { x[i] = v; layer.forward(&p, &x, batch, &mut y); dot(&y, &c) }, x0, 1e-2));
            x[i] = x0;
        }
        compare(&dx.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(), &numx, 0)?;
    }

    #[test]
    fn mlp_gradients(seed in 0u64..1000, relu in any::<bool>(), encoder in any::<bool>(), batch in 1usize..4) {
        let mut rng = RngStream::new(seed, "mlp");
        let mut alloc = ParamAlloc::new();
        let act = if relu { Activation::Relu } else { Activation::Tanh };
        let mlp = if encoder { Mlp::encoder(&mut alloc, &[3, 5, 4], act) } else { Mlp::new(&mut alloc, &[3, 5, 4, 2], act) };
        let mut p = rand_vec(&mut rng, alloc.len(), 0.7);
        let mut x = rand_vec(&mut rng, batch * 3, 1.0);
        let c = rand_vec(&mut rng, batch * mlp.out(), 1.0);
        let mut ws = MlpWs::default();
        let mut g = vec![0.0; p.len()];
        let mut dx = vec![0.0; x.len()];
        mlp.forward(&p, &x, batch, &mut ws);
        mlp.backward(&p, &mut g, &x, &c, &mut ws, Some(&mut dx));
        let mut num = Vec::new();
        for i in 0..p.len() {
            let p0 = p[i];
            num.push(fd_checked(|v| { p[i] = v; dot(mlp.forward(&p, &x, batch, &mut ws), &c) }, p0, 3e-3, f64::from(g[i])));
            p[i] = p0;
        }
        let misses = if relu { 1 } else { 0 };
        compare(&g.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(), &num, misses)?;
        let mut numx = Vec::new();
        for i in 0..x.len() {
            let x0 = x[i];
            numx.push(fd_checked(|v| { x[i] = v; dot(mlp.forward(&p, &x, batch, &mut ws), &c) }, x0, 3e-3, f64::from(dx[i])));
            x[i] = x0;
        }
        compare(&dx.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(), &numx, misses)?;
    }

    #[test]
    fn embedding_pool_gradients(seed in 0u64..1000, groups in 1usize..4, len in 1usize..5) {
        let mut rng = RngStream::new(seed, "emb");
        let mut alloc = ParamAlloc::new();
        let e = Embedding::new(&mut alloc, 6, 3);
        let mut p = rand_vec(&mut rng, alloc.len(), 1.0);
        // Includes padding (0) and out-of-vocabulary ids (≥ 6).
        let tokens: Vec<i32> = (0..groups * len).map(|_| rng.index(9) as i32).collect();
        let c = rand_vec(&mut rng, groups * 3, 1.0);
        let mut out = vec![0.0; groups * 3];
        let mut g = vec![0.0; p.len()];
        e.pool(&p, &tokens, len, &mut out);
        e.pool_backward(&mut g, &tokens, len, &c);
        let mut num = Vec::new();
        for i in 0..p.len() {
            let p0 = p[i];
            num.push(fd(|v| { p[i] = v; e.pool(&p, &tokens, len, &mut out); dot(&out, &c) }, p0, 1e-2));
            p[i] = p0;
        }
        compare(&g.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(), &num, 0)?;
    }

    #[test]
    fn masked_categorical_gradients(seed in 0u64..1000, n in 2usize..9, entropy_w in -1.0f32..1.0) {
        let mut rng = RngStream::new(seed, "cat");
        let mut z = rand_vec(&mut rng, n, 1.5);
        let mut mask: Vec<bool> = (0..n).map(|_| rng.uniform() < 0.7).collect();
        mask[0] = true;
        let legal: Vec<usize> = (0..n).filter(|i| mask[*i]).collect();
        let a = legal[rng.index(legal.len())];
        let mut lp = vec![0.0; n];
        // f = log p(a) + w·H
        let f = |z: &[f32], lp: &mut Vec<f32>| {
            masked::log_softmax(z, Some(&mask), lp);
            f64::from(lp[a]) + f64::from(entropy_w) * f64::from(masked::entropy(lp))
        };
        f(&z, &mut lp);
        let mut g = vec![0.0; n];
        masked::grad_logp(&lp, a, 1.0, &mut g);
        masked::grad_entropy(&lp, entropy_w, &mut g);
        for (i, m) in mask.iter().enumerate() {
            if !m { prop_assert_eq!(g[i], 0.0); prop_assert_eq!(lp[i], f32::NEG_INFINITY); }
        }
        let mut num = Vec::new();
        for i in 0..n {
            let z0 = z[i];
            num.push(fd(|v| { z[i] = v; f(&z, &mut lp) }, z0, 1e-2));
            z[i] = z0;
        }
        compare(&g.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(), &num, 0)?;
        let total: f64 = { f(&z, &mut lp); lp.iter().filter(|l| l.is_finite()).map(|l| f64::from(l.exp())).sum() };
        prop_assert!((total - 1.0).abs() < 1e-5);
    }

    /// The softmax gradient over the legal actions alone (BC's) is the full one's, bit for bit,
    /// and leaves the illegal entries alone: logits of any scale, any mask, none legal included.
    #[test]
    fn legal_only_softmax_gradient_is_the_full_ones(
        seed in 0u64..1000, n in 1usize..40, scale in prop::sample::select(vec![0.5f64, 30.0, 300.0]),
        p_legal in 0.0f64..1.0, coef in -2.0f32..2.0,
    ) {
        let mut rng = RngStream::new(seed, "legal");
        let z = rand_vec(&mut rng, n, scale);
        let mask: Vec<bool> = (0..n).map(|_| rng.uniform() < p_legal).collect();
        let legal: Vec<usize> = (0..n).filter(|i| mask[*i]).collect();
        let a = rng.index(n);
        let start: Vec<f32> = rand_vec(&mut rng, n, 1.0);
        let mut lp = vec![0.0; n];
        let some = masked::log_softmax(&z, Some(&mask), &mut lp);
        let mut full = start.clone();
        masked::grad_logp(&lp, a, coef, &mut full);
        let mut fast = start.clone();
        prop_assert_eq!(masked::grad_logp_legal(&z, &legal, a, coef, &mut fast), some);
        prop_assert_eq!(fast.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            full.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
        for i in (0..n).filter(|i| !mask[*i]) {
            prop_assert_eq!(fast[i].to_bits(), start[i].to_bits());
        }
    }

    #[test]
    fn gaussian_gradients(seed in 0u64..1000, d in 1usize..5) {
        let mut rng = RngStream::new(seed, "gauss");
        let mut v = rand_vec(&mut rng, 2 * d, 0.5);
        let a = rand_vec(&mut rng, d, 1.0);
        let f = |v: &[f32]| f64::from(gaussian::log_prob(&v[..d], &v[d..], &a));
        let mut dm = vec![0.0; d];
        let mut ds = vec![0.0; d];
        gaussian::grad_log_prob(&v[..d], &v[d..], &a, 1.0, &mut dm, &mut ds);
        let analytic: Vec<f64> = dm.iter().chain(&ds).map(|x| f64::from(*x)).collect();
        let mut num = Vec::new();
        for i in 0..2 * d {
            let v0 = v[i];
            num.push(fd(|x| { v[i] = x; f(&v) }, v0, 1e-2));
            v[i] = v0;
        }
        compare(&analytic, &num, 0)?;
    }

    #[test]
    fn tanh_gaussian_gradients(seed in 0u64..1000, d in 1usize..4, w_logp in -1.0f32..1.0) {
        let mut rng = RngStream::new(seed, "tanh");
        let mut v = rand_vec(&mut rng, 2 * d, 0.5);
        let eps = rand_vec(&mut rng, d, 1.0);
        let w = rand_vec(&mut rng, d, 1.0);
        // Reference in f64 (the same formulas), so saturated tanh does not drown the finite
        // difference in f32 rounding; the f32 implementation must agree with it.
        let f = |v: &[f32]| {
            let mut total = 0.0f64;
            for i in 0..d {
                let raw = f64::from(v[d + i]);
                let s = -5.0 + 3.5 * (raw.tanh() + 1.0);
                let u = f64::from(v[i]) + s.exp() * f64::from(eps[i]);
                let t = u.tanh();
                let e = f64::from(eps[i]);
                let lp = -0.5 * e * e - s - 0.918_938_533_204_672_7 - (1.0 - t * t + 1e-6).ln();
                total += t * f64::from(w[i]) + f64::from(w_logp) * lp;
            }
            total
        };
        let mut a = vec![0.0; d];
        let lp32 = tanh_gaussian::sample(&v[..d], &v[d..], &eps, &mut a);
        prop_assert!(lp32.is_finite());
        // f32 cannot resolve 1 − tanh²(u) once |u| ≳ 5 (tanh rounds to ±1); SAC's actions live
        // there only with extreme means, and the check is about the formulas, so skip those draws.
        for i in 0..d {
            let s = tanh_gaussian::log_std(v[d + i]);
            prop_assume!((v[i] + s.exp() * eps[i]).abs() < 5.0);
        }
        let mut dm = vec![0.0; d];
        let mut dr = vec![0.0; d];
        tanh_gaussian::backward(&v[..d], &v[d..], &eps, &w, w_logp, &mut dm, &mut dr);
        let analytic: Vec<f64> = dm.iter().chain(&dr).map(|x| f64::from(*x)).collect();
        let mut num = Vec::new();
        for i in 0..2 * d {
            let v0 = v[i];
            num.push(fd(|x| { v[i] = x; f(&v) }, v0, 1e-3));
            v[i] = v0;
        }
        compare(&analytic, &num, 0)?;
    }
}

/// Checks a discrete network's parameter gradients of `Σ c·logits + Σ cv·values` at up to 60
/// parameters.
fn check_net(net: &mut DiscreteNet, batch: &ObsBatch, seed: u64) -> Result<(), TestCaseError> {
    let mut rng = RngStream::new(seed, "net");
    let mut p = net.init_params(&mut rng);
    // Larger output weights than the near-uniform init so every path carries gradient.
    for v in p.iter_mut() {
        *v += (rng.normal() * 0.1) as f32;
    }
    net.forward(&p, batch);
    let c = rand_vec(&mut rng, net.logits().len(), 1.0);
    let cv = rand_vec(&mut rng, net.values().len(), 1.0);
    let mut g = vec![0.0; p.len()];
    net.backward(&p, &mut g, batch, &c, Some(&cv));
    let picks: Vec<usize> = (0..60.min(p.len())).map(|_| rng.index(p.len())).collect();
    let mut num = Vec::new();
    for &i in &picks {
        let p0 = p[i];
        num.push(fd_checked(
            |v| {
                p[i] = v;
                net.forward(&p, batch);
                dot(net.logits(), &c) + dot(net.values(), &cv)
            },
            p0,
            2e-3,
            f64::from(g[i]),
        ));
        p[i] = p0;
    }
    let analytic: Vec<f64> = picks.iter().map(|&i| f64::from(g[i])).collect();
    compare(&analytic, &num, 3)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn web_network_gradients(seed in 0u64..1000, rows in 1usize..3, projected in any::<bool>()) {
        let env = common::MiniWeb::new(3, 4, 3);
        let spec = env.spec_ref().clone();
        let layout = ObsLayout::from_spec(&spec).unwrap();
        let opts = NetOptions { embedding_dim: 4, latent_dim: 3, ..NetOptions::default() };
        let mut net = DiscreteNet::for_spec(&spec, &layout, &opts, true).unwrap();
        prop_assert_eq!(net.kind(), "web");
        net.set_web_path(if projected { WebPath::Projected } else { WebPath::Direct });
        let mut rng = RngStream::new(seed, "obs");
        let mut batch = ObsBatch::new(&layout);
        for _ in 0..rows { batch.push(&env.observation(&mut rng)).unwrap(); }
        check_net(&mut net, &batch, seed)?;
    }

    #[test]
    fn circuit_network_gradients(seed in 0u64..1000, rows in 1usize..3) {
        let spec = common::mini_circuit_spec();
        let layout = ObsLayout::from_spec(&spec).unwrap();
        let opts = NetOptions { hidden_sizes: vec![6], latent_dim: 4, ..NetOptions::default() };
        let mut net = DiscreteNet::for_spec(&spec, &layout, &opts, true).unwrap();
        prop_assert_eq!(net.kind(), "circuit");
        let mut rng = RngStream::new(seed, "obs");
        let mut batch = ObsBatch::new(&layout);
        for _ in 0..rows { batch.push(&common::mini_circuit_obs(&mut rng)).unwrap(); }
        check_net(&mut net, &batch, seed)?;
    }

    #[test]
    fn flat_network_gradients(seed in 0u64..1000, rows in 1usize..3) {
        let spec = common::mini_circuit_spec();
        let layout = ObsLayout::from_spec(&spec).unwrap();
        let opts = NetOptions { architecture: "mlp".into(), hidden_sizes: vec![7, 5], ..NetOptions::default() };
        let mut net = DiscreteNet::for_spec(&spec, &layout, &opts, true).unwrap();
        prop_assert_eq!(net.kind(), "mlp");
        let mut rng = RngStream::new(seed, "obs");
        let mut batch = ObsBatch::new(&layout);
        for _ in 0..rows { batch.push(&common::mini_circuit_obs(&mut rng)).unwrap(); }
        check_net(&mut net, &batch, seed)?;
    }
}

/// A web batch of `rows` random pages, with some token groups emptied (all padding) and some
/// ids past the vocabulary (the out-of-vocabulary row), which both paths must treat alike.
fn web_batch(
    env: &common::MiniWeb,
    layout: &ObsLayout,
    rows: usize,
    rng: &mut RngStream,
) -> ObsBatch {
    let mut batch = ObsBatch::new(layout);
    for _ in 0..rows {
        batch.push(&env.observation(rng)).unwrap();
    }
    for name in ["profile_keys", "profile_values", "dom_tokens"] {
        let i = layout.index(name).unwrap();
        for r in 0..rows {
            let toks = batch.int_row_mut(i, r);
            for group in toks.chunks_exact_mut(env.t) {
                match rng.index(6) {
                    0 => group.fill(0),
                    1 => group[0] = 40,
                    _ => {}
                }
            }
        }
    }
    batch
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The projected first layers (gather rows of `E W_sᵀ`) compute what the direct ones (pool,
    /// then multiply) do, forward and backward, up to float rounding.
    #[test]
    fn web_paths_agree(seed in 0u64..1000, rows in 1usize..7) {
        let env = common::MiniWeb::new(4, 6, 3);
        let spec = env.spec_ref().clone();
        let layout = ObsLayout::from_spec(&spec).unwrap();
        let opts = NetOptions { embedding_dim: 5, latent_dim: 4, ..NetOptions::default() };
        let mut direct = DiscreteNet::for_spec(&spec, &layout, &opts, true).unwrap();
        let mut projected = direct.clone();
        direct.set_web_path(WebPath::Direct);
        projected.set_web_path(WebPath::Projected);
        let mut rng = RngStream::new(seed, "paths");
        let mut p = direct.init_params(&mut rng);
        for v in p.iter_mut() {
            *v += (rng.normal() * 0.3) as f32;
        }
        let batch = web_batch(&env, &layout, rows, &mut rng);
        direct.forward(&p, &batch);
        projected.forward(&p, &batch);
        let close = |a: &[f32], b: &[f32], what: &str| -> Result<(), TestCaseError> {
            prop_assert_eq!(a.len(), b.len());
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                prop_assert!((x - y).abs() <= 1e-4 * x.abs().max(y.abs()) + 1e-5,
                    "{} {}: direct {} projected {}", what, i, x, y);
            }
            Ok(())
        };
        close(direct.logits(), projected.logits(), "logit")?;
        close(direct.values(), projected.values(), "value")?;
        let c = rand_vec(&mut rng, direct.logits().len(), 1.0);
        let cv = rand_vec(&mut rng, direct.values().len(), 1.0);
        let (mut gd, mut gp) = (vec![0.0; p.len()], vec![0.0; p.len()]);
        direct.backward(&p, &mut gd, &batch, &c, Some(&cv));
        projected.backward(&p, &mut gp, &batch, &c, Some(&cv));
        close(&gd, &gp, "gradient")?;
        // The gradients are not trivially equal: some are non-zero.
        prop_assert!(gd.iter().any(|g| g.abs() > 1e-3));
        // New parameters after a forward with the old ones: the projected tables the
        // network keeps for unchanged parameters must be rebuilt when any one weight changes.
        for _ in 0..6 {
            let i = rng.index(p.len());
            p[i] += 0.5;
            direct.forward(&p, &batch);
            projected.forward(&p, &batch);
            close(direct.logits(), projected.logits(), "logit after a parameter change")?;
            close(direct.values(), projected.values(), "value after a parameter change")?;
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// `argmax_at` over increasing scored actions (every other action illegal and `−∞`, as
    /// the padding of A2Perf's circuit canvas) picks what `argmax` picks over every action,
    /// ties and all-illegal rows included.
    #[test]
    fn argmax_at_picks_the_full_argmax(
        picks in proptest::collection::vec((0usize..3, 0u8..4, any::<bool>()), 0..40),
    ) {
        // Each entry: a gap before the scored action, a logit from a few values (ties), legal.
        let mut actions = Vec::new();
        let (mut logits, mut legal) = (Vec::new(), Vec::new());
        let mut at = 0;
        for (gap, z, ok) in &picks {
            at += gap;
            actions.push(at);
            logits.push(f32::from(*z) - 1.5);
            legal.push(*ok);
            at += 1;
        }
        let n = at + 2;
        let mut full = vec![f32::NEG_INFINITY; n];
        let mut mask = vec![false; n];
        for (j, &a) in actions.iter().enumerate() {
            full[a] = logits[j];
            mask[a] = legal[j];
        }
        let col = masked::argmax_at(&logits, &actions, Some(&mask));
        prop_assert_eq!(col.map(|j| actions[j]), masked::argmax(&full, Some(&mask)));
        prop_assert_eq!(masked::argmax_at(&logits, &actions, None), masked::argmax(&logits, None));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// `Mlp::backward_input` writes the input gradient `Mlp::backward` writes, bit for bit,
    /// and touches no parameter gradient (SAC's actor step relies on it).
    #[test]
    fn backward_input_is_backwards_input_gradient(
        seed in 0u64..1000, inp in 1usize..9, hidden in 1usize..7, out in 1usize..4,
        batch in 1usize..6, tanh in any::<bool>(),
    ) {
        let act = if tanh { Activation::Tanh } else { Activation::Relu };
        let mut alloc = ParamAlloc::new();
        let mlp = Mlp::new(&mut alloc, &[inp, hidden, hidden, out], act);
        let mut rng = RngStream::new(seed, "backward_input");
        let mut params = vec![0.0f32; alloc.len()];
        mlp.init(&mut params, &mut rng, 1.0);
        let x: Vec<f32> = (0..batch * inp).map(|_| rng.normal() as f32).collect();
        let dout: Vec<f32> = (0..batch * out).map(|_| rng.normal() as f32).collect();
        let mut ws = MlpWs::default();
        mlp.forward(&params, &x, batch, &mut ws);
        let mut grads = vec![0.0f32; params.len()];
        let mut dx = vec![0.0f32; batch * inp];
        mlp.backward(&params, &mut grads, &x, &dout, &mut ws, Some(&mut dx));
        let mut alone = vec![0.0f32; batch * inp];
        mlp.backward_input(&params, &dout, &mut ws, &mut alone);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&dx), bits(&alone));
    }
}

/// SAC's actor step takes each critic's action gradient on the rows where it is the minimum
/// only (`Mlp::keep_rows`, `Mlp::backward_input_cols`): at the paper's critic dimensions
/// (160 observation + 12 action inputs, 512-256 hidden, batch 256) those values must be bit
/// for bit the full backward pass's, where the dropped rows carry a zero output gradient, or
/// the pinned training runs would move.
#[test]
fn kept_rows_action_gradient_equals_the_full_pass_bit_for_bit() {
    let (od, d, b) = (160, 12, 256);
    let mut alloc = ParamAlloc::new();
    let mlp = Mlp::new(&mut alloc, &[od + d, 512, 256, 1], Activation::Relu);
    let mut params = vec![0.0; alloc.len()];
    let mut rng = RngStream::new(7, "test/kept_rows");
    mlp.init(&mut params, &mut rng, 1.0);
    let x: Vec<f32> = (0..b * (od + d)).map(|_| rng.normal() as f32).collect();
    let rows: Vec<usize> = (0..b).filter(|_| rng.uniform() < 0.5).collect();
    assert!(!rows.is_empty() && rows.len() < b);
    let g = -1.0 / b as f32;
    let mut dout = vec![0.0; b];
    for &r in &rows {
        dout[r] = g;
    }
    let mut ws = MlpWs::default();
    mlp.forward(&params, &x, b, &mut ws);
    let mut full = vec![0.0; b * (od + d)];
    mlp.backward_input(&params, &dout, &mut ws, &mut full);

    mlp.forward(&params, &x, b, &mut ws);
    mlp.keep_rows(&mut ws, &rows);
    let mut kept = vec![0.0; rows.len() * d];
    mlp.backward_input_cols(
        &params,
        &vec![g; rows.len()],
        &mut ws,
        od..od + d,
        &mut kept,
    );
    for (j, &r) in rows.iter().enumerate() {
        let want = &full[r * (od + d) + od..(r + 1) * (od + d)];
        let got = &kept[j * d..(j + 1) * d];
        assert!(
            want.iter()
                .zip(got)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "row {r}: {got:?} != {want:?}"
        );
    }
}

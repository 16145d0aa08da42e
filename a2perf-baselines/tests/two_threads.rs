//! What runs on two threads gives the values of one thread, to the bit: the actor's and
//! critic's passes side by side (`GaussianArch::forward_both` / `backward_both`) and Adam's
//! update in two halves. Run inside a pool of two threads, so the parallel paths are taken even
//! on a one-core machine.

use a2perf_baselines::model::GaussianArch;
use a2perf_baselines::nn::MlpWs;
use a2perf_baselines::nn::optim::Adam;
use a2perf_core::RngStream;

fn normals(rng: &mut RngStream, n: usize, scale: f32) -> Vec<f32> {
    (0..n).map(|_| rng.normal() as f32 * scale).collect()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of two threads")
}

#[test]
fn actor_and_critic_side_by_side_are_the_serial_passes() {
    let pool = pool();
    for (obs_dim, act_dim, hidden) in [(160, 12, vec![512, 256]), (7, 3, vec![16, 8])] {
        let arch = GaussianArch::new(obs_dim, act_dim, &hidden, true);
        let critic = arch.critic.clone().expect("value head");
        for batch in [1, 2, 5, 128] {
            let mut rng = RngStream::new(batch as u64, "two-threads");
            let mut p = arch.init_params(&mut rng, -1.0);
            // Weights away from their initial scale, so every product matters.
            for w in &mut p {
                *w += rng.normal() as f32 * 0.05;
            }
            let x = normals(&mut rng, batch * obs_dim, 1.0);
            let dmean = normals(&mut rng, batch * act_dim, 0.1);
            let dv = normals(&mut rng, batch, 0.1);

            // One thread: the passes one after the other.
            let (mut wa, mut wc) = (MlpWs::default(), MlpWs::default());
            let mut serial = vec![0.5; p.len()];
            arch.actor.forward(&p, &x, batch, &mut wa);
            critic.forward(&p, &x, batch, &mut wc);
            let (mean, value) = (arch.actor.output(&wa).to_vec(), critic.output(&wc).to_vec());
            arch.actor
                .backward(&p, &mut serial, &x, &dmean, &mut wa, None);
            critic.backward(&p, &mut serial, &x, &dv, &mut wc, None);

            // Two threads, into gradients that already hold values (the passes accumulate).
            let (mut wa, mut wc) = (MlpWs::default(), MlpWs::default());
            let mut both = vec![0.5; p.len()];
            pool.install(|| {
                arch.forward_both(&p, &x, batch, &mut wa, &mut wc);
                assert_eq!(
                    bits(arch.actor.output(&wa)),
                    bits(&mean),
                    "actor, batch {batch}"
                );
                assert_eq!(
                    bits(critic.output(&wc)),
                    bits(&value),
                    "critic, batch {batch}"
                );
                arch.backward_both(&p, &mut both, &x, &dmean, &dv, &mut wa, &mut wc);
            });
            assert_eq!(bits(&both), bits(&serial), "gradients, batch {batch}");
            assert!(
                serial[arch.log_std..].iter().all(|&g| g == 0.5),
                "log-std untouched"
            );
        }
    }
}

#[test]
fn adam_in_two_halves_is_adam_in_one() {
    let n = 100_003; // above the split threshold, odd so the halves differ in length
    let mut rng = RngStream::new(7, "adam");
    let start = normals(&mut rng, n, 1.0);
    let grads: Vec<Vec<f32>> = (0..3).map(|_| normals(&mut rng, n, 0.1)).collect();
    let run = |on_pool: bool| {
        let mut p = start.clone();
        let mut adam = Adam::new(n);
        let mut steps = || {
            for g in &grads {
                adam.step(&mut p, g, 1e-3);
            }
        };
        if on_pool {
            pool().install(|| {
                assert!(rayon::current_thread_index().is_some());
                steps();
            });
        } else {
            assert!(rayon::current_thread_index().is_none());
            steps();
        }
        p
    };
    let (one, two) = (run(false), run(true));
    assert_ne!(bits(&one), bits(&start), "the steps moved the parameters");
    assert_eq!(bits(&one), bits(&two));
}

"""PPO in PyTorch, in the single-file style of CleanRL, benchmarked by a2perf_rs.

Trains on ``QuadrupedLocomotion-DogPace-v0`` with ``run.make_vec`` (N environments stepped in
Rust threads, seeded from the run's seed), logs the built-in evaluation protocol's curve and
checkpoints with ``a2perf_rs.TrainingRun``, then infers and generalizes the greedy policy. It is
not run in CI (it needs PyTorch, which the tests do not install); CI only checks that it
compiles. Run from the repository root (the second command trains the built-in PPO to compare
with)::

    pip install ./python torch
    python examples/python/torch_ppo.py --out results/torch_ppo --total-steps 200000
    cargo run --release -p a2perf-cli -- run configs/quadruped_locomotion/ppo.ron --seeds 0 -o results/locomotion_ppo
    cargo run --release -p a2perf-cli -- report results/torch_ppo results/locomotion_ppo -o results/torch-vs-ppo

Vector-environment semantics are Gymnasium 1.x's next-step autoreset: after an episode ends,
the next ``step`` only resets that environment (its action is ignored, its reward is 0), so
those steps are masked out of the PPO loss below.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.distributions import Normal

import a2perf_rs

ENV_ID = "QuadrupedLocomotion-DogPace-v0"


def linear(n_in: int, n_out: int, gain: float = float(np.sqrt(2))) -> nn.Linear:
    layer = nn.Linear(n_in, n_out)
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


class ActorCritic(nn.Module):
    def __init__(self, obs_dim: int, act_dim: int, hidden: int = 64) -> None:
        super().__init__()
        self.critic = nn.Sequential(
            linear(obs_dim, hidden), nn.Tanh(), linear(hidden, hidden), nn.Tanh(),
            linear(hidden, 1, 1.0),
        )
        self.mean = nn.Sequential(
            linear(obs_dim, hidden), nn.Tanh(), linear(hidden, hidden), nn.Tanh(),
            linear(hidden, act_dim, 0.01),
        )
        # Small pose offsets (std 0.135 rad), as configs/quadruped_locomotion/ppo.ron found
        # necessary: wider exploration topples the robot before it learns anything.
        self.log_std = nn.Parameter(torch.full((act_dim,), -2.0))

    def value(self, x: torch.Tensor) -> torch.Tensor:
        return self.critic(x).squeeze(-1)

    def act(self, x: torch.Tensor, action: torch.Tensor | None = None):
        dist = Normal(self.mean(x), self.log_std.exp().expand(x.shape[0], -1))
        if action is None:
            action = dist.sample()
        return action, dist.log_prob(action).sum(-1), dist.entropy().sum(-1), self.value(x)


class ObsNorm:
    """Running mean and variance of observations (updated during training only)."""

    def __init__(self, dim: int) -> None:
        self.mean, self.var, self.count = np.zeros(dim), np.ones(dim), 1e-4

    def update(self, x: np.ndarray) -> None:
        m, v, n = x.mean(0), x.var(0), x.shape[0]
        delta, total = m - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + v * n + delta**2 * self.count * n / total) / total
        self.count = total

    def __call__(self, x: np.ndarray) -> torch.Tensor:
        z = np.clip((x - self.mean) / np.sqrt(self.var + 1e-8), -10, 10)
        return torch.as_tensor(z, dtype=torch.float32)


class GreedyPolicy:
    """``policy(obs) -> action`` for a2perf_rs: the mean action, clipped to the space."""

    def __init__(self, agent: ActorCritic, norm: ObsNorm, low: np.ndarray, high: np.ndarray):
        self.agent, self.norm, self.low, self.high = agent, norm, low, high

    @torch.no_grad()
    def __call__(self, obs: np.ndarray) -> np.ndarray:
        mean = self.agent.mean(self.norm(obs[None]))[0].numpy()
        return np.clip(mean, self.low, self.high).astype(np.float32)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="results/torch_ppo")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--total-steps", type=int, default=200_000)
    p.add_argument("--num-envs", type=int, default=4)
    p.add_argument("--num-steps", type=int, default=512, help="steps per environment per update")
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--gae-lambda", type=float, default=0.95)
    p.add_argument("--epochs", type=int, default=10)
    p.add_argument("--minibatches", type=int, default=32)
    p.add_argument("--clip", type=float, default=0.2)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--max-grad-norm", type=float, default=0.5)
    a = p.parse_args()
    hp = {k: v for k, v in vars(a).items() if k not in ("out", "seed")}

    with a2perf_rs.TrainingRun(
        a.out, env_id=ENV_ID, algorithm="torch-ppo", seed=a.seed, hyperparameters=hp,
        set=[f"training.total_env_steps={a.total_steps}", f"training.num_envs={a.num_envs}",
             "training.eval_interval=10000", "training.checkpoint_interval=50000"],
    ) as run:
        torch.manual_seed(run.seed)
        envs = run.make_vec(a.num_envs)
        low, high = envs.single_action_space.low, envs.single_action_space.high
        obs_dim, act_dim = envs.single_observation_space.shape[0], low.shape[0]
        agent, norm = ActorCritic(obs_dim, act_dim), ObsNorm(obs_dim)
        opt = torch.optim.Adam(agent.parameters(), lr=a.lr, eps=1e-5)
        n, t = a.num_envs, a.num_steps
        obs_buf = np.zeros((t, n, obs_dim), np.float32)
        act_buf = torch.zeros((t, n, act_dim))
        logp_buf, val_buf = torch.zeros((t, n)), torch.zeros((t, n))
        rew_buf, done_buf, valid_buf = np.zeros((t, n)), np.zeros((t, n)), np.zeros((t, n))
        obs, _ = envs.reset()
        resetting = np.zeros(n, bool)  # this step only resets (next-step autoreset)
        steps, next_eval, next_ckpt = 0, run.training["eval_interval"], run.training["checkpoint_interval"]
        ckpt_dir = Path(tempfile.mkdtemp())
        while steps < a.total_steps:
            for g in opt.param_groups:
                g["lr"] = a.lr * (1.0 - steps / a.total_steps)
            for i in range(t):
                norm.update(obs)
                obs_buf[i], valid_buf[i] = obs, ~resetting
                with torch.no_grad():
                    action, logp, _, value = agent.act(norm(obs))
                act_buf[i], logp_buf[i], val_buf[i] = action, logp, value
                obs, reward, term, trunc, _ = envs.step(
                    np.clip(action.numpy(), low, high).astype(np.float32))
                rew_buf[i], done_buf[i] = reward, term
                resetting = term | trunc
                steps += n
            with torch.no_grad():
                next_value = agent.value(norm(obs)).numpy()
            adv = np.zeros((t, n))
            last = np.zeros(n)
            for i in reversed(range(t)):
                nv = next_value if i == t - 1 else val_buf[i + 1].numpy()
                # A terminal step does not bootstrap; a truncated one bootstraps from its final
                # observation (the reset step's stored one). The reset step itself is masked out
                # of the loss and cuts the advantage chain.
                cont = 1.0 - done_buf[i]
                nxt_valid = 1.0 if i == t - 1 else valid_buf[i + 1]
                delta = rew_buf[i] + a.gamma * nv * cont - val_buf[i].numpy()
                last = delta + a.gamma * a.gae_lambda * cont * nxt_valid * last
                adv[i] = last
            ret = adv + val_buf.numpy()
            b_obs = norm(obs_buf.reshape(-1, obs_dim))
            b_act, b_logp = act_buf.reshape(-1, act_dim), logp_buf.reshape(-1)
            b_adv = torch.as_tensor(adv.reshape(-1), dtype=torch.float32)
            b_ret = torch.as_tensor(ret.reshape(-1), dtype=torch.float32)
            b_valid = torch.as_tensor(valid_buf.reshape(-1), dtype=torch.float32)
            size = t * n
            mb = size // a.minibatches
            for _ in range(a.epochs):
                for idx in np.array_split(np.random.permutation(size), size // mb):
                    _, logp, ent, value = agent.act(b_obs[idx], b_act[idx])
                    ratio = (logp - b_logp[idx]).exp()
                    w = b_valid[idx]
                    adv_mb = (b_adv[idx] - b_adv[idx].mean()) / (b_adv[idx].std() + 1e-8)
                    pg = torch.max(-adv_mb * ratio,
                                   -adv_mb * ratio.clamp(1 - a.clip, 1 + a.clip))
                    loss = ((pg + a.vf_coef * 0.5 * (value - b_ret[idx]) ** 2) * w).sum()
                    loss = loss / w.sum().clamp(min=1.0)
                    opt.zero_grad()
                    loss.backward()
                    nn.utils.clip_grad_norm_(agent.parameters(), a.max_grad_norm)
                    opt.step()
            policy = GreedyPolicy(agent, norm, low, high)
            if steps >= next_eval or steps >= a.total_steps:
                mean, std = run.evaluate(steps, policy)
                print(f"step {steps}: return {mean:.2f} ± {std:.2f}")
                next_eval += run.training["eval_interval"]
            if steps >= next_ckpt or steps >= a.total_steps:
                path = ckpt_dir / "agent.pt"
                torch.save({"agent": agent.state_dict(), "mean": norm.mean, "var": norm.var}, path)
                run.save_checkpoint(steps, path)
                next_ckpt += run.training["checkpoint_interval"]
        envs.close()
    inference = a2perf_rs.infer(run.run_dir, policy)
    generalization = a2perf_rs.generalize(run.run_dir, policy)
    print(f"{run.run_dir}: return {inference['returns']['mean']:.2f}, "
          f"{inference['inference_time_ms']['median']:.4f} ms/call; "
          f"generalization {generalization['sum_of_mean_returns']:.2f}")


if __name__ == "__main__":
    main()

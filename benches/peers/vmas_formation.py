"""The issue's VMAS peer of `echelon.envs.bench`, run on the same machine:
E environments of N differential-drive robots (VMAS's `DiffDrive`
dynamics, RK4, no collisions, float32 on the CPU) holding slots behind a
virtual leader on a circle, each robot observing what `echelon.envs` gives
(its tracking error in its frame, its leader's velocity in its frame, its
slot), stepped in a Python loop under the kinematic law computed from those
observations in torch — VMAS's way of timing a scenario with its heuristic
policy. Agent-steps per second, with torch on 2 threads.

    pip install vmas torch   # not in the project's requirements: gigabytes
    python benches/peers/vmas_formation.py [--steps 100] [--runs 3]
"""

from __future__ import annotations

import argparse
import time

import torch
import vmas
from vmas.simulator.core import Agent, Sphere, World
from vmas.simulator.dynamics.diff_drive import DiffDrive
from vmas.simulator.scenario import BaseScenario

V_MAX, W_MAX, KE = 0.5, 2.0, 1.0


class Formation(BaseScenario):
    """N robots behind a leader of constant speed and turn rate (eq. 18),
    slots on a lattice one metre apart, as `echelon.envs` draws them."""

    def make_world(self, batch_dim: int, device: torch.device, **kwargs) -> World:
        n, dt = kwargs.get("n_agents", 10), kwargs.get("dt", 0.01)
        self.n, self.dt, self.batch = n, dt, batch_dim
        world = World(batch_dim, device, dt=dt, drag=0.0)
        for i in range(n):
            world.add_agent(
                Agent(
                    name=f"robot_{i}",
                    collide=False,
                    shape=Sphere(0.05),
                    u_range=[V_MAX, W_MAX],
                    u_multiplier=[1.0, 1.0],
                    dynamics=DiffDrive(world, integration="rk4"),
                )
            )
        width = int(n**0.5 + 0.999)
        self.slots = torch.tensor(
            [[(m // width + 1.0), -((m % width) - 0.5 * (width - 1))] for m in range(n)], device=device
        )
        self.t = torch.zeros(batch_dim, device=device)
        self.heading = torch.zeros(batch_dim, device=device)
        self.speed = torch.zeros(batch_dim, device=device)
        self.turn = torch.zeros(batch_dim, device=device)
        return world

    def reset_world_at(self, env_index: int | None = None) -> None:
        idx = slice(None) if env_index is None else env_index
        size = self.batch if env_index is None else 1
        dev = self.world.device
        self.t[idx] = 0.0
        self.heading[idx] = (torch.rand(size, device=dev) * 2 - 1) * torch.pi
        self.speed[idx] = 0.05 + 0.15 * torch.rand(size, device=dev)
        self.turn[idx] = (torch.rand(size, device=dev) * 2 - 1) * 0.1
        h = self.heading[idx]
        c, s = torch.cos(h), torch.sin(h)
        for i, agent in enumerate(self.world.agents):
            lx, ly = self.slots[i]
            pos = torch.stack([-(lx * c - ly * s), -(lx * s + ly * c)], dim=-1)
            pos = pos + 0.2 * (torch.rand(size, 2, device=dev) - 0.5)
            agent.set_pos(pos.reshape(-1, 2), batch_index=env_index)
            agent.set_rot(h.reshape(-1, 1), batch_index=env_index)
        self.p, self.dp = self.leader()

    def post_step(self) -> None:
        self.t += self.dt
        self.p, self.dp = self.leader()

    def leader(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The leader's position and velocity now (eq. 18), once a step."""
        th = self.heading + self.turn * self.t
        half = 0.5 * self.turn * self.t
        sinc = torch.where(half.abs() < 1e-4, 1 - half * half / 6, torch.sin(half) / torch.where(half == 0, 1.0, half))
        chord = self.speed * self.t * sinc
        p = torch.stack([chord * torch.cos(self.heading + half), chord * torch.sin(self.heading + half)], dim=-1)
        dp = torch.stack([self.speed * torch.cos(th), self.speed * torch.sin(th)], dim=-1)
        return p, dp

    def error(self, agent: Agent) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """The robot's tracking error (eq. 7) in its frame, its heading's cos and sin, its index."""
        i = self.world.agents.index(agent)
        th = agent.state.rot[:, 0]
        c, s = torch.cos(th), torch.sin(th)
        d = agent.state.pos - self.p
        lx, ly = self.slots[i]
        e = torch.stack([c * d[:, 0] + s * d[:, 1] + lx, -s * d[:, 0] + c * d[:, 1] + ly], dim=-1)
        return e, c, s, i

    def observation(self, agent: Agent) -> torch.Tensor:
        e, c, s, i = self.error(agent)
        dp = self.dp
        q = torch.stack([c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1]], dim=-1)
        slot = self.slots[i].expand(self.batch, 2)
        return torch.cat([e, q, slot], dim=-1)

    def reward(self, agent: Agent) -> torch.Tensor:
        e = self.error(agent)[0]
        return -(e * e).sum(-1)


def law(obs: torch.Tensor) -> torch.Tensor:
    """The kinematic law from an observation: ξ* = R ṗ_d − k_e e, ω* = ξ*₂/L_X, v* = ξ*₁ + ω* L_Y."""
    xi = obs[:, 2:4] - KE * obs[:, 0:2]
    omega = xi[:, 1] / obs[:, 4]
    return torch.stack([xi[:, 0] + omega * obs[:, 5], omega], dim=-1)


def bench(num_envs: int, n: int, steps: int, dt: float) -> float:
    env = vmas.make_env(Formation(), num_envs=num_envs, device="cpu", continuous_actions=True, clamp_actions=True, seed=0, n_agents=n, dt=dt)
    obs = env.reset()
    for _ in range(10):
        obs, _, _, _ = env.step([law(o) for o in obs])
    start = time.perf_counter()
    for _ in range(steps):
        obs, _, _, _ = env.step([law(o) for o in obs])
    return num_envs * n * steps / (time.perf_counter() - start)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--dt", type=float, default=0.01)
    args = ap.parse_args()
    torch.set_num_threads(2)
    for e, n in [(1000, 10), (100, 100), (10000, 1)]:
        rates = [bench(e, n, args.steps, args.dt) / 1e6 for _ in range(args.runs)]
        print(f"VMAS {vmas.__version__}, torch {torch.__version__}, {e} x {n}: " + ", ".join(f"{r:.2f}" for r in rates) + " M agent-steps/s", flush=True)


if __name__ == "__main__":
    main()

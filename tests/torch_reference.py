"""Reference updates written the way PyTorch users write them, after CORL's td3_bc.py, edac.py, rebrac.py, iql.py and
finetune/awac.py, from the published equations: the other side of tests/test_parity_torch.py, which checks in
float64 that our JAX updates equal these.  `benchmarks.pytorch` also times the TD3+BC and EDAC ones against the JAX
driver.

Defaults are the benchmark's shapes: hopper (obs 11, act 3), 100k random transitions, batch 256, default sizes
(TD3+BC: 2x256 + LayerNorm, twin critics, policy delay 2; EDAC: 3x256 + LayerNorm, N = 10 vectorised critics,
eta = 1), one seed.  Like CORL, the TD3+BC actor loss evaluates critic 1 only, and the EDAC diversity loss runs its
own second forward pass of the ensemble (CORL's `_critic_diversity_loss`).  The classes take keyword arguments
beyond those (sizes, LayerNorm form, what a TD target treats as done, the tanh log-det form, a log-alpha bound,
injected sampling noise, the pre-training updates) so the parity tests can match every switch of ours.

Needs torch (`pip install -e .[torch]`); nothing in the package imports this module.
"""
from __future__ import annotations

import copy
import math

import torch
import torch.nn.functional as F
from torch import nn

OBS_DIM, ACT_DIM, BATCH, ROWS = 11, 3, 256, 100_000


def mlp(in_dim: int, hidden: tuple[int, ...], out_dim: int, layer_norm: bool = True, ln_affine: bool = True,
        ln_eps: float = 1e-5) -> nn.Sequential:
    layers: list[nn.Module] = []
    for width in hidden:
        norm = [nn.LayerNorm(width, eps=ln_eps, elementwise_affine=ln_affine)] if layer_norm else []
        layers += [nn.Linear(in_dim, width), *norm, nn.ReLU()]
        in_dim = width
    return nn.Sequential(*layers, nn.Linear(in_dim, out_dim))


def polyak(net: nn.Module, target: nn.Module, tau: float) -> None:
    """target <- tau * net + (1 - tau) * target, in place."""
    with torch.no_grad():
        for p, tp in zip(net.parameters(), target.parameters()):
            tp.data.mul_(1 - tau).add_(tau * p.data)


class Replay:
    def __init__(self, seed: int = 0):
        g = torch.Generator().manual_seed(seed)
        self.obs = torch.randn(ROWS, OBS_DIM, generator=g)
        self.next_obs = torch.randn(ROWS, OBS_DIM, generator=g)
        self.act = torch.rand(ROWS, ACT_DIM, generator=g) * 2 - 1
        self.rew = 1.0 + 0.1 * self.obs[:, :1]
        self.done = torch.zeros(ROWS, 1)

    def sample(self):
        idx = torch.randint(0, ROWS, (BATCH,))
        return self.obs[idx], self.act[idx], self.rew[idx], self.next_obs[idx], self.done[idx]


# ----------------------------------------------------------------------------------------------------------- TD3+BC


class Critic(nn.Module):
    def __init__(self, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM, hidden: tuple[int, ...] = (256, 256),
                 **ln):
        super().__init__()
        self.net = mlp(obs_dim + act_dim, hidden, 1, **ln)

    def forward(self, s, a):
        return self.net(torch.cat([s, a], 1))


class TD3BC:
    """CORL's TD3+BC.  `train(batch)` is one update of the offline-RL phase (critic every call, actor and targets
    every `policy_freq` calls); `bc_update` / `mc_update` are the pre-training updates (BC on the actor, Monte-Carlo
    regression on the critics, each followed by its targets' Polyak update).  batch = (state, action, reward,
    next_state, done), reward and done (B, 1); `done` is whatever stops bootstrapping (terminal, or terminal or
    time-out)."""

    def __init__(self, alpha: float = 10.0, gamma: float = 0.99, tau: float = 0.005, policy_noise: float = 0.2,
                 noise_clip: float = 0.5, policy_freq: int = 2, lr: float = 3e-4, obs_dim: int = OBS_DIM,
                 act_dim: int = ACT_DIM, hidden: tuple[int, ...] = (256, 256),
                 actor_hidden: tuple[int, ...] | None = None, ln_affine: bool = True, ln_eps: float = 1e-5):
        ln = dict(ln_affine=ln_affine, ln_eps=ln_eps)
        self.actor = mlp(obs_dim, actor_hidden or hidden, act_dim, **ln)
        self.actor_target = copy.deepcopy(self.actor)
        self.critic_1, self.critic_2 = Critic(obs_dim, act_dim, hidden, **ln), Critic(obs_dim, act_dim, hidden, **ln)
        self.critic_1_target, self.critic_2_target = copy.deepcopy(self.critic_1), copy.deepcopy(self.critic_2)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=lr)
        self.critic_1_opt = torch.optim.Adam(self.critic_1.parameters(), lr=lr)
        self.critic_2_opt = torch.optim.Adam(self.critic_2.parameters(), lr=lr)
        self.alpha, self.gamma, self.tau = alpha, gamma, tau
        self.policy_noise, self.noise_clip, self.policy_freq = policy_noise, noise_clip, policy_freq
        self.total_it = 0

    def td_target(self, reward, next_state, done):
        with torch.no_grad():
            next_action = torch.tanh(self.actor_target(next_state))
            noise = (torch.randn_like(next_action) * self.policy_noise).clamp(-self.noise_clip, self.noise_clip)
            next_action = (next_action + noise).clamp(-1.0, 1.0)
            target_q = torch.min(self.critic_1_target(next_state, next_action),
                                 self.critic_2_target(next_state, next_action))
            return reward + (1 - done) * self.gamma * target_q

    def critic_step(self, critic_loss) -> None:
        self.critic_1_opt.zero_grad()
        self.critic_2_opt.zero_grad()
        critic_loss.backward()
        self.critic_1_opt.step()
        self.critic_2_opt.step()

    def update_targets(self, actor: bool = True) -> None:
        polyak(self.critic_1, self.critic_1_target, self.tau)
        polyak(self.critic_2, self.critic_2_target, self.tau)
        if actor:
            polyak(self.actor, self.actor_target, self.tau)

    def train(self, batch) -> None:
        self.total_it += 1
        state, action, reward, next_state, done = batch
        target_q = self.td_target(reward, next_state, done)
        self.critic_step(F.mse_loss(self.critic_1(state, action), target_q)
                         + F.mse_loss(self.critic_2(state, action), target_q))
        if self.total_it % self.policy_freq == 0:
            pi = torch.tanh(self.actor(state))
            q = self.critic_1(state, pi)
            lmbda = self.alpha / q.abs().mean().detach()
            actor_loss = -lmbda * q.mean() + F.mse_loss(pi, action)
            self.actor_opt.zero_grad()
            actor_loss.backward()
            self.actor_opt.step()
            self.update_targets()

    def bc_update(self, batch) -> None:
        """Pre-training: one BC (MSE) step on the actor, then the actor target's Polyak update."""
        state, action = batch[:2]
        loss = F.mse_loss(torch.tanh(self.actor(state)), action)
        self.actor_opt.zero_grad()
        loss.backward()
        self.actor_opt.step()
        polyak(self.actor, self.actor_target, self.tau)

    def mc_update(self, batch, returns, lam: float = 0.0) -> None:
        """Pre-training: one critic step on the Monte-Carlo returns (B, 1), the authors' lambda mixing with TD
        (1 - lam) L_MC / sg(L_MC) + lam L_TD / sg(L_TD) when lam > 0, then the critic targets' Polyak update."""
        state, action, reward, next_state, done = batch
        q1, q2 = self.critic_1(state, action), self.critic_2(state, action)
        loss = F.mse_loss(q1, returns) + F.mse_loss(q2, returns)
        if lam > 0:
            target_q = self.td_target(reward, next_state, done)
            td = F.mse_loss(q1, target_q) + F.mse_loss(q2, target_q)
            loss = (1 - lam) * loss / loss.detach() + lam * td / td.detach()
        self.critic_step(loss)
        self.update_targets(actor=False)


# ------------------------------------------------------------------------------------------------------------- EDAC


class VectorizedLinear(nn.Module):
    def __init__(self, in_features: int, out_features: int, ensemble_size: int):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(ensemble_size, in_features, out_features))
        self.bias = nn.Parameter(torch.empty(ensemble_size, 1, out_features))
        for layer in range(ensemble_size):
            nn.init.kaiming_uniform_(self.weight[layer], a=math.sqrt(5))
        nn.init.uniform_(self.bias, -1 / math.sqrt(in_features), 1 / math.sqrt(in_features))

    def forward(self, x):  # (N, B, in) -> (N, B, out)
        return x @ self.weight + self.bias


class VectorizedCritic(nn.Module):
    """CORL's ensemble.  Its LayerNorms, with affine parameters, share them across the members."""

    def __init__(self, num_critics: int, hidden: int | tuple[int, ...] = 256, depth: int = 3, obs_dim: int = OBS_DIM,
                 act_dim: int = ACT_DIM, ln_affine: bool = True, ln_eps: float = 1e-5):
        super().__init__()
        widths = (hidden,) * depth if isinstance(hidden, int) else tuple(hidden)
        layers: list[nn.Module] = []
        in_dim = obs_dim + act_dim
        for width in widths:
            layers += [VectorizedLinear(in_dim, width, num_critics),
                       nn.LayerNorm(width, eps=ln_eps, elementwise_affine=ln_affine), nn.ReLU()]
            in_dim = width
        layers.append(VectorizedLinear(in_dim, 1, num_critics))
        self.critic = nn.Sequential(*layers)
        self.num_critics = num_critics

    def forward(self, state, action):
        sa = torch.cat([state, action], dim=-1)
        if sa.dim() != 3:
            sa = sa.unsqueeze(0).repeat_interleave(self.num_critics, dim=0)
        return self.critic(sa).squeeze(-1)  # (N, B)


class Actor(nn.Module):
    """Tanh-Gaussian actor.  `forward(state, noise)` samples a = tanh(mu + sigma * noise), noise ~ N(0, 1) unless
    given; log_det "eps": log(1 - a^2 + 1e-6) (CORL), "exact": 2 (log 2 - u - softplus(-2u)) (torch's
    TanhTransform)."""

    def __init__(self, hidden: int | tuple[int, ...] = 256, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM,
                 ln_affine: bool = True, ln_eps: float = 1e-5, log_det: str = "eps"):
        super().__init__()
        widths = (hidden,) * 3 if isinstance(hidden, int) else tuple(hidden)
        layers: list[nn.Module] = []
        in_dim = obs_dim
        for width in widths:
            layers += [nn.Linear(in_dim, width), nn.LayerNorm(width, eps=ln_eps, elementwise_affine=ln_affine),
                       nn.ReLU()]
            in_dim = width
        self.trunk = nn.Sequential(*layers)
        self.mu, self.log_sigma = nn.Linear(in_dim, act_dim), nn.Linear(in_dim, act_dim)
        self.log_det = log_det

    def dist(self, state):
        h = self.trunk(state)
        mu, log_sigma = self.mu(h), torch.clip(self.log_sigma(h), -5, 2)
        return torch.distributions.Normal(mu, torch.exp(log_sigma))

    def log_prob_pre_tanh(self, dist, u):
        if self.log_det == "eps":
            log_det = torch.log(1 - torch.tanh(u).pow(2) + 1e-6)
        else:
            log_det = 2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))
        return dist.log_prob(u).sum(-1) - log_det.sum(-1)

    def forward(self, state, noise=None):
        dist = self.dist(state)
        action = dist.rsample() if noise is None else dist.loc + dist.scale * noise
        return torch.tanh(action), self.log_prob_pre_tanh(dist, action)

    def log_prob(self, state, action, eps: float = 1e-6):
        """log pi(action | state) of a dataset action, clipped to +-(1 - eps) before atanh."""
        return self.log_prob_pre_tanh(self.dist(state), torch.atanh(action.clamp(-1 + eps, 1 - eps)))


class EDAC:
    """CORL's EDAC.  `update(batch, noise)`: temperature, actor, critic (+ target), in that order, each step seeing
    the one before; `noise` = (temperature's, actor's, TD target's) standard-normal draws, each (B, act_dim), or None
    to sample.  `log_alpha_bound` > 0 clips the alpha `update` uses, not log alpha itself.  `pretrain_actor_update`
    (temperature + soft BC) and `pretrain_critic_update` (regression on soft returns, mean over critics, + eta *
    diversity) are the paper's pre-training updates."""

    def __init__(self, num_critics: int = 10, eta: float = 1.0, gamma: float = 0.99, tau: float = 0.005,
                 lr: float = 3e-4, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM,
                 hidden: int | tuple[int, ...] = 256, actor_hidden: int | tuple[int, ...] | None = None,
                 ln_affine: bool = True, ln_eps: float = 1e-5, log_det: str = "eps", log_alpha_bound: float = 0.0):
        ln = dict(ln_affine=ln_affine, ln_eps=ln_eps)
        self.actor = Actor(actor_hidden or hidden, obs_dim, act_dim, log_det=log_det, **ln)
        self.critic = VectorizedCritic(num_critics, hidden, obs_dim=obs_dim, act_dim=act_dim, **ln)
        self.target_critic = copy.deepcopy(self.critic)
        self.log_alpha = torch.tensor([0.0], requires_grad=True)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=lr)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=lr)
        self.alpha_opt = torch.optim.Adam([self.log_alpha], lr=lr)
        self.alpha = self.log_alpha.exp().detach()
        self.num_critics, self.eta, self.gamma, self.tau = num_critics, eta, gamma, tau
        self.target_entropy = -float(act_dim)
        self.log_alpha_bound = log_alpha_bound

    def diversity_loss(self, state, action):
        n = self.num_critics
        state = state.unsqueeze(0).repeat_interleave(n, dim=0)
        action = action.unsqueeze(0).repeat_interleave(n, dim=0).requires_grad_(True)
        q_ensemble = self.critic(state, action)
        grads = torch.autograd.grad(q_ensemble.sum(), action, retain_graph=True, create_graph=True)[0]
        grads = grads / (torch.norm(grads, p=2, dim=2).unsqueeze(-1) + 1e-10)
        grads = grads.transpose(0, 1)
        masks = torch.eye(n, dtype=grads.dtype).unsqueeze(0).repeat(grads.shape[0], 1, 1)
        gram = (1 - masks) * (grads @ grads.permute(0, 2, 1))
        return gram.sum(dim=(1, 2)).mean() / (n - 1)

    def temperature_update(self, state, noise=None, clip: bool = True) -> None:
        with torch.no_grad():
            _, log_prob = self.actor(state, noise)
        alpha_loss = (-self.log_alpha * (log_prob + self.target_entropy)).mean()
        self.alpha_opt.zero_grad()
        alpha_loss.backward()
        self.alpha_opt.step()
        bound = self.log_alpha_bound
        self.alpha = (self.log_alpha.clamp(-bound, bound) if clip and bound > 0 else self.log_alpha).exp().detach()

    def critic_step(self, loss) -> None:
        self.critic_opt.zero_grad()
        loss.backward()
        self.critic_opt.step()
        polyak(self.critic, self.target_critic, self.tau)

    def update(self, batch, noise=None) -> None:
        state, action, reward, next_state, done = batch
        noise_alpha, noise_actor, noise_target = (None, None, None) if noise is None else noise
        self.temperature_update(state, noise_alpha)

        pi, log_prob = self.actor(state, noise_actor)
        actor_loss = (self.alpha * log_prob - self.critic(state, pi).min(0).values).mean()
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()

        with torch.no_grad():
            next_action, next_log_prob = self.actor(next_state, noise_target)
            q_next = self.target_critic(next_state, next_action).min(0).values - self.alpha * next_log_prob
            target = reward.squeeze(-1) + self.gamma * (1 - done.squeeze(-1)) * q_next
        q = self.critic(state, action)
        critic_loss = ((q - target.view(1, -1)) ** 2).mean(dim=1).sum(dim=0)
        self.critic_step(critic_loss + self.eta * self.diversity_loss(state, action))

    def pretrain_actor_update(self, batch, noise=None) -> None:
        """Temperature step (no clipping), then soft BC E[alpha log pi(a~|s) - log pi(a|s)] on the actor."""
        state, action = batch[:2]
        noise_alpha, noise_actor = (None, None) if noise is None else noise
        self.temperature_update(state, noise_alpha, clip=False)
        _, log_prob = self.actor(state, noise_actor)
        loss = (self.alpha * log_prob - self.actor.log_prob(state, action)).mean()
        self.actor_opt.zero_grad()
        loss.backward()
        self.actor_opt.step()

    def pretrain_critic_update(self, batch, soft_returns) -> None:
        """Regression on the soft returns-to-go (B,), mean over the critics, + eta * diversity."""
        state, action = batch[:2]
        q = self.critic(state, action)
        loss = ((q - soft_returns.view(1, -1)) ** 2).mean(dim=1).mean(dim=0)
        self.critic_step(loss + self.eta * self.diversity_loss(state, action))


# ----------------------------------------------------------------------------------------------------------- ReBRAC


def ensemble_q(critics, s, a):
    """(N, B): every critic's Q(s, a), for ReBRAC's and IQL's twin critics (an nn.ModuleList of MLPs)."""
    return torch.stack([c(torch.cat([s, a], 1))[:, 0] for c in critics])


class ReBRAC:
    """CORL's ReBRAC update (Tarasov et al. 2023), for the parity tests: `update(batch, next_actions)` is one offline
    step (the critics on every call; on every `policy_freq`-th, counting from the first, the actor on the same
    minibatch after the critics, then every target).  The target policy's smoothing noise is left out
    (`policy_noise` 0 in the tests), so both sides draw nothing."""

    def __init__(self, actor_beta: float, critic_beta: float, gamma: float = 0.99, tau: float = 0.005,
                 policy_freq: int = 2, actor_lr: float = 1e-3, critic_lr: float = 1e-3, obs_dim: int = OBS_DIM,
                 act_dim: int = ACT_DIM, hidden: tuple[int, ...] = (256, 256, 256), ln_affine: bool = True,
                 ln_eps: float = 1e-6):
        self.actor = mlp(obs_dim, hidden, act_dim, layer_norm=False)
        ln = dict(ln_affine=ln_affine, ln_eps=ln_eps)
        self.critics = nn.ModuleList([mlp(obs_dim + act_dim, hidden, 1, **ln) for _ in range(2)])
        self.actor_target, self.critics_target = copy.deepcopy(self.actor), copy.deepcopy(self.critics)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=actor_lr)
        self.critic_opt = torch.optim.Adam(self.critics.parameters(), lr=critic_lr)
        self.actor_beta, self.critic_beta, self.gamma, self.tau = actor_beta, critic_beta, gamma, tau
        self.policy_freq, self.step = policy_freq, 0

    def update(self, batch, next_actions) -> None:
        state, action, reward, next_state, done = batch
        with torch.no_grad():
            next_pi = torch.tanh(self.actor_target(next_state))
            penalty = ((next_pi - next_actions) ** 2).sum(-1)
            next_q = ensemble_q(self.critics_target, next_state, next_pi).min(0).values - self.critic_beta * penalty
            target = reward[:, 0] + self.gamma * (1 - done[:, 0]) * next_q
        loss = ((ensemble_q(self.critics, state, action) - target[None]) ** 2).mean(1).sum(0)
        self.critic_opt.zero_grad()
        loss.backward()
        self.critic_opt.step()
        if self.step % self.policy_freq == 0:
            pi = torch.tanh(self.actor(state))
            q = ensemble_q(self.critics, state, pi).min(0).values
            lmbda = 1 / q.abs().mean().detach()
            actor_loss = (self.actor_beta * ((pi - action) ** 2).sum(-1) - lmbda * q).mean()
            self.actor_opt.zero_grad()
            actor_loss.backward()
            self.actor_opt.step()
            polyak(self.actor, self.actor_target, self.tau)
            polyak(self.critics, self.critics_target, self.tau)
        self.step += 1


# -------------------------------------------------------------------------------------------------------------- IQL


class IQL:
    """CORL's IQL update (Kostrikov et al. 2022), for the parity tests: `update(batch)` is V (expectile regression on
    the target twin critics' min), then Q (on r + gamma (1 - d) V(s'), V(s') from before the V step; Polyak), then
    the actor (exp(beta A) clipped at 100 times the dataset action's negative log-likelihood under a Gaussian with a
    state-independent std, or its squared error for a deterministic actor) with a cosine learning-rate schedule."""

    def __init__(self, expectile: float = 0.7, beta: float = 3.0, gamma: float = 0.99, tau: float = 0.005,
                 lr: float = 3e-4, lr_steps: int = 1_000_000, deterministic: bool = False, obs_dim: int = OBS_DIM,
                 act_dim: int = ACT_DIM, hidden: tuple[int, ...] = (256, 256), log_std_bounds=(-20.0, 2.0)):
        self.actor = mlp(obs_dim, hidden, act_dim, layer_norm=False)
        self.log_std = nn.Parameter(torch.zeros(act_dim))
        self.critics = nn.ModuleList([mlp(obs_dim + act_dim, hidden, 1, layer_norm=False) for _ in range(2)])
        self.critics_target = copy.deepcopy(self.critics)
        self.value = mlp(obs_dim, hidden, 1, layer_norm=False)
        actor_params = list(self.actor.parameters()) + ([] if deterministic else [self.log_std])
        self.actor_opt = torch.optim.Adam(actor_params, lr=lr)
        self.schedule = torch.optim.lr_scheduler.CosineAnnealingLR(self.actor_opt, lr_steps)
        self.critic_opt = torch.optim.Adam(self.critics.parameters(), lr=lr)
        self.value_opt = torch.optim.Adam(self.value.parameters(), lr=lr)
        self.expectile, self.beta, self.gamma, self.tau = expectile, beta, gamma, tau
        self.deterministic, self.log_std_bounds = deterministic, log_std_bounds

    def update(self, batch) -> None:
        state, action, reward, next_state, done = batch
        with torch.no_grad():
            next_v = self.value(next_state)[:, 0]
            target_q = ensemble_q(self.critics_target, state, action).min(0).values
        adv = target_q - self.value(state)[:, 0]
        v_loss = (torch.abs(self.expectile - (adv < 0).double()) * adv ** 2).mean()
        self.value_opt.zero_grad()
        v_loss.backward()
        self.value_opt.step()
        target = reward[:, 0] + (1 - done[:, 0]) * self.gamma * next_v
        q = ensemble_q(self.critics, state, action)
        q_loss = sum(F.mse_loss(qi, target) for qi in q) / len(q)
        self.critic_opt.zero_grad()
        q_loss.backward()
        self.critic_opt.step()
        polyak(self.critics, self.critics_target, self.tau)
        weight = torch.exp(self.beta * adv.detach()).clamp(max=100.0)
        mean = torch.tanh(self.actor(state))
        if self.deterministic:
            nll = ((mean - action) ** 2).sum(1)
        else:
            std = torch.exp(self.log_std.clamp(*self.log_std_bounds))
            nll = -torch.distributions.Normal(mean, std).log_prob(action).sum(-1)
        actor_loss = (weight * nll).mean()
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()
        self.schedule.step()


# ------------------------------------------------------------------------------------------------------------- AWAC


class AWACActor(nn.Module):
    """CORL's AWAC actor: a Gaussian with an unsquashed mean and a state-independent log std clamped to [-20, 2];
    its samples are clamped to [-1, 1].  `forward` takes the standard-normal noise of its `rsample` as an argument."""

    def __init__(self, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM, hidden: tuple[int, ...] = (256, 256, 256)):
        super().__init__()
        self._mlp = mlp(obs_dim, hidden, act_dim, layer_norm=False)
        self._log_std = nn.Parameter(torch.zeros(act_dim))

    def _get_policy(self, state):
        return torch.distributions.Normal(self._mlp(state), self._log_std.clamp(-20.0, 2.0).exp())

    def log_prob(self, state, action):
        return self._get_policy(state).log_prob(action).sum(-1, keepdim=True)

    def forward(self, state, noise):
        policy = self._get_policy(state)
        action = policy.loc + policy.scale * noise  # rsample() with this noise
        return action.clamp(-1.0, 1.0)


class AWAC:
    """CORL's `AdvantageWeightedActorCritic` (finetune/awac.py), for the parity tests: `update(batch, noise)` is the
    critics (each its own Adam; r + gamma (1 - d) min of the target critics at a clamped policy sample of s', no
    entropy; q1_loss + q2_loss), then the actor (exp((min Q(s, a) - min Q(s, a~)) / lambda) clamped at 100 times
    -log pi(a | s), a~ a clamped sample, from the critics just updated), then both targets' Polyak update.  `noise`:
    the two draws, TD target's then actor's."""

    def __init__(self, awac_lambda: float = 1.0, gamma: float = 0.99, tau: float = 0.005, lr: float = 3e-4,
                 obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM, hidden: tuple[int, ...] = (256, 256, 256),
                 exp_adv_max: float = 100.0):
        self.actor = AWACActor(obs_dim, act_dim, hidden)
        self.critics = nn.ModuleList([mlp(obs_dim + act_dim, hidden, 1, layer_norm=False) for _ in range(2)])
        self.critics_target = copy.deepcopy(self.critics)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=lr)
        self.critic_opts = [torch.optim.Adam(c.parameters(), lr=lr) for c in self.critics]
        self.awac_lambda, self.gamma, self.tau, self.exp_adv_max = awac_lambda, gamma, tau, exp_adv_max

    def q(self, critics, s, a):
        return torch.min(critics[0](torch.cat([s, a], 1)), critics[1](torch.cat([s, a], 1)))

    def update(self, batch, noise) -> None:
        state, action, reward, next_state, done = batch
        with torch.no_grad():
            q_next = self.q(self.critics_target, next_state, self.actor(next_state, noise[0]))
            q_target = reward + self.gamma * (1.0 - done) * q_next
        sa = torch.cat([state, action], 1)
        critic_loss = F.mse_loss(self.critics[0](sa), q_target) + F.mse_loss(self.critics[1](sa), q_target)
        for opt in self.critic_opts:
            opt.zero_grad()
        critic_loss.backward()
        for opt in self.critic_opts:
            opt.step()
        with torch.no_grad():
            v = self.q(self.critics, state, self.actor(state, noise[1]))
            adv = self.q(self.critics, state, action) - v
            weights = torch.clamp_max(torch.exp(adv / self.awac_lambda), self.exp_adv_max)
        actor_loss = (-self.actor.log_prob(state, action) * weights).mean()
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()
        polyak(self.critics, self.critics_target, self.tau)


# ------------------------------------------------------------------------------------------------------ CQL, Cal-QL


class CalQL:
    """CORL's Cal-QL update (cal_ql.py; Nakamoto et al. 2023), which with `calibrate=False` is its CQL (cql.py).

    Twin critics (MLPs, no LayerNorm), a tanh-Gaussian actor whose last layer gives the mean and the raw log-std
    (log-std = raw + `log_std_offset`, clipped to [-20, 2]; CORL's multiplier and offset are trainable scalars, held
    constant here as ours are), a learned temperature (Adam at the policy learning rate), no entropy in the backup.
    `update(batch, returns, noise, random_actions)` computes the temperature, actor and critic losses from the incoming
    parameters, then steps all three and moves the target critics.  The critic loss is the two TD errors plus
    cql_alpha * (T logsumexp over [Q(s, a_rand) - A log 0.5, Q(s, a~pi(s)) - log pi, Q(s, a~pi(s')) - log pi'] / T
    - Q(s, a_data)), batch-mean, per critic; with `calibrate` the two policy-action Q sets are first replaced by
    max(Q, G(s)), G the row's Monte-Carlo return.  `noise`: the standard-normal draws of the temperature's, the
    actor's and the TD target's samples (B, A) each, and the penalty's at s and at s' (B, M, A) each (CORL's
    temperature and actor losses share one sample; here each has its own, as ours); `random_actions` (B, M, A)."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...], actor_hidden: tuple[int, ...],
                 actor_lr: float, critic_lr: float, gamma: float, tau: float, cql_alpha: float, temperature: float,
                 log_std_offset: float, calibrate: bool):
        self.actor = mlp(obs_dim, actor_hidden, 2 * act_dim, layer_norm=False)
        self.critics = nn.ModuleList([mlp(obs_dim + act_dim, hidden, 1, layer_norm=False) for _ in range(2)])
        self.critics_target = copy.deepcopy(self.critics)
        self.log_alpha = torch.tensor(0.0, requires_grad=True)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=actor_lr)
        self.critic_opt = [torch.optim.Adam(c.parameters(), lr=critic_lr) for c in self.critics]
        self.alpha_opt = torch.optim.Adam([self.log_alpha], lr=actor_lr)
        self.act_dim, self.gamma, self.tau, self.cql_alpha = act_dim, gamma, tau, cql_alpha
        self.temperature, self.log_std_offset, self.calibrate = temperature, log_std_offset, calibrate
        self.target_entropy = -float(act_dim)

    def sample(self, state, noise):
        """(tanh(u), log pi) for u = mean + std * noise, state (..., obs) -> ((..., A), (...,))."""
        mean, raw = torch.split(self.actor(state), self.act_dim, dim=-1)
        std = torch.exp(torch.clamp(raw + self.log_std_offset, -20.0, 2.0))
        u = mean + std * noise
        log_det = 2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))  # torch's TanhTransform
        return torch.tanh(u), (torch.distributions.Normal(mean, std).log_prob(u) - log_det).sum(-1)

    def q(self, critics, state, action):
        return [c(torch.cat([state, action], -1))[..., 0] for c in critics]

    def update(self, batch, returns, noise, random_actions) -> None:
        state, action, reward, next_state, done = batch
        noise_alpha, noise_actor, noise_target, noise_pi, noise_next = noise
        m = random_actions.shape[1]
        _, log_pi = self.sample(state, noise_alpha)
        alpha_loss = -(self.log_alpha * (log_pi + self.target_entropy).detach()).mean()
        alpha = self.log_alpha.exp().detach()
        pi, log_pi = self.sample(state, noise_actor)
        q1_pi, q2_pi = self.q(self.critics, state, pi)
        actor_loss = (alpha * log_pi - torch.min(q1_pi, q2_pi)).mean()

        with torch.no_grad():
            next_action, _ = self.sample(next_state, noise_target)
            target = reward[:, 0] + (1 - done[:, 0]) * self.gamma * torch.min(
                *self.q(self.critics_target, next_state, next_action))
            repeat = lambda x: x.unsqueeze(1).repeat_interleave(m, dim=1)  # noqa: E731  (B, D) -> (B, M, D)
            a_pi, logp_pi = self.sample(repeat(state), noise_pi)
            a_next, logp_next = self.sample(repeat(next_state), noise_next)
        critic_loss = 0.0
        q_data = self.q(self.critics, state, action)
        q_rand = self.q(self.critics, repeat(state), random_actions)
        q_cur = self.q(self.critics, repeat(state), a_pi)
        q_nxt = self.q(self.critics, repeat(state), a_next)
        bound = returns.view(-1, 1).repeat(1, m)
        for i in range(2):
            cur, nxt = q_cur[i], q_nxt[i]
            if self.calibrate:
                cur, nxt = torch.maximum(cur, bound), torch.maximum(nxt, bound)
            cat = torch.cat([q_rand[i] - math.log(0.5 ** self.act_dim), nxt - logp_next, cur - logp_pi], dim=1)
            ood = torch.logsumexp(cat / self.temperature, dim=1) * self.temperature
            critic_loss = critic_loss + F.mse_loss(q_data[i], target) + self.cql_alpha * (ood - q_data[i]).mean()

        self.alpha_opt.zero_grad()
        alpha_loss.backward()
        self.alpha_opt.step()
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()
        for opt in self.critic_opt:
            opt.zero_grad()
        critic_loss.backward()
        for opt in self.critic_opt:
            opt.step()
        polyak(self.critics, self.critics_target, self.tau)

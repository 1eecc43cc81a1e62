r"""Policy search on DMP weights behind one ask/tell interface.

Every optimiser proposes a batch of ``K`` exploratory roll-outs (:meth:`PolicySearch.ask`
returns an :class:`Exploration`), receives their rewards (:meth:`PolicySearch.tell`) and
updates its mean weights. A task (:class:`dmpopt.learning.RewardTask`) turns an
``Exploration`` into rewards in one batched call; :func:`optimise` runs the loop
(:meth:`PolicySearch.learn`). eNAC and eREINFORCE on a reward task run it as one compiled
(numba) loop: the same normal draws, rewards and updates as the rounds in Python, bit for
bit, without their per-round overhead (0.13 instead of 0.33 ms an update on the paper task,
``benchmarks/bench_learning.py``).

Two kinds of exploration:

*Action space* (:class:`EpisodicNAC`, :class:`EpisodicReinforce`), the Gaussian policy of
[dmpopt-paper] eq. (17): all roll-outs of a batch use the mean weights ``W``, and each
perturbs the acceleration command of every step by :math:`\epsilon_{k,t} \sim N(0, \sigma^2)`.
With :math:`\partial\mu_t/\partial w = \phi_t` (``features``), the log-likelihood gradient
summed over a roll-out is

.. math:: \psi_k = \nabla_W \sum_t \log\pi(\ddot y_{t,k}) =
          \sum_t \epsilon_{t,k}\, \phi_t / \sigma^2 ,
          \qquad \partial_{\log\sigma} \sum_t \log\pi = \sum_t (\epsilon_{t,k}^2/\sigma^2 - 1).

*Parameter space* (:class:`PIBB`, :class:`CMAES`): each roll-out uses its own weights
:math:`W + \delta_k` and a noise-free plan (PI-BB of Stulp & Sigaud 2012, CMA-ES of Hansen).

Rewards given to ``tell`` may be per step, shape (K, n_steps), or returns, shape (K,); every
method here is episodic and uses the return :math:`R_k = \sum_t r_{t,k}`, eq. (18), so
delayed rewards (everything at the last step) give the same updates.

Step rules of the gradient methods (``step_rule``): ``"constant"``
:math:`W \leftarrow W + \alpha g`; ``"kl"`` scales the step so that the Kullback-Leibler
divergence between the roll-out distributions before and after the update is ``step_size``,
:math:`\alpha = \sqrt{2\,\mathrm{step\_size} / (g^T F g)}` with ``F`` the exact Fisher matrix
of the policy, :math:`F = \sum_t \phi_t\phi_t^T / \sigma^2` per DOF. Both are divided by
``1 + decay * n_updates``: a fixed step keeps jumping around the optimum with the noise of the
estimate, a decaying one settles.
"""

from __future__ import annotations

import math
import threading
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np
from threadpoolctl import ThreadpoolController

from ..exceptions import InvalidInputError, MissingDependency, ShapeError
from ..validation import check_resources, integer, real, real_array
from .normals import fill_standard_normal, generator_state, set_generator_state
from .rewards import _plan_samples, _reward_kernel, _row_sums

__all__ = [
    "CMAES",
    "PIBB",
    "EpisodicNAC",
    "EpisodicReinforce",
    "Exploration",
    "LearningCurve",
    "PolicySearch",
    "enac_gradient",
    "make_method",
    "optimise",
    "reinforce_gradient",
]

STEP_RULES = ("constant", "kl")
_compile = numba.njit(cache=True, nogil=True, error_model="numpy")


@dataclass(frozen=True, eq=False)
class Exploration:
    """A batch of roll-outs to evaluate.

    Attributes
    ----------
    weights : ndarray, shape (K, n_dofs, n_basis)
        Forcing weights of each roll-out.
    acceleration_noise : ndarray, shape (K, n_actions, n_dofs) or None
        Perturbation of the acceleration command at each step (action-space exploration).
    """

    weights: np.ndarray
    acceleration_noise: np.ndarray | None = None

    @property
    def n_rollouts(self) -> int:
        """``K``."""
        return self.weights.shape[0]


def _as_returns(rewards, n_rollouts: int) -> np.ndarray:
    rewards = real_array(
        "rewards", rewards, fix="a failed roll-out needs a finite (e.g. very low) reward"
    )
    if rewards.ndim == 2:
        rewards = _row_sums(rewards)
    if rewards.shape != (n_rollouts,):
        raise ShapeError(
            f"rewards has shape {rewards.shape}, expected ({n_rollouts},) returns or "
            f"({n_rollouts}, n_steps) per-step rewards for the {n_rollouts} roll-outs asked"
        )
    if not np.all(np.isfinite(rewards)):
        raise InvalidInputError("rewards overflow when summed over the steps; rescale them")
    return rewards


@lru_cache(maxsize=1)
def _blas() -> ThreadpoolController:
    """The BLAS libraries loaded with NumPy, to run PI-BB's linear algebra on one thread."""
    return ThreadpoolController()


class _OneBlasThread:
    """Context in which BLAS runs on one thread; entries nested in one (``ask`` and ``tell``
    inside ``learn``) find the limit set and cost nothing. Setting and restoring the limit
    queries every loaded library: once per update it cost a quarter of a PI-BB run on the
    paper task (0.075 -> 0.057 CPU-s a run of 3,000 trials)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._depth = 0
        self._limiter = None

    def __enter__(self):
        with self._lock:
            if self._depth == 0:
                self._limiter = _blas().limit(limits=1, user_api="blas")
            self._depth += 1

    def __exit__(self, *exc):
        with self._lock:
            self._depth -= 1
            if self._depth == 0:
                self._limiter.restore_original_limits()
                self._limiter = None


_one_blas_thread = _OneBlasThread()


def _initial_weights(value) -> np.ndarray:
    weights = np.atleast_2d(real_array("initial_weights", value))
    if weights.ndim != 2:
        raise ShapeError(f"initial_weights has shape {weights.shape}, expected (n_dofs, n_basis)")
    return weights


def _check_sizes(n_rollouts: int, n_per_rollout: int, n_params: int, covariance: bool) -> None:
    """Refuse batches (and covariance matrices) beyond the allocation bound."""
    check_resources(
        f"{n_rollouts} roll-outs of {n_per_rollout} values each",
        8.0 * (n_rollouts * n_per_rollout),
        "lower n_rollouts",
    )
    if covariance:
        check_resources(
            f"a covariance over {n_params} weights",
            8.0 * (n_params**2),
            "learn fewer weights (fewer basis functions or DOFs)",
        )


def _scores_and_returns(scores, returns) -> tuple[np.ndarray, np.ndarray]:
    scores = real_array("scores", scores, ndim=2)
    returns = real_array("returns", returns, ndim=1)
    if returns.shape != (scores.shape[0],):
        raise ShapeError(
            f"returns has shape {returns.shape}, expected ({scores.shape[0]},): one per row "
            "of scores"
        )
    return scores, returns


def enac_gradient(scores, returns) -> tuple[np.ndarray, float]:
    r"""Natural gradient and baseline by regression, [dmpopt-paper] eq. (19).

    .. math:: [g^T, c]^T = (\Psi^T\Psi)^{-1}\Psi^T R,\qquad \Psi_k = [\psi_k^T, 1]

    Parameters
    ----------
    scores : ndarray, shape (K, n_params)
        Log-likelihood gradients summed over each roll-out.
    returns : ndarray, shape (K,)

    Returns
    -------
    natural_gradient : ndarray, shape (n_params,)
    baseline : float
    """
    scores, returns = _scores_and_returns(scores, returns)
    solution = _enac_solution(scores, returns)
    return solution[:-1], float(solution[-1])


@_compile
def _enac_solution(scores, returns):
    """``[g, c]`` of :func:`enac_gradient`: least squares by SVD (LAPACK ``gelsd``), singular
    values below ``eps * max(K, n_params + 1)`` of the largest dropped (NumPy's default)."""
    n_rollouts, n_params = scores.shape
    design = np.ones((n_rollouts, n_params + 1))
    design[:, :n_params] = scores
    rcond = np.finfo(np.float64).eps * max(n_rollouts, n_params + 1)
    return np.linalg.lstsq(design, returns, rcond=rcond)[0]


def reinforce_gradient(scores, returns) -> np.ndarray:
    r"""Episodic REINFORCE with the optimal (per-component) baseline.

    .. math:: g_h = \langle \psi_h (R - b_h)\rangle,\qquad
              b_h = \langle \psi_h^2 R\rangle / \langle \psi_h^2\rangle

    (Williams 1992; the variance-minimising baseline of Peters & Schaal 2008.)
    """
    scores, returns = _scores_and_returns(scores, returns)
    return _reinforce_direction(scores, returns)


@_compile
def _reinforce_direction(scores, returns):
    """:func:`reinforce_gradient`, summed roll-out by roll-out."""
    n_rollouts, n_params = scores.shape
    gradient = np.zeros(n_params)
    for h in range(n_params):
        weighted = 0.0
        total = 0.0
        for k in range(n_rollouts):
            squared = scores[k, h] * scores[k, h]
            weighted += squared * returns[k]
            total += squared
        baseline = weighted / max(total, 1e-300)
        for k in range(n_rollouts):
            gradient[h] += scores[k, h] * (returns[k] - baseline)
        gradient[h] /= n_rollouts
    return gradient


class PolicySearch(ABC):
    """Ask/tell interface: ``ask()`` a batch, evaluate it, ``tell(rewards)``, repeat.

    Optimisers are stateful objects (like ``cma``): ``mean`` is the current policy's weights,
    ``n_trials`` counts every exploratory roll-out told so far.
    """

    n_rollouts: int
    n_trials: int = 0
    n_updates: int = 0

    @property
    @abstractmethod
    def mean(self) -> np.ndarray:
        """Current weights, shape (n_dofs, n_basis)."""

    @abstractmethod
    def ask(self) -> Exploration:
        """The next batch of exploratory roll-outs."""

    @abstractmethod
    def tell(self, rewards) -> None:
        """Rewards of the last batch asked: (K,) returns or (K, n_steps) per-step rewards."""

    def learn(self, task, n_updates: int) -> list[np.ndarray]:
        """``n_updates`` rounds of ask, ``task.evaluate``, tell; the mean weights after each.

        The rounds run on one BLAS thread (set once, not per ``ask`` and ``tell``).
        """
        n_updates = integer("n_updates", n_updates, minimum=0)
        means = []
        with _one_blas_thread:
            for _ in range(n_updates):
                self.tell(task.evaluate(self.ask()))
                means.append(self.mean)
        return means

    def _pending_returns(self, rewards) -> tuple[np.ndarray, np.ndarray]:
        """The pending batch and the checked returns; the batch stays pending on an error."""
        if getattr(self, "_pending", None) is None:
            raise InvalidInputError("tell() called without a pending ask(); call ask() first")
        returns = _as_returns(rewards, self._pending.shape[0])
        pending, self._pending = self._pending, None
        return pending, returns


def _check_exploration_std(value) -> float:
    return real("exploration_std", value, minimum=0.0, open_minimum=True)


class _ActionSpaceGradient(PolicySearch):
    """Shared machinery of the likelihood-ratio methods on the policy of eq. (17)."""

    def __init__(
        self,
        features,
        initial_weights,
        exploration_std: float,
        n_rollouts: int = 20,
        step_size: float = 0.1,
        step_rule: str = "kl",
        decay: float = 0.0,
        learn_exploration: bool = False,
        seed=None,
    ):
        features = real_array("features", features)
        weights = _initial_weights(initial_weights)
        if features.ndim != 2 or features.shape[1] != weights.shape[1]:
            raise ShapeError(
                f"features has shape {features.shape}, expected (n_actions, {weights.shape[1]}) "
                f"to match initial_weights {weights.shape}"
            )
        exploration_std = _check_exploration_std(exploration_std)
        n_rollouts = integer("n_rollouts", n_rollouts, minimum=2)
        if not isinstance(step_rule, str) or step_rule not in STEP_RULES:
            raise InvalidInputError(f"step_rule must be one of {STEP_RULES}, got {step_rule!r}")
        n_params = weights.size + 1
        _check_sizes(n_rollouts, features.shape[0] * weights.shape[0], n_params, True)
        self.features = features
        self._weights = weights.copy()
        self.log_std = float(np.log(exploration_std))
        self.n_rollouts = n_rollouts
        self.step_size = real("step_size", step_size, minimum=0.0, open_minimum=True)
        self.step_rule = step_rule
        self.decay = real("decay", decay, minimum=0.0)
        self.learn_exploration = bool(learn_exploration)
        self.rng = np.random.default_rng(seed)
        self.n_trials = 0
        self.n_updates = 0
        self._pending = None
        # sum_t phi_t phi_t^T, one block per DOF: the Fisher matrix times sigma^2
        self._gram = features.T @ features
        self._blocks = np.kron(np.eye(weights.shape[0]), self._gram)

    @property
    def mean(self) -> np.ndarray:
        return self._weights.copy()

    @property
    def exploration_std(self) -> float:
        """Current :math:`\\sigma` [acceleration units]."""
        return math.exp(self.log_std)

    def ask(self) -> Exploration:
        k, (n_dofs, _) = self.n_rollouts, self._weights.shape
        noise = self.exploration_std * self.rng.standard_normal((k, self.features.shape[0], n_dofs))
        self._pending = noise
        weights = np.broadcast_to(self._weights, (k,) + self._weights.shape)
        return Exploration(weights=weights, acceleration_noise=noise)

    def scores(self, noise) -> np.ndarray:
        r"""Log-likelihood gradients summed over each roll-out, shape (K, n_params).

        Columns: the weights, flattened row-major (DOF, basis), then :math:`\log\sigma` if
        the exploration is learned.
        """
        noise = real_array("noise", noise, ndim=3)
        return _scores(noise, self.features, self.exploration_std**2, self.learn_exploration)

    def fisher(self) -> np.ndarray:
        """Exact Fisher matrix of the roll-out distribution, in the layout of :meth:`scores`."""
        n_dofs = self._weights.shape[0]
        blocks = self._blocks / self.exploration_std**2
        if not self.learn_exploration:
            return blocks
        size = blocks.shape[0] + 1
        fisher = np.zeros((size, size))
        fisher[:-1, :-1] = blocks
        fisher[-1, -1] = 2.0 * self.features.shape[0] * n_dofs
        return fisher

    def _rule(self) -> tuple:
        """The update's settings and count, as the compiled update functions take them."""
        kl = self.step_rule == "kl"
        return self.learn_exploration, self.natural, kl, self.step_size, self.decay, self.n_updates

    def _change(self, noise, returns) -> np.ndarray:
        """Change of ``[vec(W), log sigma]`` in one update (:func:`_gradient_change`)."""
        return _gradient_change(
            noise, returns, self.features, self._gram, self.exploration_std**2, *self._rule()
        )

    def _overflow(self, returns) -> InvalidInputError:
        return InvalidInputError(
            f"the update overflows: returns up to {np.max(np.abs(returns)):.3g} times "
            f"step_size = {self.step_size:g} (step_rule='constant') exceed the float range; "
            "rescale the rewards or lower step_size"
        )

    def _apply(self, change, returns, n_rollouts: int) -> None:
        if not np.all(np.isfinite(change)):
            raise self._overflow(returns)
        n = self._weights.size
        self._weights = self._weights + change[:n].reshape(self._weights.shape)
        if self.learn_exploration:
            self.log_std += float(change[n])
        self.n_trials += n_rollouts
        self.n_updates += 1

    def tell(self, rewards) -> None:
        noise, returns = self._pending_returns(rewards)
        self._apply(self._change(noise, returns), returns, noise.shape[0])

    def learn(self, task, n_updates: int) -> list[np.ndarray]:
        """``n_updates`` ask/evaluate/tell rounds on ``task``; the mean weights after each.

        On a task with ``reward_arrays()`` (:meth:`dmpopt.learning.RewardTask.reward_arrays`)
        the rounds run in one compiled loop: the same numbers as the rounds in Python (the
        same normal draws from ``rng``, the same reward and update functions) without their
        per-round overhead. ``rng`` must be NumPy's default ``PCG64`` generator for that (the
        loop draws its normals itself, :mod:`dmpopt.learning.normals`); another bit
        generator runs the rounds in Python.
        """
        words = generator_state(self.rng)
        if not hasattr(task, "reward_arrays") or words is None:
            return super().learn(task, n_updates)
        n_updates = integer("n_updates", n_updates, minimum=0)
        arrays = task.reward_arrays()
        means, log_stds, returns, done, status = _learn_action_space(
            words,
            n_updates,
            self.n_rollouts,
            self._weights,
            self.log_std,
            self.features,
            self._gram,
            *self._rule(),
            arrays[:6],  # the plan's rows (dmpopt.learning.rewards._plan_samples)
            *arrays[6:],
        )
        set_generator_state(self.rng, words)
        for u in range(done):
            self._weights, self.log_std = means[u].copy(), float(log_stds[u])
            self.n_trials += self.n_rollouts
            self.n_updates += 1
        if status == 1:
            raise InvalidInputError("rewards overflow when summed over the steps; rescale them")
        if status == 2:
            raise self._overflow(returns)
        return [means[u].copy() for u in range(done)]


@_compile
def _scores(noise, features, variance, learn_exploration):
    """:meth:`_ActionSpaceGradient.scores` of ``noise`` (K, n_actions, n_dofs)."""
    n_rollouts, n_actions, n_dofs = noise.shape
    n_basis = features.shape[1]
    n_weights = n_dofs * n_basis
    scores = np.zeros((n_rollouts, n_weights + (1 if learn_exploration else 0)))
    # sums over the steps in step order, the roll-outs side by side (innermost loop)
    sums = np.empty((n_basis, n_rollouts))
    epsilon = np.empty(n_rollouts)
    for d in range(n_dofs):
        sums[:] = 0.0
        for t in range(n_actions):
            for k in range(n_rollouts):
                epsilon[k] = noise[k, t, d]
            for i in range(n_basis):
                feature = features[t, i]
                for k in range(n_rollouts):
                    sums[i, k] += epsilon[k] * feature
        for k in range(n_rollouts):
            for i in range(n_basis):
                scores[k, d * n_basis + i] = sums[i, k] / variance
    for k in range(n_rollouts):
        if learn_exploration:
            total = 0.0
            for t in range(n_actions):
                for d in range(n_dofs):
                    total += noise[k, t, d] * noise[k, t, d] / variance - 1.0
            scores[k, n_weights] = total
    return scores


@_compile
def _gradient_change(
    noise, returns, features, gram, variance, learn_exploration, natural, kl, step, decay, n_updates
):
    """Change of ``[vec(W), log sigma]`` in one update of eNAC (``natural``) or eREINFORCE.

    Both gradients are linear in the returns: they are computed for returns scaled into
    [-1, 1] by a power of two (exact), so that returns near the float range do not overflow
    the direction and its curvature (a KL step then silently became 0). Equal returns carry
    no gradient (the KL rule would scale round-off to a full step). ``kl``: the step makes
    the KL divergence ``step`` (module docstring; ``gram = Phi^T Phi``, the Fisher matrix
    times sigma^2 per DOF), else ``W += step g``; divided by ``1 + decay n_updates``.
    Not finite if the update overflows.
    """
    largest = 0.0
    for value in returns:
        largest = max(largest, abs(value))
    scale = math.ldexp(1.0, math.frexp(largest)[1])
    scores = _scores(noise, features, variance, learn_exploration)
    scaled = returns / scale
    if natural:
        direction = _enac_solution(scores, scaled)[:-1].copy()
    else:
        direction = _reinforce_direction(scores, scaled)
    if not returns.max() - returns.min() > 0.0:
        direction[:] = 0.0
    if kl:  # the step does not depend on the scale of the returns
        n_basis = gram.shape[0]
        curvature = 0.0
        for d in range(noise.shape[2]):
            for i in range(n_basis):
                row = 0.0
                for j in range(n_basis):
                    row += gram[i, j] * direction[d * n_basis + j]
                curvature += direction[d * n_basis + i] * row
        curvature /= variance
        if learn_exploration:
            curvature += 2.0 * noise.shape[1] * noise.shape[2] * direction[-1] ** 2
        length = math.sqrt(2.0 * step / curvature) if curvature > 0 else 0.0
    else:
        length = step * scale
    length /= 1.0 + decay * n_updates
    return length * direction


@_compile
def _learn_action_space(
    words,
    n_updates,
    n_rollouts,
    weights,
    log_std,
    features,
    gram,
    learn_exploration,
    natural,
    kl,
    step,
    decay,
    n_done,
    plan_rows,
    system,
    samples,
    via,
    goal,
    reward_weights,
    dt,
):
    """The rounds of :meth:`_ActionSpaceGradient.learn`: ask (the normal draws of the
    ``PCG64`` generator whose state is ``words``, :mod:`dmpopt.learning.normals`),
    rewards (:func:`dmpopt.learning.rewards._reward_kernel` on the shared plan), tell
    (:func:`_gradient_change`). Returns the means and ``log sigma`` after each update, the
    last returns, the number of updates done and 0, 1 (rewards not finite, stopped) or 2 (the
    update overflows, stopped). ``plan_rows``: the six arrays :func:`_plan_samples` takes
    after the weights."""
    n_dofs, n_basis = weights.shape
    n_actions = features.shape[0]
    means = np.zeros((n_updates, n_dofs, n_basis))
    log_stds = np.zeros(n_updates)
    returns = np.zeros(n_rollouts)
    shared = weights.reshape(1, n_dofs, n_basis).copy()
    noise = np.empty((n_rollouts, n_actions, n_dofs))
    rewards = np.empty((n_rollouts, plan_rows[0].shape[1]))
    for u in range(n_updates):
        std = math.exp(log_std)
        fill_standard_normal(words, noise)
        noise *= std
        plan = _plan_samples(shared, *plan_rows)
        rewards[:] = 0.0
        _reward_kernel(
            plan[0],
            plan[1],
            plan[2],
            noise,
            system,
            samples,
            via,
            goal,
            reward_weights,
            dt,
            rewards,
        )
        returns = _row_sums(rewards)
        if not np.all(np.isfinite(returns)):
            return means, log_stds, returns, u, 1
        change = _gradient_change(
            noise,
            returns,
            features,
            gram,
            std**2,
            learn_exploration,
            natural,
            kl,
            step,
            decay,
            n_done + u,
        )
        if not np.all(np.isfinite(change)):
            return means, log_stds, returns, u, 2
        shared[0] = shared[0] + change[: n_dofs * n_basis].reshape(n_dofs, n_basis)
        if learn_exploration:
            log_std += change[n_dofs * n_basis]
        means[u] = shared[0]
        log_stds[u] = log_std
    return means, log_stds, returns, n_updates, 0


class EpisodicNAC(_ActionSpaceGradient):
    r"""Episodic Natural Actor-Critic, [dmpopt-paper] eqs. (17)-(19).

    Gaussian exploration on the acceleration command (eq. 17), log-likelihood gradients
    summed over each roll-out, natural gradient and baseline by regression (eq. 19,
    :func:`enac_gradient`; needs ``n_rollouts > n_params + 1`` for a unique solution, else the
    minimum-norm one is used), ``W <- W + alpha g_NAC``. With ``learn_exploration`` the
    regression includes the score of :math:`\log\sigma`, which is updated along.

    Parameters
    ----------
    features : ndarray, shape (n_actions, n_basis)
        :math:`\partial\mu_t / \partial w_i`, e.g. ``task.policy_features``.
    initial_weights : ndarray, shape (n_dofs, n_basis)
    exploration_std : float
        :math:`\sigma` of eq. (17) [acceleration units].
    n_rollouts : int
        Roll-outs per update.
    step_size : float
        :math:`\alpha` (``step_rule="constant"``) or the KL per update (``"kl"``).
    step_rule : {"kl", "constant"}
    decay : float
        Step divided by ``1 + decay * n_updates``.
    learn_exploration : bool
    seed : int or numpy Generator, optional
    """

    natural = True


class EpisodicReinforce(_ActionSpaceGradient):
    r"""Episodic REINFORCE with the optimal baseline (:func:`reinforce_gradient`).

    The paper's comparison for eNAC: same policy, same scores, vanilla gradient. Parameters
    as :class:`EpisodicNAC`; with ``step_rule="kl"`` only the length of the step is
    normalised, its direction stays the vanilla gradient.
    """

    natural = False


class PIBB(PolicySearch):
    r"""PI-BB: reward-weighted averaging of parameter perturbations (Stulp & Sigaud 2012).

    Samples :math:`W_k = W + \delta_k`, :math:`\delta_k\sim N(0, \Sigma)`; weights
    :math:`P_k \propto \exp(h (R_k - \max R)/(\max R - \min R))`, new mean
    :math:`\sum_k P_k W_k`. The covariance is either shrunk by ``decay`` per update
    (``adapt_covariance=False``, the original PI-BB) or re-estimated from the weighted
    samples (PI2-CMA style, mixed with the old one by ``covariance_rate``, floored at
    ``1e-6`` of its initial scale).
    """

    def __init__(
        self,
        initial_weights,
        exploration_std: float,
        n_rollouts: int = 20,
        eliteness: float = 10.0,
        decay: float = 0.98,
        adapt_covariance: bool = True,
        covariance_rate: float = 0.5,
        seed=None,
    ):
        weights = _initial_weights(initial_weights)
        n_rollouts = integer("n_rollouts", n_rollouts, minimum=2)
        exploration_std = _check_exploration_std(exploration_std)
        decay = real("decay", decay, minimum=0.0, maximum=1.0, open_minimum=True)
        _check_sizes(n_rollouts, weights.size, weights.size, True)
        self.shape = weights.shape
        self._mean = weights.ravel().copy()
        self.covariance = np.eye(self._mean.size) * exploration_std**2
        self._floor = 1e-6 * exploration_std**2
        self.n_rollouts = n_rollouts
        self.eliteness = real("eliteness", eliteness, minimum=0.0, open_minimum=True)
        self.decay = decay
        self.adapt_covariance = bool(adapt_covariance)
        self.covariance_rate = real("covariance_rate", covariance_rate, minimum=0.0, maximum=1.0)
        self.rng = np.random.default_rng(seed)
        self.n_trials = 0
        self.n_updates = 0
        self._pending = None

    @property
    def mean(self) -> np.ndarray:
        return self._mean.reshape(self.shape).copy()

    def ask(self) -> Exploration:
        # one BLAS thread: the SVD inside multivariate_normal rounds differently with two
        # threads (60 weights: 423 of 1200 draws differ by up to 7e-15), and PI-BB amplifies
        # that into another learning curve; the same bits in series, in workers and on Ray
        # check_valid="ignore": the covariance is PSD by construction, and numpy's check (a
        # product and an allclose) only warns; the draws are the same bits
        with _one_blas_thread:
            samples = self.rng.multivariate_normal(
                self._mean, self.covariance, self.n_rollouts, check_valid="ignore"
            )
        self._pending = samples
        return Exploration(weights=samples.reshape((-1,) + self.shape))

    def tell(self, rewards) -> None:
        samples, returns = self._pending_returns(rewards)
        spread = returns.max() - returns.min()
        scaled = (returns - returns.max()) / spread if spread > 0 else np.zeros_like(returns)
        probabilities = np.exp(self.eliteness * scaled)
        probabilities /= probabilities.sum()
        deviations = samples - self._mean
        with _one_blas_thread:
            self._mean = probabilities @ samples
            estimate = (probabilities[:, None] * deviations).T @ deviations
        if self.adapt_covariance:
            rate = self.covariance_rate
            covariance = (1 - rate) * self.covariance + rate * estimate
        else:
            covariance = self.covariance
        covariance = self.decay * covariance
        self.covariance = covariance + self._floor * np.eye(self._mean.size)
        self.n_trials += samples.shape[0]
        self.n_updates += 1


class CMAES(PolicySearch):
    """CMA-ES (Hansen) on the flattened weights, through the ``cma`` package.

    ``n_rollouts`` is CMA's population size; the returns are maximised. Stopping criteria of
    ``cma`` are switched off: the caller decides how many trials to run.

    The normal draws come from a private ``numpy.random.RandomState`` seeded from ``seed``
    (cma's ``randn`` option): the same numbers cma would draw after seeding NumPy's global
    generator, but that global generator is neither reseeded nor read, so a run gives the
    same bits whatever else in the process uses it (other runs in a worker, user code).

    An update costs ``cma`` about 0.6 ms (10 weights) to 1.3 ms (60 weights) of thread CPU, most
    of a run (``benchmarks/bench_learning.py`` splits it): its eigendecomposition of ``C``
    every update (the lazy-update gap ``1 / (10 N (c_1 + c_mu))`` is below one here), the
    covariance and step-size updates, and its own bookkeeping in Python (argument checks,
    the archive of sent solutions, the best solution). No option turns that bookkeeping off
    without changing the numbers (``verb_log``, ``check_points`` and the types passed to
    ``tell`` change nothing measurable; logging and termination checks never run here).
    """

    def __init__(
        self,
        initial_weights,
        exploration_std: float,
        n_rollouts: int = 20,
        seed=None,
        options: dict | None = None,
    ):
        try:
            import cma
        except ImportError as error:  # pragma: no cover - depends on the installation
            raise MissingDependency(
                "CMAES needs the 'cma' package: pip install 'dmpopt[rl]'"
            ) from error
        weights = _initial_weights(initial_weights)
        n_rollouts = integer("n_rollouts", n_rollouts, minimum=2)
        exploration_std = _check_exploration_std(exploration_std)
        if options is not None and not isinstance(options, dict):
            raise InvalidInputError(
                f"options must be a dict of cma options, got {type(options).__name__}"
            )
        _check_sizes(n_rollouts, weights.size, weights.size, True)
        self.shape = weights.shape
        seed = int(np.random.default_rng(seed).integers(1, 2**31 - 1))  # cma: 0 means "random"
        settings = {
            "popsize": int(n_rollouts),
            "seed": float("nan"),  # cma seeds the global generator unless the seed is NaN
            "randn": np.random.RandomState(seed).randn,
            "verbose": -9,
            "tolfun": 0.0,
            "tolfunhist": 0.0,
            "tolx": 0.0,
            "tolstagnation": 10**9,
            "tolflatfitness": 10**9,
            "maxiter": 10**9,
        }
        settings.update(options or {})
        try:
            self.strategy = cma.CMAEvolutionStrategy(weights.ravel(), exploration_std, settings)
        except ValueError as error:  # cma refuses unknown or malformed options
            raise InvalidInputError(f"options were refused by cma: {error}") from error
        self.n_rollouts = int(n_rollouts)
        self.n_trials = 0
        self.n_updates = 0
        self._pending = None

    @property
    def mean(self) -> np.ndarray:
        return np.asarray(self.strategy.mean).reshape(self.shape).copy()

    def ask(self) -> Exploration:
        with _one_blas_thread:  # cma's eigendecomposition, as PI-BB
            samples = np.asarray(self.strategy.ask())
        self._pending = samples
        return Exploration(weights=samples.reshape((-1,) + self.shape))

    def tell(self, rewards) -> None:
        samples, returns = self._pending_returns(rewards)
        with _one_blas_thread:
            self.strategy.tell(list(samples), list(-returns))
        self.n_trials += samples.shape[0]
        self.n_updates += 1


METHODS = ("enac", "ereinforce", "pibb", "cmaes")


def make_method(name: str, task, seed=None, **options) -> PolicySearch:
    """An optimiser for ``task`` (a :class:`~dmpopt.learning.RewardTask`) by name.

    ``"enac"`` and ``"ereinforce"`` take ``features`` and ``initial_weights`` from the task;
    ``"pibb"`` and ``"cmaes"`` take ``initial_weights``. ``options`` go to the constructor
    (``exploration_std`` is required).
    """
    if not isinstance(name, str) or name not in METHODS:
        raise InvalidInputError(f"method must be one of {METHODS}, got {name!r}")
    if "exploration_std" not in options:
        raise InvalidInputError(
            f"make_method({name!r}, ...) needs exploration_std=..., the initial exploration "
            "standard deviation"
        )
    if name == "enac":
        return EpisodicNAC(task.policy_features, task.initial_weights, seed=seed, **options)
    if name == "ereinforce":
        return EpisodicReinforce(task.policy_features, task.initial_weights, seed=seed, **options)
    if name == "pibb":
        return PIBB(task.initial_weights, seed=seed, **options)
    return CMAES(task.initial_weights, seed=seed, **options)


@dataclass(frozen=True, eq=False)
class LearningCurve:
    """Progress of one run, one entry per update (plus the start).

    Attributes
    ----------
    trials : ndarray, shape (n_updates + 1,)
        Exploratory roll-outs used so far.
    returns : ndarray, shape (n_updates + 1,)
        Return of the noise-free plan of the mean weights.
    improvement : ndarray, shape (n_updates + 1,)
        ``returns`` as the fraction of the achievable improvement (``task.improvement``).
    weights : ndarray, shape (n_updates + 1, n_dofs, n_basis)
        Mean weights after each update.
    """

    trials: np.ndarray
    returns: np.ndarray
    improvement: np.ndarray
    weights: np.ndarray

    @property
    def final_weights(self) -> np.ndarray:
        """Mean weights after the last update, shape (n_dofs, n_basis)."""
        return self.weights[-1]

    def weights_at(self, trials: float) -> np.ndarray:
        """Mean weights after the last update that used at most ``trials`` roll-outs."""
        trials = real("trials", trials, minimum=float(self.trials[0]))
        return self.weights[int(np.searchsorted(self.trials, trials, side="right")) - 1]

    def trials_to(self, fraction: float) -> float:
        """First trial count at which ``improvement >= fraction`` (``inf`` if never)."""
        fraction = real("fraction", fraction)
        reached = np.nonzero(self.improvement >= fraction)[0]
        return float(self.trials[reached[0]]) if reached.size else float("inf")


def optimise(method: PolicySearch, task, n_trials: int) -> LearningCurve:
    """Run ask/evaluate/tell until ``n_trials`` roll-outs have been used.

    After every update the noise-free plan of ``method.mean`` is scored on ``task``.
    """
    if not isinstance(method, PolicySearch):
        raise InvalidInputError(
            f"method must be a PolicySearch (e.g. from make_method), got {type(method).__name__}"
        )
    if not all(hasattr(task, name) for name in ("evaluate", "returns", "initial_return")):
        raise InvalidInputError(
            f"task must be a RewardTask (evaluate, returns, initial_return), got "
            f"{type(task).__name__}"
        )
    n_trials = integer("n_trials", n_trials, minimum=0)
    first = method.n_trials
    n_updates = max(0, (n_trials - first) // method.n_rollouts)
    means = np.stack([method.mean, *method.learn(task, n_updates)])
    trials = first + method.n_rollouts * np.arange(n_updates + 1)
    returns = task.returns(means)
    start, best = task.initial_return, task.optimum_return
    return LearningCurve(
        trials=np.asarray(trials, dtype=float),
        returns=returns,
        improvement=(returns - start) / (best - start),
        weights=means,
    )

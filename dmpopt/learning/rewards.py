r"""Reward tasks for reinforcement learning on discrete DMPs, with their exact optimum.

A task fixes a :class:`~dmpopt.DiscreteDMP` (start, goal, time constant, basis) and a
quadratic reward on its plan. The learner chooses the forcing weights :math:`W` of shape
(n_dofs, n_basis) (``dmp.forcing_weights()``; with ``goal_scaling="translation"`` these are
the DMP's ``weights``).

Exploration on the acceleration command, [dmpopt-paper] eq. (17)
-----------------------------------------------------------------
The policy draws, at every step ``k = 0 .. n_steps - 2``, the acceleration command

.. math:: \ddot y_k = \mu_k(W) + \epsilon_k, \qquad \epsilon_k \sim N(0, \sigma^2),

with :math:`\mu_k = \dot z_k / \tau` the DMP's acceleration of eq. (10); the perturbation is
held over the step ``[t_k, t_{k+1})``. It enters eq. (10) as the additive input ``C`` of
:math:`\tau \dot z` (``coupling`` in :mod:`dmpopt.symbolic`) with :math:`C = \tau^2 \epsilon`.
The transformation system is linear, so the noisy plan is still affine,

.. math:: Y = F + G W^T + H \epsilon,

with ``F, G`` the :class:`~dmpopt.AffinePlan` and ``H`` (:attr:`RewardTask.noise_response`)
the response to a unit acceleration held over one step, derived from the symbolic RK4 step
(the same discretisation as the plan). ``H`` is lower-triangular Toeplitz, the response of a
three-state linear system: the rewards of a batch of ``K`` roll-outs run that system over the
noise sample by sample (a compiled loop, ``O(K n)``), on the noise-free plan ``F + G W^T``.

The score of the policy (the derivative of the mean command with respect to the weights at
a fixed state) is :math:`\partial \mu_k / \partial w_i = \phi_i(x_k) / \tau^2` with
:math:`\phi_i` the normalised, phase-velocity-gated basis of eq. (7)
(:attr:`RewardTask.policy_features`). It treats the forcing term as held over each step,
whereas the plan integrates it continuously (RK4); the resulting bias of likelihood-ratio
gradients is of order ``dt`` (measured in the tests: below 1 %).

Reward, a choice for the OCR-garbled eq. (20) of [dmpopt-paper]
----------------------------------------------------------------
.. math::

    R = -c_g \lVert y(T) - g\rVert^2 - c_v \lVert \dot y(T)\rVert^2
        - c_a \sum_{k=0}^{n-2} \lVert \ddot y_k\rVert^2 \Delta t
        - c_j \sum_{k=0}^{n-2} \lVert (\ddot y_{k+1} - \ddot y_k) / \Delta t\rVert^2 \Delta t
        - \sum_v c_v' \lVert y(t_v) - p_v \rVert^2

with the paper's task using :math:`c_g = 1000, c_v = 1, c_a = 10^{-3}, c_j = 0`. The
acceleration cost is an integral (times ``dt``) weighted by ``1e-3``: the plain unweighted sum
of squared accelerations over 500 steps would swamp the goal term, and the optimum would no
longer reach the goal. The jerk cost (option) gives the minimum-jerk, "5th-order polynomial"
shape. Per-step rewards put the acceleration and jerk terms at their step and the terminal and
via-point terms at their sample; ``delayed=True`` gives the whole return at the last step only.

Exact optimum
-------------
Every term is the square of an affine function of the plan, and the plan is affine in the
weights, so :math:`R(W) = -\lVert A\,\mathrm{vec}(W) - b\rVert^2` and the best weights are a
linear least-squares solution. With exploration noise the expected return is
:math:`R(W)` minus a constant that does not depend on ``W``, so the same weights maximise it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from .. import basis, symbolic
from ..dmp import AffinePlan, DiscreteDMP
from ..exceptions import InvalidInputError, ShapeError
from ..validation import check_resources, real, real_array, sequence_of

__all__ = [
    "RewardTask",
    "ViaPointReward",
    "multi_dof_reaching_task",
    "paper_reaching_task",
    "via_point_task",
]


@dataclass(frozen=True)
class ViaPointReward:
    """A reward term ``-weight * ||y(time) - position||^2`` of a :class:`RewardTask`.

    Not a :class:`dmpopt.ViaPoint`: that one is a hard constraint of a fit (the plan must
    pass within a tolerance, interpolated between samples); this one is a soft, weighted
    penalty on the nearest sample, which the learner trades against the other reward terms.
    """

    time: float  # [s]
    position: tuple
    weight: float = 1000.0


def _noise_system(dmp: DiscreteDMP, dt: float) -> tuple[np.ndarray, ...]:
    r"""The transformation system's response to a held acceleration input, as a state space.

    Returns ``(transition, input_column, readout, feedthrough)``: with the transformation
    state ``s`` (position, scaled velocity, forcing; the canonical state plays no part, the
    input enters linearly) and an acceleration ``epsilon_m`` held over step ``m`` (coupling
    ``tau^2 epsilon_m`` on ``tau zdot`` in eq. (10)),

    .. math:: s_{m+1} = A s_m + b\,\epsilon_m, \qquad
              (y, \dot y, \ddot y)_m = C s_m + d\,\epsilon_m, \qquad s_0 = 0,

    ``A`` (3, 3), ``b`` (3,), ``C`` (3 outputs, 3 states), ``d`` (3,) read off the symbolic
    RK4 step and output functions (the same discretisation as the plan).
    """
    signature = symbolic.Signature("acceleration", 1, 1, "gaussian")
    tau = dmp.tau
    gains = np.asarray(dmp.gains)
    step = symbolic.step_function(signature)
    output = symbolic.output_function(signature)

    def parameters(coupling):
        return symbolic.parameters(tau=tau, canonical_target=1.0, gains=gains, coupling=coupling)

    def transformation_step(state, coupling):
        full = np.concatenate([[0.0, 0.0], state])
        return step(state=full, dt=dt, **parameters(coupling))["next_state"].full().ravel()[2:]

    def outputs(state, coupling):
        full = np.concatenate([[0.0, 0.0], state])
        values = output(state=full, **parameters(coupling))
        return np.array([float(values[name]) for name in symbolic.PLAN_OUTPUTS])

    unit = np.eye(3)
    transition = np.column_stack([transformation_step(e, 0.0) for e in unit])  # (y, z, r)
    input_column = transformation_step(np.zeros(3), tau**2)
    readout = np.column_stack([outputs(e, 0.0) for e in unit])  # (3 outputs, 3 states)
    feedthrough = outputs(np.zeros(3), tau**2)  # (0, 0, 1): the held command itself
    return transition, input_column, readout, feedthrough


def _noise_response(system, n_steps: int) -> np.ndarray:
    """``H`` of shape (3, n_steps, n_steps - 1) of the state space ``system``.

    ``H[:, k, j]`` is the effect on sample ``k`` of an acceleration ``epsilon_j = 1`` held over
    step ``j``: the impulse response ``d`` at lag 0 and ``C A^(m-1) b`` at lag ``m >= 1``; the
    response is time invariant (lower-triangular Toeplitz).
    """
    transition, input_column, readout, feedthrough = system
    impulse = np.zeros((3, n_steps))  # impulse[:, m]: effect m samples after the input
    impulse[:, 0] = feedthrough
    state = input_column
    for m in range(1, n_steps):
        impulse[:, m] = readout @ state
        state = transition @ state
    lag = np.arange(n_steps)[:, None] - np.arange(n_steps - 1)[None, :]
    response = np.where(lag >= 0, impulse[:, np.clip(lag, 0, None)], 0.0)
    response.setflags(write=False)
    return response


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _noise_free_terms(
    accelerations, positions, velocity, samples, j, jerky, dt, squares, jerks, sampled, final
):
    """DOF ``j``'s terms of :func:`_reward_kernel` without noise: the plan's own values.

    The noisy loop adds the noise response, exactly zero here (zero states and inputs), to
    each acceleration, position and velocity; adding a zero changes at most the sign of a
    zero, which every term squares or subtracts from a target, so these terms are the same
    bits. Each roll-out runs on its own, its steps in order (contiguous reads).
    """
    n_rollouts = squares.shape[1]
    n_steps = squares.shape[0]
    shared = accelerations.shape[0] == 1
    for k in range(n_rollouts):
        row = 0 if shared else k
        previous = 0.0
        for m in range(n_steps):
            acceleration = accelerations[row, j, m]
            squares[m, k] += acceleration * acceleration
            if jerky and m > 0:
                jerk = (acceleration - previous) / dt
                jerks[m - 1, k] += jerk * jerk
            previous = acceleration
        for column in range(samples.size):
            sampled[column, j, k] = positions[row, j, column]
        final[j, k] = velocity[row, j]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _reward_kernel(
    accelerations, positions, velocity, noise, system, samples, via, goal, weights, dt, rewards
):
    """Per-step rewards of a batch into ``rewards`` (K, n_steps), zero on entry.

    ``accelerations`` (K', D, n_steps), ``positions`` (K', D, S) at the samples ``samples``,
    ``velocity`` (K', D) at the end: the noise-free plans, K' = K or 1 (shared by every
    roll-out). ``noise`` (K, n_steps - 1, D) or of size 0: the held acceleration inputs,
    whose response is run through the state space ``system`` (:func:`_noise_system`, packed
    as rows ``A``, ``b``, ``C``, ``d`` in a (8, 3) array) sample by sample. ``via`` rows
    ``(column in samples, sample, weight, target per DOF)``; ``weights`` ``(c_a, c_j, c_g, c_v)``.
    The terms, and the order in which they are summed, are those of the module docstring:
    per step the acceleration, the jerk, the via points, the goal, the final velocity, each
    summed over the DOFs first.
    """
    n_rollouts, n_steps = rewards.shape
    n_dofs = accelerations.shape[1]
    n_samples = samples.size
    noisy = noise.size > 0
    shared = accelerations.shape[0] == 1
    acceleration_weight, jerk_weight, goal_weight, velocity_weight = weights
    a, b, c, d = system[0:3], system[3], system[4:7], system[7]
    # time-major work arrays: the roll-outs advance side by side (innermost loop), each with
    # the arithmetic, in the order, of a roll-out alone; their recursions are independent
    squares = np.zeros((n_steps, n_rollouts))
    jerks = np.zeros((n_steps, n_rollouts))
    sampled = np.empty((n_samples, n_dofs, n_rollouts))  # positions at the samples
    final = np.empty((n_dofs, n_rollouts))  # velocity at the end
    epsilon = np.zeros(n_rollouts)
    s0 = np.empty(n_rollouts)  # states of the noise responses
    s1 = np.empty(n_rollouts)
    s2 = np.empty(n_rollouts)
    response = np.empty(n_rollouts)
    previous = np.empty(n_rollouts)
    for j in range(n_dofs):
        if not noisy:
            _noise_free_terms(
                accelerations,
                positions,
                velocity,
                samples,
                j,
                jerk_weight > 0.0,
                dt,
                squares,
                jerks,
                sampled,
                final,
            )
            continue
        s0[:] = 0.0
        s1[:] = 0.0
        s2[:] = 0.0
        column = 0
        for m in range(n_steps):
            if noisy and m < n_steps - 1:
                for k in range(n_rollouts):
                    epsilon[k] = noise[k, m, j]
            else:
                epsilon[:] = 0.0
            for k in range(n_rollouts):
                response[k] = (
                    c[2, 0] * s0[k] + c[2, 1] * s1[k] + c[2, 2] * s2[k] + d[2] * epsilon[k]
                )
            for k in range(n_rollouts):
                acceleration = accelerations[0 if shared else k, j, m] + response[k]
                squares[m, k] += acceleration * acceleration
                if jerk_weight > 0.0 and m > 0:
                    jerk = (acceleration - previous[k]) / dt
                    jerks[m - 1, k] += jerk * jerk
                previous[k] = acceleration
            if column < n_samples and samples[column] == m:
                for k in range(n_rollouts):
                    sampled[column, j, k] = positions[0 if shared else k, j, column] + (
                        c[0, 0] * s0[k] + c[0, 1] * s1[k] + c[0, 2] * s2[k] + d[0] * epsilon[k]
                    )
                column += 1
            if m == n_steps - 1:
                for k in range(n_rollouts):
                    final[j, k] = velocity[0 if shared else k, j] + (
                        c[1, 0] * s0[k] + c[1, 1] * s1[k] + c[1, 2] * s2[k] + d[1] * epsilon[k]
                    )
            if noisy:
                for k in range(n_rollouts):
                    x0, x1, x2, e = s0[k], s1[k], s2[k], epsilon[k]
                    s0[k] = a[0, 0] * x0 + a[0, 1] * x1 + a[0, 2] * x2 + b[0] * e
                    s1[k] = a[1, 0] * x0 + a[1, 1] * x1 + a[1, 2] * x2 + b[1] * e
                    s2[k] = a[2, 0] * x0 + a[2, 1] * x1 + a[2, 2] * x2 + b[2] * e
    for k in range(n_rollouts):
        for m in range(n_steps - 1):
            rewards[k, m] -= acceleration_weight * dt * squares[m, k]
            if jerk_weight > 0.0:
                rewards[k, m] -= jerk_weight * dt * jerks[m, k]
        for v in range(via.shape[0]):
            column = int(via[v, 0])
            error = 0.0
            for j in range(n_dofs):
                deviation = sampled[column, j, k] - via[v, 3 + j]
                error += deviation * deviation
            rewards[k, int(via[v, 1])] -= via[v, 2] * error
        error = 0.0
        speed = 0.0
        for j in range(n_dofs):
            deviation = sampled[n_samples - 1, j, k] - goal[j]
            error += deviation * deviation
            speed += final[j, k] * final[j, k]
        rewards[k, n_steps - 1] -= goal_weight * error
        rewards[k, n_steps - 1] -= velocity_weight * speed


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _row_sums(rewards):
    """Returns of per-step rewards (K, n_steps), summed step by step (one order for the
    compiled learning loop, :meth:`RewardTask.returns` and the optimisers' ``tell``)."""
    returns = np.zeros(rewards.shape[0])
    for k in range(rewards.shape[0]):
        for t in range(rewards.shape[1]):
            returns[k] += rewards[k, t]
    return returns


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _plan_samples(
    weights, free_accelerations, accelerations, free_positions, positions, free_velocity, velocity
):
    """Noise-free plans ``F + G W^T`` at the samples the reward reads, for ``weights``
    (K, D, B): accelerations (K, D, n_steps), positions (K, D, S), final velocity (K, D),
    from the rows of ``F`` (D, ...) and ``G`` (B, ...) with time along the last axis."""
    n_rollouts, n_dofs, n_basis = weights.shape
    planned_accelerations = np.zeros((n_rollouts, n_dofs, accelerations.shape[1]))
    planned_positions = np.zeros((n_rollouts, n_dofs, positions.shape[1]))
    planned_velocity = np.zeros((n_rollouts, n_dofs))
    for k in range(n_rollouts):
        for d in range(n_dofs):
            for i in range(n_basis):  # scalar loops: slices would allocate a temporary each
                w = weights[k, d, i]
                for m in range(accelerations.shape[1]):
                    planned_accelerations[k, d, m] += w * accelerations[i, m]
                for m in range(positions.shape[1]):
                    planned_positions[k, d, m] += w * positions[i, m]
                planned_velocity[k, d] += w * velocity[i]
            for m in range(accelerations.shape[1]):
                planned_accelerations[k, d, m] += free_accelerations[d, m]
            for m in range(positions.shape[1]):
                planned_positions[k, d, m] += free_positions[d, m]
            planned_velocity[k, d] += free_velocity[d]
    return planned_accelerations, planned_positions, planned_velocity


@dataclass(frozen=True, eq=False)
class RewardTask:
    r"""A DMP, a horizon and a quadratic reward (module docstring); values are read-only.

    Parameters
    ----------
    dmp : DiscreteDMP
        Start, goal, time constant and basis; its weights are the task's initial weights.
    duration : float
        Horizon ``T`` [s].
    dt : float
        Step [s]; one exploration sample per step.
    goal_weight, velocity_weight, acceleration_weight, jerk_weight : float
        :math:`c_g, c_v, c_a, c_j` of the reward.
    via_points : tuple of ViaPointReward
        Rewarded positions (one entry per DOF in ``position``).
    delayed : bool
        Per-step rewards (False) or the whole return at the last step (True).

    Attributes
    ----------
    plan : AffinePlan
        Noise-free plan as an affine function of the forcing weights.
    noise_response : ndarray, shape (3, n_steps, n_steps - 1)
        ``H``: response to a unit acceleration held over one step.
    policy_features : ndarray, shape (n_steps - 1, n_basis)
        Derivative of the mean acceleration command of each step w.r.t. each weight.
    """

    dmp: DiscreteDMP
    duration: float = 0.5
    dt: float = 0.001
    goal_weight: float = 1000.0
    velocity_weight: float = 1.0
    acceleration_weight: float = 1e-3
    jerk_weight: float = 0.0
    via_points: tuple = ()
    delayed: bool = False
    plan: AffinePlan = field(init=False)
    noise_response: np.ndarray = field(init=False)
    policy_features: np.ndarray = field(init=False)

    def __post_init__(self):
        if not isinstance(self.dmp, DiscreteDMP) or self.dmp.form != "acceleration":
            raise InvalidInputError(
                "dmp must be a DiscreteDMP with form='acceleration' (the policy of eq. (17) "
                "perturbs the acceleration command of eq. (10))"
            )
        for name in ("goal_weight", "velocity_weight", "acceleration_weight", "jerk_weight"):
            object.__setattr__(self, name, real(name, getattr(self, name), minimum=0.0))
        duration = real("duration", self.duration, minimum=0.0, open_minimum=True)
        dt = real("dt", self.dt, minimum=0.0, maximum=duration / 2, open_minimum=True)
        estimate = duration / dt + 1  # samples; H holds 3 n^2 values
        check_resources(
            f"a task of {duration:g} s with dt = {dt:g} s ({estimate:.3g} steps)",
            8.0
            * (max(3 * estimate**2, (self.n_dofs * self.n_basis + 1) * 3 * estimate * self.n_dofs)),
            "raise dt (the paper uses 1 ms over 0.5 s) or shorten the duration",
        )
        if not isinstance(self.delayed, (bool, np.bool_)):
            raise InvalidInputError(f"delayed must be True or False, got {self.delayed!r}")
        plan = self.dmp.affine_plan(duration, dt)
        object.__setattr__(self, "plan", plan)
        n_steps = plan.times.size
        via = []
        fix = "a reward task scores closeness: ViaPointReward(time, position, weight)"
        for i, point in enumerate(sequence_of("via_points", self.via_points, ViaPointReward, fix)):
            name = f"via_points[{i}]"
            time = real(f"{name}.time", point.time, minimum=0.0, maximum=duration)
            position = np.atleast_1d(real_array(f"{name}.position", point.position))
            if position.shape != (self.n_dofs,):
                raise ShapeError(
                    f"{name}.position has shape {position.shape}, expected ({self.n_dofs},)"
                )
            index = min(int(round(time / dt)), n_steps - 1)
            via.append((index, position, real(f"{name}.weight", point.weight, minimum=0.0)))
        object.__setattr__(self, "_via", tuple(via))
        system = _noise_system(self.dmp, self.dt)
        object.__setattr__(self, "noise_response", _noise_response(system, n_steps))
        # the reward reads whole acceleration series but positions only at the via points and
        # the end, velocities only at the end: the rows of F, G, H at those samples
        samples = tuple(sorted({index for index, _, _ in via} | {n_steps - 1}))
        rows = {  # time along the last axis: (n_dofs or n_basis, samples)
            "samples": samples,
            "free_positions": plan.free[0, list(samples)].T.copy(),
            "positions": plan.weight_response[0, list(samples)].T.copy(),
            "free_velocity": plan.free[1, -1],
            "velocity": plan.weight_response[1, -1],
            "free_accelerations": plan.free[2].T.copy(),
            "accelerations": plan.weight_response[2].T.copy(),
            # the reward kernel's inputs: the state space (rows A, b, C, d), the via points
            # (column in samples, sample, weight, target per DOF), the weights of the terms
            "system": np.vstack(system),
            "via_rows": np.array(
                [[samples.index(i), i, weight, *position] for i, position, weight in via],
                dtype=float,
            ).reshape(len(via), 3 + self.n_dofs),
            "samples_array": np.array(samples, dtype=np.int64),
            "goal": np.array(self.dmp.goal, dtype=float),
            "weights": np.array(
                [self.acceleration_weight, self.jerk_weight, self.goal_weight, self.velocity_weight]
            ),
        }
        object.__setattr__(self, "_rows", rows)
        # d mu_k / d w_i = phi_i(x_k) / tau^2 at each step's sample, (n_steps - 1, n_basis)
        features = self.dmp.phase_features(n_steps, self.dt)[:-1] / self.dmp.tau**2
        features.setflags(write=False)
        object.__setattr__(self, "policy_features", features)
        object.__setattr__(self, "_optimum", self._solve_optimum())

    # -- sizes --------------------------------------------------------------------------

    @property
    def n_dofs(self) -> int:
        """Number of DOFs."""
        return self.dmp.n_dofs

    @property
    def n_basis(self) -> int:
        """Weights per DOF."""
        return self.dmp.n_basis

    @property
    def n_steps(self) -> int:
        """Samples of the plan, ``0, dt, ..., T``."""
        return self.plan.times.size

    @property
    def n_actions(self) -> int:
        """Exploratory acceleration commands per DOF and roll-out (``n_steps - 1``)."""
        return self.n_steps - 1

    @property
    def initial_weights(self) -> np.ndarray:
        """Forcing weights the learners start from, shape (n_dofs, n_basis)."""
        return np.array(self.dmp.forcing_weights())

    # -- roll-outs and rewards ---------------------------------------------------------------

    def rollouts(self, weights, acceleration_noise=None) -> np.ndarray:
        r"""Plans of a batch, shape (K, 3, n_steps, n_dofs) (positions, velocities, accelerations).

        Parameters
        ----------
        weights : array_like, shape (K, n_dofs, n_basis) or (n_dofs, n_basis)
            Forcing weights of each roll-out.
        acceleration_noise : array_like, shape (K, n_steps - 1, n_dofs), optional
            Exploration :math:`\epsilon` added to the acceleration command at each step.
        """
        weights = self._batch_weights(weights)
        k = weights.shape[0]
        check_resources(
            f"plans of {k} roll-outs",
            8.0 * (k * 3 * self.n_steps * self.n_dofs),
            "evaluate the batch in smaller chunks",
        )
        flat = weights.transpose(2, 0, 1).reshape(self.n_basis, k * self.n_dofs)
        response = self.plan.weight_response.reshape(3 * self.n_steps, self.n_basis)
        forced = (response @ flat).reshape(3, self.n_steps, k, self.n_dofs)
        plans = self.plan.free[None] + forced.transpose(2, 0, 1, 3)
        if acceleration_noise is not None:
            noise = self._check_noise(acceleration_noise, k)
            response = self.noise_response.reshape(3 * self.n_steps, self.n_actions)
            plans = plans + (response @ noise).reshape(k, 3, self.n_steps, self.n_dofs)
        return plans

    def rewards(self, plans: np.ndarray) -> np.ndarray:
        """Per-step rewards of plans from :meth:`rollouts`, shape (K, n_steps).

        With ``delayed=True`` all but the last column are zero.
        """
        plans = real_array("plans", plans)
        if plans.ndim != 4 or plans.shape[1:] != (3, self.n_steps, self.n_dofs):
            raise ShapeError(
                f"plans has shape {plans.shape}, expected (K, 3, {self.n_steps}, {self.n_dofs}) "
                "as returned by rollouts()"
            )
        samples = list(self._rows["samples"])
        return self._step_rewards(
            np.swapaxes(plans[:, 0, samples], 1, 2), plans[:, 1, -1], np.swapaxes(plans[:, 2], 1, 2)
        )

    def _step_rewards(self, positions, final_velocity, accelerations, noise=None) -> np.ndarray:
        """The reward of the module docstring, per step, shape (K, n_steps).

        ``positions`` (K', n_dofs, S) at the samples ``self._rows["samples"]`` (the via points
        and the end), ``final_velocity`` (K', n_dofs), ``accelerations`` (K', n_dofs, n_steps)
        of the noise-free plans, K' = K or 1 (one plan shared by the K roll-outs); ``noise``
        (K, n_steps - 1, n_dofs) the held acceleration inputs added to them (``H epsilon``,
        run through the state space of :func:`_noise_system` step by step), or None.
        """
        k = accelerations.shape[0] if noise is None else noise.shape[0]
        rewards = np.zeros((k, self.n_steps))
        _reward_kernel(
            np.ascontiguousarray(accelerations),
            np.ascontiguousarray(positions),
            np.ascontiguousarray(final_velocity),
            np.empty((0, 0, 0)) if noise is None else np.ascontiguousarray(noise),
            *self.reward_arrays()[6:],
            rewards,
        )
        if self.delayed:
            total = _row_sums(rewards)
            rewards = np.zeros_like(rewards)
            rewards[:, -1] = total
        return rewards

    def _sampled_rewards(self, weights, acceleration_noise=None) -> np.ndarray:
        """Per-step rewards of a batch from the rows of ``F, G`` the reward reads.

        The same plans as :meth:`rollouts` (``Y = F + G W^T + H epsilon``) evaluated only
        where :meth:`_step_rewards` looks: the accelerations of every sample, the positions
        at the via points and the end, the velocity at the end. Roll-outs that share their
        weights (action-space exploration) share one noise-free plan.
        """
        weights = self._batch_weights(weights)
        k = weights.shape[0]
        shared = bool(np.all(weights == weights[:1]))
        mean = weights[:1] if shared else weights
        accelerations, positions, velocity = _plan_samples(
            np.ascontiguousarray(mean), *self.reward_arrays()[:6]
        )
        if acceleration_noise is None:
            rewards = self._step_rewards(positions, velocity, accelerations)
            return np.repeat(rewards, k, axis=0) if shared else rewards
        noise = self._check_noise(acceleration_noise, k)
        return self._step_rewards(positions, velocity, accelerations, noise)

    def _check_noise(self, acceleration_noise, n_rollouts: int) -> np.ndarray:
        noise = real_array("acceleration_noise", acceleration_noise)
        expected = (n_rollouts, self.n_actions, self.n_dofs)
        if noise.shape != expected:
            raise ShapeError(
                f"acceleration_noise has shape {noise.shape}, expected {expected} "
                "(roll-outs, steps - 1, DOFs)"
            )
        return noise

    def evaluate(self, exploration) -> np.ndarray:
        """Per-step rewards (K, n_steps) of the roll-outs an optimiser asked for.

        ``exploration`` has ``weights`` (K, n_dofs, n_basis) and ``acceleration_noise``
        (K, n_steps - 1, n_dofs) or None (see :class:`dmpopt.learning.Exploration`).
        """
        if not hasattr(exploration, "weights") or not hasattr(exploration, "acceleration_noise"):
            raise InvalidInputError(
                f"exploration must be an Exploration (from an optimiser's ask()), got "
                f"{type(exploration).__name__}"
            )
        return self._sampled_rewards(exploration.weights, exploration.acceleration_noise)

    def returns(self, weights, acceleration_noise=None) -> np.ndarray:
        """Returns (sums of rewards) of a batch, shape (K,)."""
        return _row_sums(self._sampled_rewards(weights, acceleration_noise))

    def reward_arrays(self) -> tuple:
        """What the compiled reward reads, in the order of its arguments.

        The rows of ``F`` and ``G`` the reward reads, time along the last axis:
        accelerations (n_dofs, n_steps) and (n_basis, n_steps), positions at the via points
        and the end (n_dofs, S) and (n_basis, S), final velocity (n_dofs,) and (n_basis,);
        then the noise response as a state space (rows ``A``, ``b``, ``C``, ``d`` of
        :func:`_noise_system`, (8, 3)), the samples read (S,), the via points (rows of column
        in the samples, sample, weight, target per DOF), the goal, the weights
        ``(c_a, c_j, c_g, c_v)`` and ``dt``. A reparametrised task (weights ``v`` with
        ``W = D v``) gives ``G D`` instead of ``G``.
        """
        rows = self._rows
        return (
            rows["free_accelerations"],
            rows["accelerations"],
            rows["free_positions"],
            rows["positions"],
            rows["free_velocity"],
            rows["velocity"],
            rows["system"],
            rows["samples_array"],
            rows["via_rows"],
            rows["goal"],
            rows["weights"],
            self.dt,
        )

    def deterministic_return(self, weights) -> float:
        """Return of the noise-free plan with ``weights`` (n_dofs, n_basis)."""
        return float(self.returns(np.asarray(weights)[None])[0])

    # -- exact optimum -----------------------------------------------------------------------

    def _batch_weights(self, weights) -> np.ndarray:
        weights = real_array("weights", weights)
        if weights.ndim == 2:
            weights = weights[None]
        if weights.ndim != 3 or weights.shape[1:] != (self.n_dofs, self.n_basis):
            raise ShapeError(
                f"weights has shape {weights.shape}, expected (K, {self.n_dofs}, {self.n_basis})"
            )
        return weights

    def _residuals(self, plans: np.ndarray) -> np.ndarray:
        """Affine residuals whose squared norm is minus the return, shape (K, m)."""
        positions, velocities, accelerations = plans[:, 0], plans[:, 1], plans[:, 2]
        k = plans.shape[0]
        dt = self.dt
        parts = [np.sqrt(self.acceleration_weight * dt) * accelerations[:, :-1].reshape(k, -1)]
        if self.jerk_weight > 0.0:
            jerk = np.diff(accelerations, axis=1) / dt
            parts.append(np.sqrt(self.jerk_weight * dt) * jerk.reshape(k, -1))
        for index, position, weight in self._via:
            parts.append(np.sqrt(weight) * (positions[:, index] - position))
        parts.append(np.sqrt(self.goal_weight) * (positions[:, -1] - np.asarray(self.dmp.goal)))
        parts.append(np.sqrt(self.velocity_weight) * velocities[:, -1])
        return np.concatenate(parts, axis=1)

    def _solve_optimum(self):
        n = self.n_dofs * self.n_basis
        unit = np.concatenate([np.zeros((1, n)), np.eye(n)]).reshape(n + 1, self.n_dofs, -1)
        residuals = self._residuals(self.rollouts(unit))
        offset = residuals[0]
        jacobian = (residuals[1:] - offset).T
        solution = np.linalg.lstsq(jacobian, -offset, rcond=None)[0]
        weights = solution.reshape(self.n_dofs, self.n_basis)
        weights.setflags(write=False)
        return weights, self.deterministic_return(weights)

    @property
    def optimal_weights(self) -> np.ndarray:
        """Forcing weights of the best noise-free plan (exact least squares), (n_dofs, n_basis)."""
        return self._optimum[0]

    @property
    def optimum_return(self) -> float:
        """Best achievable return of the noise-free plan; also maximises the expected return."""
        return self._optimum[1]

    @property
    def initial_return(self) -> float:
        """Return of the noise-free plan with :attr:`initial_weights`."""
        return self.deterministic_return(self.initial_weights)

    def improvement(self, weights) -> np.ndarray:
        """Fraction of the achievable improvement: 0 at the initial, 1 at the optimal weights.

        ``weights`` of shape (n_dofs, n_basis) or a batch (K, n_dofs, n_basis).
        """
        batch = self._batch_weights(weights)
        returns = self.returns(batch)
        start = self.initial_return
        fraction = (returns - start) / (self.optimum_return - start)
        return fraction if np.ndim(weights) == 3 else float(fraction[0])


def _dmp(start, goal, duration: float, n_basis: int) -> DiscreteDMP:
    """Acceleration DMP, zero weights, unforced plan 95 % converged at ``duration``.

    ``tau = duration / convergence_time(tau = 1)`` (Section 3.4's choice of ``tau``).
    """
    start = np.atleast_1d(real_array("start", start))
    goal = np.atleast_1d(real_array("goal", goal))
    if start.ndim != 1 or goal.shape != start.shape:
        raise ShapeError(f"goal has shape {goal.shape}, expected {start.shape}: one per DOF")
    duration = real("duration", duration, minimum=0.0, open_minimum=True)
    n_basis = basis.check_n_basis(n_basis)
    template = DiscreteDMP(
        weights=np.zeros((start.size, n_basis)),
        start=start,
        goal=goal,
        tau=1.0,
        centres=np.zeros(n_basis),
        widths=np.ones(n_basis),
        form="acceleration",
        goal_scaling="translation",
    )
    centres, widths = basis.discrete_basis(n_basis, template.gains)
    tau = duration / basis.convergence_time("acceleration", template.gains)
    return template.replace(tau=tau, centres=centres, widths=widths)


def paper_reaching_task(
    jerk_weight: float = 0.0, delayed: bool = False, dt: float = 0.001, n_basis: int = 10
) -> RewardTask:
    """The task of Section 4.2 of [dmpopt-paper]: 1 DOF, ``y: 0 -> g = 1`` in 500 ms.

    Acceleration DMP, 10 basis functions, weights start at zero, ``dt = 1 ms``, reward of the
    module docstring with ``c_g = 1000, c_v = 1, c_a = 1e-3`` (and ``jerk_weight`` if given).
    """
    return RewardTask(
        _dmp([0.0], [1.0], 0.5, n_basis),
        duration=0.5,
        dt=dt,
        jerk_weight=jerk_weight,
        delayed=delayed,
    )


def multi_dof_reaching_task(
    goals=(1.0, -0.5, 0.8, 0.3, -1.2, 0.6),
    duration: float = 0.5,
    dt: float = 0.001,
    n_basis: int = 10,
    delayed: bool = False,
) -> RewardTask:
    """Several DOFs from 0 to different goals on one canonical system (default 6 DOFs)."""
    goals = np.atleast_1d(real_array("goals", goals))
    if goals.ndim != 1:
        raise ShapeError(f"goals has shape {goals.shape}, expected (n_dofs,)")
    return RewardTask(
        _dmp(np.zeros(goals.size), goals, duration, n_basis),
        duration=duration,
        dt=dt,
        delayed=delayed,
    )


def via_point_task(
    via_time: float = 0.2,
    via_position=(0.3, 0.6),
    goal=(1.0, 0.0),
    duration: float = 0.5,
    dt: float = 0.001,
    n_basis: int = 10,
    delayed: bool = False,
) -> RewardTask:
    """A 2-DOF reach from the origin to ``goal`` that must pass ``via_position`` at ``via_time``.

    The unforced plan goes straight; the via point (weight 1000) makes the learner bend it.
    """
    goal = np.atleast_1d(real_array("goal", goal))
    return RewardTask(
        _dmp(np.zeros(goal.size), goal, duration, n_basis),
        duration=duration,
        dt=dt,
        via_points=(ViaPointReward(via_time, tuple(via_position)),),
        delayed=delayed,
    )

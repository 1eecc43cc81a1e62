r"""Probabilistic movement primitives: a Gaussian over basis weights, learned from demonstrations.

A ProMP ([Paraschos2013]_) writes each DOF's position at normalised time :math:`z = t / T`
as a weighted sum of normalised Gaussian basis functions plus observation noise,

.. math:: y_d(t) = \phi(z)^T w_d + \epsilon, \qquad \epsilon \sim N(0, \sigma^2),

and models the stacked weights :math:`w = [w_1; \dots; w_D]` as :math:`N(\mu, \Sigma)`. The
basis is the one of the discrete DMP's forcing term (eq. (7), the normalised Gaussians of
:func:`dmpopt.symbolic.basis_log_activations`), here on the linear phase :math:`z \in [0, 1]`;
its phase derivatives give velocities and accelerations.

Learning (regularised maximum likelihood): each demonstration's weights are the ridge
least-squares fit :math:`w_i = (\Phi^T\Phi + \lambda I)^{-1}\Phi^T y_i` on its own normalised
time; then :math:`\mu = \frac1N\sum_i w_i`, :math:`\Sigma = \frac1N\sum_i (w_i - \mu)(w_i -
\mu)^T + \kappa I` (the maximum-likelihood Gaussian, with a prior :math:`\kappa` that keeps it
invertible when there are fewer demonstrations than weights), and :math:`\sigma^2` the mean
squared residual of the fits.

Conditioning on observations :math:`o = \Psi^T w + \eta`, :math:`\eta \sim N(0, R)` (positions
and/or velocities at given times) is Gaussian conditioning,

.. math:: K = \Sigma\Psi(R + \Psi^T\Sigma\Psi)^{-1}, \quad \mu' = \mu + K(o - \Psi^T\mu),
          \quad \Sigma' = \Sigma - K\Psi^T\Sigma.

Blending and co-activation ([Paraschos2013]_) combine the trajectory
distributions of several ProMPs at each time as the product of their Gaussians raised to
their activations :math:`\alpha_i(t)`:
:math:`\Sigma_t^{-1} = \sum_i \alpha_i \Sigma_{i,t}^{-1}`,
:math:`\mu_t = \Sigma_t \sum_i \alpha_i \Sigma_{i,t}^{-1} \mu_{i,t}`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .exceptions import InvalidInputError, ShapeError
from .fitting._recall import Recall, exact
from .trajectory import Trajectory, check_times
from .validation import integer, real, real_array, sequence_of

CROSSING = 1.0 / np.sqrt(2.0)
"""Neighbouring basis functions cross at this fraction of their height (as the DMP's)."""


def basis(n_basis: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres equally spaced on ``[0, 1]`` and widths crossing at :data:`CROSSING`."""
    n_basis = integer("n_basis", n_basis, minimum=2)
    centres = np.linspace(0.0, 1.0, n_basis)
    spacing = centres[1] - centres[0]
    widths = np.full(n_basis, -4.0 * np.log(CROSSING) / spacing**2)
    return centres, widths


def features(phases, centres, widths) -> np.ndarray:
    r"""Normalised activations and their first two phase derivatives, shape
    (3, n_phases, n_basis).

    With :math:`a_i = -h_i (z - c_i)^2` (:func:`dmpopt.symbolic.basis_log_activations`) and
    :math:`\psi_i = e^{a_i} / \sum_j e^{a_j}`: :math:`\psi_i' = \psi_i (a_i' - m)` with
    :math:`m = \sum_j \psi_j a_j'`, and :math:`\psi_i'' = \psi_i' (a_i' - m) + \psi_i
    (a_i'' - m')`, :math:`m' = \sum_j (\psi_j' a_j' + \psi_j a_j'')`. Written in NumPy for
    speed (the CasADi expression is about 100 times slower on a thousand phases); the tests
    check it against the symbolic definition differentiated by CasADi.
    """
    z, psi = _normalised(phases, centres, widths)
    slope, curvature = -2.0 * widths * (z - centres), -2.0 * widths
    m = np.sum(psi * slope, axis=1, keepdims=True)
    first = psi * (slope - m)
    m_rate = np.sum(first * slope + psi * curvature, axis=1, keepdims=True)
    second = first * (slope - m) + psi * (curvature - m_rate)
    return np.stack([psi, first, second])


def _normalised(phases, centres, widths) -> tuple[np.ndarray, np.ndarray]:
    r"""The phases as a column and the normalised activations :math:`\psi_i` at them,
    (n_phases, n_basis): :func:`features` without the derivatives."""
    z = np.atleast_1d(np.asarray(phases, dtype=float))[:, None]
    log_psi = -widths * (z - centres) ** 2
    psi = np.exp(log_psi - log_psi.max(axis=1, keepdims=True))
    psi /= psi.sum(axis=1, keepdims=True)
    return z, psi


@dataclass(frozen=True, eq=False)
class ProMP:
    r"""A distribution over trajectories of ``n_dofs`` DOFs; a frozen value.

    Build one with :func:`fit_promp`; :meth:`condition` returns a new ProMP.

    Attributes
    ----------
    mean : ndarray, shape (n_dofs, n_basis)
        :math:`\mu`, the weights' mean, one row per DOF [unit of the positions].
    covariance : ndarray, shape (n_dofs * n_basis, n_dofs * n_basis)
        :math:`\Sigma` over the stacked weights (DOF-major) [unit^2]; symmetric positive
        semi-definite (definite after :func:`fit_promp`; conditioning without noise makes it
        singular along the observed directions).
    centres, widths : ndarray, shape (n_basis,)
        :math:`c_i` on the normalised phase and :math:`h_i`.
    duration : float
        :math:`T` [s]: the phase runs from 0 to 1 over it.
    noise_variance : float
        :math:`\sigma^2` [unit^2], the observation noise of each position sample.
    """

    mean: np.ndarray
    covariance: np.ndarray
    centres: np.ndarray
    widths: np.ndarray
    duration: float
    noise_variance: float = 0.0

    def __post_init__(self):
        mean = real_array("mean", self.mean, ndim=2, expected="shape (n_dofs, n_basis)")
        n = mean.size
        centres = real_array("centres", self.centres, shape=(mean.shape[1],))
        widths = real_array("widths", self.widths, shape=(mean.shape[1],))
        covariance = real_array(
            "covariance",
            self.covariance,
            shape=(n, n),
            expected=f"shape ({n}, {n}) to match mean {mean.shape}",
        )
        if np.any(widths <= 0.0):
            raise InvalidInputError(f"widths must be positive, got {widths.min():g}")
        asymmetry = np.abs(covariance - covariance.T).max()
        if asymmetry > 1e-9 * max(np.abs(covariance).max(), 1e-300):
            raise InvalidInputError(
                f"covariance must be symmetric; it differs from its transpose by {asymmetry:.3g}"
                "; pass (covariance + covariance.T) / 2"
            )
        lowest = np.linalg.eigvalsh(0.5 * (covariance + covariance.T)).min() if n else 0.0
        if lowest < -1e-9 * max(np.abs(covariance).max(), 1e-300):
            raise InvalidInputError(
                f"covariance must be positive semi-definite; its lowest eigenvalue is "
                f"{lowest:.3g}; add a multiple of the identity (fit_promp's regularization does)"
            )
        for name, value in (("mean", mean), ("covariance", covariance)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        for name, value in (("centres", centres), ("widths", widths)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        duration = real("duration", self.duration, minimum=0.0, open_minimum=True)
        object.__setattr__(self, "duration", duration)
        noise = real("noise_variance", self.noise_variance, minimum=0.0)
        object.__setattr__(self, "noise_variance", noise)

    @property
    def n_dofs(self) -> int:
        """Number of DOFs."""
        return self.mean.shape[0]

    @property
    def n_basis(self) -> int:
        """Basis functions per DOF."""
        return self.mean.shape[1]

    def _phases(self, times) -> np.ndarray:
        times = real_array("times", np.atleast_1d(times), ndim=1)
        return times / self.duration

    def feature_matrix(self, times, derivative: int = 0) -> np.ndarray:
        r""":math:`\Psi^T` mapping the stacked weights to the stacked samples at ``times``.

        Returns shape (n_times * n_dofs, n_dofs * n_basis): row ``k * n_dofs + d`` gives
        DOF ``d`` at ``times[k]`` (position, velocity or acceleration for ``derivative`` 0, 1,
        2; the phase derivatives divided by :math:`T` and :math:`T^2`).
        """
        phases = self._phases(times)
        rows = features(phases, self.centres, self.widths)[derivative] / self.duration**derivative
        blocks = np.kron(np.eye(self.n_dofs), rows)  # rows d * n_times + k
        blocks = blocks.reshape(self.n_dofs, rows.shape[0], -1).transpose(1, 0, 2)
        return blocks.reshape(rows.shape[0] * self.n_dofs, -1)

    def mean_trajectory(self, times) -> Trajectory:
        """The trajectory of the mean weights at ``times`` [s]."""
        times = check_times(times)
        phases = self._phases(times)
        values = features(phases, self.centres, self.widths)
        scales = self.duration ** -np.arange(3.0)
        positions, velocities, accelerations = (
            scale * value @ self.mean.T for scale, value in zip(scales, values)
        )
        return Trajectory(times, positions, velocities, accelerations)

    def mean_positions(self, times) -> np.ndarray:
        """Positions of the mean weights at ``times`` [s], shape (n_times, n_dofs)."""
        return features(self._phases(times), self.centres, self.widths)[0] @ self.mean.T

    def position_covariances(self, times) -> np.ndarray:
        r"""Covariance of the positions at each time, :math:`\Psi_t^T\Sigma\Psi_t`, shape
        (n_times, n_dofs, n_dofs) (without the observation noise)."""
        matrix = self.feature_matrix(times).reshape(-1, self.n_dofs, self.mean.size)
        return np.einsum("tik,kl,tjl->tij", matrix, self.covariance, matrix)

    def sample_weights(self, n_samples: int, rng=None) -> np.ndarray:
        """Weights drawn from :math:`N(\\mu, \\Sigma)`, shape (n_samples, n_dofs, n_basis)."""
        n_samples = integer("n_samples", n_samples, minimum=1)
        rng = np.random.default_rng(rng)
        draws = rng.multivariate_normal(self.mean.ravel(), self.covariance, n_samples)
        return draws.reshape(n_samples, self.n_dofs, self.n_basis)

    def sample_trajectories(self, times, n_samples: int, rng=None) -> np.ndarray:
        """Positions of sampled weights at ``times``, shape (n_samples, n_times, n_dofs)."""
        weights = self.sample_weights(n_samples, rng)
        values = features(self._phases(times), self.centres, self.widths)[0]
        return np.einsum("tb,sdb->std", values, weights)

    def condition(
        self,
        time: float,
        position=None,
        velocity=None,
        position_variance=0.0,
        velocity_variance=0.0,
    ) -> ProMP:
        r"""The ProMP given the position and/or velocity at ``time`` [s] (Gaussian conditioning).

        Parameters
        ----------
        time : float
            [s], usually in ``[0, duration]``.
        position, velocity : array_like, shape (n_dofs,), optional
            Observed position [unit] and velocity [unit/s]; at least one.
        position_variance, velocity_variance : float or array_like, shape (n_dofs,)
            Observation noise :math:`R` [unit^2], [unit^2/s^2]; 0 (default) pins the mean on
            the observation exactly.

        Returns
        -------
        ProMP
            :math:`\mu' = \mu + K(o - \Psi^T\mu)`, :math:`\Sigma' = \Sigma - K\Psi^T\Sigma`
            with :math:`K = \Sigma\Psi(R + \Psi^T\Sigma\Psi)^{-1}` (module docstring).
        """
        time = real("time", time)
        if position is None and velocity is None:
            raise InvalidInputError("condition needs a position, a velocity or both; got neither")
        rows, observed, noise = [], [], []
        for derivative, value, variance, name in (
            (0, position, position_variance, "position"),
            (1, velocity, velocity_variance, "velocity"),
        ):
            if value is None:
                continue
            observed.append(_per_dof(name, value, self.n_dofs))
            noise.append(_per_dof(f"{name}_variance", variance, self.n_dofs, minimum=0.0))
            rows.append(self.feature_matrix([time], derivative))
        psi_t = np.vstack(rows)  # Psi^T
        observation, variance = np.concatenate(observed), np.concatenate(noise)
        projected = psi_t @ self.covariance  # Psi^T Sigma
        innovation = projected @ psi_t.T + np.diag(variance)
        try:
            gain = np.linalg.solve(innovation, projected).T  # Sigma Psi (R + ...)^-1
        except np.linalg.LinAlgError as error:
            raise InvalidInputError(
                "the observations are degenerate (their covariance is singular); give a "
                "position_variance or velocity_variance > 0"
            ) from error
        mean = self.mean.ravel() + gain @ (observation - psi_t @ self.mean.ravel())
        covariance = self.covariance - gain @ projected
        covariance = 0.5 * (covariance + covariance.T)
        return replace(self, mean=mean.reshape(self.mean.shape), covariance=covariance)

    def log_likelihood(self, trajectory: Trajectory) -> float:
        r"""Log density [nats] of the positions of ``trajectory`` under the ProMP.

        The trajectory's times are mapped onto the phase by its own duration; the positions
        are jointly Gaussian, :math:`N(\Psi^T\mu, \Psi^T\Sigma\Psi + \sigma^2 I)`.
        """
        if not isinstance(trajectory, Trajectory) or trajectory.n_dofs != self.n_dofs:
            raise InvalidInputError(
                f"trajectory must be a Trajectory with {self.n_dofs} DOFs, got "
                f"{type(trajectory).__name__}"
            )
        times = (trajectory.times - trajectory.times[0]) / trajectory.duration * self.duration
        psi_t = self.feature_matrix(times)
        residual = trajectory.positions.ravel() - psi_t @ self.mean.ravel()
        covariance = psi_t @ self.covariance @ psi_t.T
        covariance[np.diag_indices_from(covariance)] += self.noise_variance
        factor = np.linalg.cholesky(covariance)
        whitened = np.linalg.solve(factor, residual)
        return float(
            -0.5 * whitened @ whitened
            - np.log(np.diag(factor)).sum()
            - 0.5 * residual.size * np.log(2 * np.pi)
        )


def _per_dof(name: str, value, n_dofs: int, minimum=None) -> np.ndarray:
    array = np.atleast_1d(real_array(name, value))
    if array.shape == (1,):
        array = np.full(n_dofs, array[0])
    if array.shape != (n_dofs,):
        raise ShapeError(f"{name} has shape {array.shape}, expected ({n_dofs},) for the DOFs")
    if minimum is not None and np.any(array < minimum):
        raise InvalidInputError(f"{name} must be >= {minimum}, got {array.tolist()}")
    return array


def fit_promp(
    demonstrations,
    n_basis: int = 20,
    *,
    regularization: float = 1e-8,
    covariance_regularization: float = 0.1,
) -> ProMP:
    r"""Learn a ProMP from several demonstrations (regularised maximum likelihood).

    Parameters
    ----------
    demonstrations : sequence of Trajectory
        Two or more, with the same DOFs; each is mapped onto the phase ``[0, 1]`` by its own
        duration; the ProMP's ``duration`` is their mean.
    n_basis : int
        Basis functions per DOF (two or more).
    regularization : float
        :math:`\lambda` of each demonstration's ridge fit, relative to the mean diagonal of
        :math:`\Phi^T\Phi`.
    covariance_regularization : float
        :math:`\kappa` added to the diagonal of :math:`\Sigma`, relative to the mean variance
        of the weights (a prior that keeps :math:`\Sigma` invertible). The default 0.1 gave
        the best held-out likelihood on LASA (leave one of 7 demonstrations out) among 1e-6,
        1e-4, 1e-2, 0.1 and 1; 1e-6 makes held-out demonstrations hundreds of nats per
        sample less likely (the 7 demonstrations span 6 of the 40 directions).

    Returns
    -------
    ProMP
    """
    demos = sequence_of("demonstrations", demonstrations, Trajectory)
    if len(demos) < 2:
        raise InvalidInputError(
            f"demonstrations holds {len(demos)} trajectory, at least 2 are needed to learn a "
            "covariance"
        )
    n_dofs = demos[0].n_dofs
    for k, demo in enumerate(demos):
        if demo.n_dofs != n_dofs:
            raise ShapeError(
                f"demonstrations[{k}] has {demo.n_dofs} DOFs, demonstrations[0] has {n_dofs}"
            )
    centres, widths = basis(n_basis)
    regularization = real("regularization", regularization, minimum=0.0)
    kappa = real("covariance_regularization", covariance_regularization, minimum=0.0)
    weights, residuals, n_samples = [], 0.0, 0
    for demo in demos:
        key = (exact(demo.times, demo.positions), n_basis, regularization)
        w, residual = _DEMO_FITS(key, lambda: _demo_fit(demo, centres, widths, regularization))
        weights.append(w)
        residuals += float(residual)
        n_samples += demo.positions.size
    weights = np.array(weights)
    mean = weights.mean(axis=0)
    deviations = weights - mean
    covariance = deviations.T @ deviations / len(demos)
    prior = kappa * max(np.trace(covariance) / mean.size, 1e-300)
    covariance += prior * np.eye(mean.size)
    return ProMP(
        mean=mean.reshape(n_dofs, n_basis),
        covariance=covariance,
        centres=centres,
        widths=widths,
        duration=float(np.mean([demo.duration for demo in demos])),
        noise_variance=residuals / n_samples,
    )


def _demo_fit(demo: Trajectory, centres, widths, regularization: float) -> tuple:
    """One demonstration's ridge weights (DOF-major, flat) and squared residual sum."""
    n_basis = centres.size
    phases = (demo.times - demo.times[0]) / demo.duration
    phi = _normalised(phases, centres, widths)[1]
    gram = phi.T @ phi
    lam = regularization * np.trace(gram) / n_basis
    w = np.linalg.solve(gram + lam * np.eye(n_basis), phi.T @ demo.positions).T
    return w.ravel(), np.array(np.sum((phi @ w.T - demo.positions) ** 2))


_DEMO_FITS = Recall(16)
"""Ridge fits of the last demonstrations: a leave-one-out over N demonstrations fits each of
them once instead of N times (each fit depends on its own demonstration alone)."""


def coactivate(promps, times, activations) -> tuple[np.ndarray, np.ndarray]:
    r"""Co-activation of several ProMPs: the product of their Gaussians at each time.

    Parameters
    ----------
    promps : sequence of ProMP
        Same DOFs.
    times : array_like, shape (n_times,)
        [s], on each ProMP's own time axis.
    activations : array_like, shape (n_promps, n_times) or (n_promps,)
        :math:`\alpha_i(t) \ge 0`, not all zero at any time (a column is broadcast in time).

    Returns
    -------
    means : ndarray, shape (n_times, n_dofs)
    covariances : ndarray, shape (n_times, n_dofs, n_dofs)
        :math:`\Sigma_t = (\sum_i \alpha_i \Sigma_{i,t}^{-1})^{-1}`,
        :math:`\mu_t = \Sigma_t\sum_i\alpha_i\Sigma_{i,t}^{-1}\mu_{i,t}` (module docstring).
    """
    promps = sequence_of("promps", promps, ProMP)
    if not promps:
        raise InvalidInputError("promps is empty; give at least one ProMP")
    n_dofs = promps[0].n_dofs
    if any(p.n_dofs != n_dofs for p in promps):
        raise ShapeError(f"promps have {[p.n_dofs for p in promps]} DOFs; give the same for all")
    times = real_array("times", np.atleast_1d(times), ndim=1)
    alpha = real_array("activations", activations)
    if alpha.ndim == 1:
        alpha = np.repeat(alpha[:, None], times.size, axis=1)
    if alpha.shape != (len(promps), times.size):
        raise ShapeError(
            f"activations has shape {alpha.shape}, expected ({len(promps)}, {times.size}) "
            "(one row per ProMP, one column per time) or one value per ProMP"
        )
    if np.any(alpha < 0.0) or np.any(alpha.sum(axis=0) <= 0.0):
        raise InvalidInputError("activations must be >= 0 and not all zero at any time")
    information = np.zeros((times.size, n_dofs, n_dofs))
    weighted = np.zeros((times.size, n_dofs))
    for promp, a in zip(promps, alpha):
        means = promp.mean_positions(times)
        inverse = np.linalg.inv(promp.position_covariances(times))
        information += a[:, None, None] * inverse
        weighted += a[:, None] * np.einsum("tij,tj->ti", inverse, means)
    covariances = np.linalg.inv(information)
    return np.einsum("tij,tj->ti", covariances, weighted), covariances


def blend(first: ProMP, second: ProMP, times, activation) -> tuple[np.ndarray, np.ndarray]:
    r"""Blend from ``first`` to ``second``: :func:`coactivate` with activations
    :math:`\alpha(t)` and :math:`1 - \alpha(t)`.

    ``activation`` : array_like, shape (n_times,), in ``[0, 1]``: the weight of ``first``
    (e.g. a sigmoid falling from 1 to 0 over the switch).
    """
    times = real_array("times", np.atleast_1d(times), ndim=1)
    alpha = real_array("activation", activation, shape=times.shape)
    if np.any(alpha < 0.0) or np.any(alpha > 1.0):
        raise InvalidInputError("activation must lie in [0, 1] (the weight of first)")
    return coactivate((first, second), times, np.vstack([alpha, 1.0 - alpha]))

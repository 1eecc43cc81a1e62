"""ProMPs: basis against its symbolic definition, ML fit, Gaussian conditioning, blending, io."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmpopt import ProMP, Trajectory, blend, coactivate, fit_promp, load, save, symbolic
from dmpopt.exceptions import InvalidInputError, ShapeError
from dmpopt.promp import basis, features


def _random_promp(rng, n_dofs=2, n_basis=6, duration=2.0) -> ProMP:
    centres, widths = basis(n_basis)
    n = n_dofs * n_basis
    root = rng.normal(size=(n, n))
    return ProMP(
        mean=rng.normal(size=(n_dofs, n_basis)),
        covariance=root @ root.T / n + 0.1 * np.eye(n),
        centres=centres,
        widths=widths,
        duration=duration,
        noise_variance=0.01,
    )


@pytest.mark.parametrize("spread", [1.0, 4.0])
def test_features_match_the_symbolic_basis_and_its_casadi_derivatives(spread):
    """Answer key: eq. (7)'s normalised Gaussians from dmpopt.symbolic, differentiated by
    CasADi's automatic differentiation (exact up to rounding, ~1e-12 relative); with equal
    widths and with widths spread ``spread``-fold over the bases (equal widths hide the
    curvature -2 h_i of the second derivative: it cancels)."""
    centres, widths = basis(7)
    widths = widths * np.linspace(2.0 / (1.0 + spread), 2.0 * spread / (1.0 + spread), 7)
    z = ca.SX.sym("z")
    psi = symbolic.normalised_activations(
        symbolic.basis_log_activations("gaussian", z, ca.DM(centres), ca.DM(widths))
    )
    first = ca.jacobian(psi, z)
    function = ca.Function("f", [z], [psi, first, ca.jacobian(first, z)])
    phases = np.linspace(-0.1, 1.1, 25)
    got = features(phases, centres, widths)
    for k, phase in enumerate(phases):
        for order, value in enumerate(function(phase)):
            scale = np.abs(value.full()).max()
            np.testing.assert_allclose(got[order, k], value.full().ravel(), atol=1e-10 * scale)


def test_fit_recovers_the_mean_and_covariance_of_the_generating_gaussian():
    """Synthetic demos drawn from a known weight Gaussian on the same basis (no noise): the
    fit is the sample mean and the 1/N sample covariance of the drawn weights (closed form,
    computed here with numpy) plus the prior on the diagonal."""
    rng = np.random.default_rng(3)
    truth = _random_promp(rng)
    weights = truth.sample_weights(12, rng)
    times = np.linspace(0.0, truth.duration, 200)
    phi = features(times / truth.duration, truth.centres, truth.widths)[0]
    demos = [Trajectory.from_positions(times, phi @ w.T) for w in weights]
    fitted = fit_promp(demos, 6, regularization=0.0, covariance_regularization=1e-3)
    flat = weights.reshape(12, -1)
    mean = flat.mean(axis=0)
    covariance = (flat - mean).T @ (flat - mean) / 12
    covariance += 1e-3 * np.trace(covariance) / mean.size * np.eye(mean.size)
    # least squares on 200 samples of 6 well-conditioned columns: rounding ~1e-12
    np.testing.assert_allclose(fitted.mean, mean.reshape(2, 6), atol=1e-8)
    np.testing.assert_allclose(fitted.covariance, covariance, atol=1e-8)
    assert fitted.noise_variance < 1e-16


def test_fit_converges_to_the_generating_gaussian_with_many_demos():
    """With N demos the ML estimates are within a few standard errors (~1/sqrt(N)) of the
    truth: 2000 demos put the mean within 5 standard errors."""
    rng = np.random.default_rng(4)
    truth = _random_promp(rng, n_dofs=1, n_basis=4)
    weights = truth.sample_weights(2000, rng)
    times = np.linspace(0.0, truth.duration, 50)
    phi = features(times / truth.duration, truth.centres, truth.widths)[0]
    demos = [Trajectory.from_positions(times, phi @ w.T) for w in weights]
    fitted = fit_promp(demos, 4, regularization=0.0, covariance_regularization=0.0)
    error = fitted.mean.ravel() - truth.mean.ravel()
    standard_error = np.sqrt(np.diag(truth.covariance) / 2000)
    assert np.all(np.abs(error) < 5 * standard_error)
    relative = np.abs(fitted.covariance - truth.covariance).max() / np.abs(truth.covariance).max()
    assert relative < 0.15  # sampling error of a covariance ~ sqrt(2/N) = 3 %, 5 sigma


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(0.0, 2.0), st.booleans())
def test_conditioning_is_gaussian_conditioning(seed, time, with_velocity):
    """Answer key: the joint Gaussian of (weights, observation) conditioned by the Schur
    complement, written plainly here with the observation matrix built from features()."""
    rng = np.random.default_rng(seed)
    promp = _random_promp(rng)
    position, velocity = rng.normal(size=2), rng.normal(size=2)
    variance = rng.uniform(0.0, 0.1, 2)
    z = np.array([time / promp.duration])
    phi = features(z, promp.centres, promp.widths)
    rows = [np.kron(np.eye(2), phi[0])]  # positions of both DOFs, DOF-major weights
    values, noise = [position], [variance]
    if with_velocity:
        rows.append(np.kron(np.eye(2), phi[1] / promp.duration))
        values.append(velocity)
        noise.append(2 * variance)
    H, o, R = np.vstack(rows), np.concatenate(values), np.diag(np.concatenate(noise))
    mu, sigma = promp.mean.ravel(), promp.covariance
    S = H @ sigma @ H.T + R
    mean = mu + sigma @ H.T @ np.linalg.inv(S) @ (o - H @ mu)
    covariance = sigma - sigma @ H.T @ np.linalg.inv(S) @ H @ sigma
    got = promp.condition(
        time,
        position=position,
        velocity=velocity if with_velocity else None,
        position_variance=variance,
        velocity_variance=2 * variance,
    )
    np.testing.assert_allclose(got.mean.ravel(), mean, atol=1e-9)
    np.testing.assert_allclose(got.covariance, covariance, atol=1e-9)


def test_exact_conditioning_pins_the_mean_on_the_via_point():
    """With no observation noise the conditioned mean passes through the point."""
    promp = _random_promp(np.random.default_rng(0))
    point = np.array([0.3, -1.2])
    conditioned = promp.condition(0.7, position=point)
    np.testing.assert_allclose(conditioned.mean_positions([0.7])[0], point, atol=1e-10)
    assert np.abs(conditioned.position_covariances([0.7])).max() < 1e-10


def test_samples_have_the_predicted_covariance():
    """Sample covariance of 20000 sampled trajectories at one time against
    Psi^T Sigma Psi (sampling error ~ sqrt(2/N) = 1 %, bound 6 %)."""
    promp = _random_promp(np.random.default_rng(1))
    samples = promp.sample_trajectories([0.5, 1.3], 20000, rng=2)
    predicted = promp.position_covariances([0.5, 1.3])
    for k in range(2):
        empirical = np.cov(samples[:, k].T)
        assert np.abs(empirical - predicted[k]).max() < 0.06 * np.abs(predicted[k]).max()
    np.testing.assert_allclose(samples.mean(axis=0), promp.mean_positions([0.5, 1.3]), atol=0.05)


def test_log_likelihood_is_the_multivariate_normal_density():
    """Answer key: the Gaussian density written out with numpy's determinant and inverse."""
    promp = _random_promp(np.random.default_rng(5))
    times = np.linspace(0.0, promp.duration, 8)
    positions = np.random.default_rng(6).normal(size=(8, 2))
    trajectory = Trajectory.from_positions(times, positions)
    phi = features(times / promp.duration, promp.centres, promp.widths)[0]
    H = np.zeros((16, 12))
    for k in range(8):
        H[2 * k : 2 * k + 2] = np.kron(np.eye(2), phi[k])
    C = H @ promp.covariance @ H.T + promp.noise_variance * np.eye(16)
    r = positions.ravel() - H @ promp.mean.ravel()
    expected = -0.5 * (r @ np.linalg.inv(C) @ r + np.linalg.slogdet(C)[1] + 16 * np.log(2 * np.pi))
    assert promp.log_likelihood(trajectory) == pytest.approx(expected, rel=1e-9)


def test_coactivation_is_the_product_of_gaussians():
    """Answer key: at one time, the product of N(m1, S1)^a1 N(m2, S2)^a2 has precision
    a1 S1^-1 + a2 S2^-1 (written out); blending at activation 1 returns the first ProMP."""
    rng = np.random.default_rng(7)
    first, second = _random_promp(rng), _random_promp(rng)
    times = np.array([0.2, 1.0, 1.8])
    activations = np.array([[0.3, 1.0, 0.0], [0.7, 0.5, 1.0]])
    means, covariances = coactivate((first, second), times, activations)
    for k in range(3):
        m1, m2 = first.mean_positions(times)[k], second.mean_positions(times)[k]
        p1 = np.linalg.inv(first.position_covariances(times)[k])
        p2 = np.linalg.inv(second.position_covariances(times)[k])
        a1, a2 = activations[:, k]
        precision = a1 * p1 + a2 * p2
        np.testing.assert_allclose(covariances[k], np.linalg.inv(precision), rtol=1e-9)
        expected = np.linalg.solve(precision, a1 * p1 @ m1 + a2 * p2 @ m2)
        np.testing.assert_allclose(means[k], expected, rtol=1e-9, atol=1e-12)
    means, covariances = blend(first, second, times, [1.0, 1.0, 1.0])
    np.testing.assert_allclose(means, first.mean_positions(times), atol=1e-12)
    np.testing.assert_allclose(covariances, first.position_covariances(times), rtol=1e-9)


def test_save_and_load_round_trip_exactly(tmp_path):
    promp = _random_promp(np.random.default_rng(8)).condition(0.4, position=[0.0, 1.0])
    loaded = load(save(promp, tmp_path / "promp"))
    assert isinstance(loaded, ProMP)
    for name in ("mean", "covariance", "centres", "widths"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(promp, name))
    assert (loaded.duration, loaded.noise_variance) == (promp.duration, promp.noise_variance)


def test_errors_name_the_argument():
    promp = _random_promp(np.random.default_rng(9))
    with pytest.raises(InvalidInputError, match="needs a position, a velocity or both"):
        promp.condition(0.5)
    with pytest.raises(ShapeError, match=r"position has shape \(3,\), expected \(2,\)"):
        promp.condition(0.5, position=[1.0, 2.0, 3.0])
    with pytest.raises(InvalidInputError, match="at least 2 are needed"):
        fit_promp([Trajectory.from_positions([0.0, 1.0, 2.0], [0.0, 1.0, 2.0])])
    with pytest.raises(InvalidInputError, match="positive semi-definite"):
        ProMP(promp.mean, -np.eye(12), promp.centres, promp.widths, 1.0)
    with pytest.raises(InvalidInputError, match="activation must lie in"):
        blend(promp, promp, [0.0, 1.0], [0.5, 1.5])


def test_mean_trajectory_derivatives_are_the_time_derivatives_of_its_positions():
    """Answer key: central finite differences of mean_positions (step 1e-5 s: truncation
    ~1e-10 relative on these smooth Gaussians of width ~0.2 s, rounding ~1e-11 / 1e-5)."""
    promp = _random_promp(np.random.default_rng(10), duration=1.7)
    times = np.linspace(0.1, 1.6, 7)
    trajectory = promp.mean_trajectory(times)
    h = 1e-5
    plus, minus = promp.mean_positions(times + h), promp.mean_positions(times - h)
    middle = promp.mean_positions(times)
    scale = np.abs(trajectory.velocities).max()
    np.testing.assert_allclose(trajectory.velocities, (plus - minus) / (2 * h), atol=1e-6 * scale)
    second = (plus - 2 * middle + minus) / h**2
    np.testing.assert_allclose(trajectory.accelerations, second, atol=1e-3 * np.abs(second).max())
    conditioned = promp.condition(times[3], velocity=[0.5, -0.2])
    np.testing.assert_allclose(
        conditioned.mean_trajectory(times).velocities[3], [0.5, -0.2], atol=1e-10
    )


def test_recalled_demo_fits_give_the_fresh_fit():
    """fit_promp recalls each demonstration's ridge fit: a leave-one-out over three demos
    gives, bit for bit, the ProMPs fitted with nothing recalled, and a demo with the same
    times but other positions is not handed another's fit (a key without the positions
    would hand it). Answer key: the same fits after the store is cleared."""
    from dmpopt import promp

    times = np.linspace(0.0, 1.0, 50)
    demos = [
        Trajectory.from_positions(times, np.column_stack([np.sin(k + 3 * times), times**k]))
        for k in range(1, 4)
    ]
    recalled = [fit_promp(demos[:k] + demos[k + 1 :], 5) for k in range(3)]
    recalled.append(fit_promp(demos, 5))
    for k, fit in enumerate(recalled):
        promp._DEMO_FITS.clear()
        fresh = fit_promp(demos[:k] + demos[k + 1 :], 5)
        np.testing.assert_array_equal(fit.mean, fresh.mean)
        np.testing.assert_array_equal(fit.covariance, fresh.covariance)
        assert fit.noise_variance == fresh.noise_variance


# answer keys (mutation run)


def test_features_far_from_every_centre_go_to_the_nearest_basis():
    """At phase 50 every activation underflows (e^{-h 49^2}); normalised per phase, the last
    basis (centre 1) takes all of it (the next one e^{-h (50.25^2 - 49^2)} of it), while
    phase 0.5 keeps its own values summing to one."""
    centres, widths = basis(5)
    psi = features([0.5, 50.0], centres, widths)[0]
    assert psi[1, 4] == 1.0 and np.all(psi[1, :4] < 1e-200)
    assert psi[0].sum() == pytest.approx(1.0, rel=1e-15, abs=0) and psi[0, 2] == psi[0].max()


def _plain_fit(demos, n_basis, regularization, kappa):
    """fit_promp's docstring written out: phases (t - t_0) / duration, Gaussians exp(-h (z -
    c)^2) normalised, ridge weights with lambda = regularization tr(G) / n_basis, the 1/N
    covariance plus kappa times its mean variance on the diagonal, the noise as the mean
    squared residual over every sample and DOF."""
    centres, widths = basis(n_basis)
    weights, squares, count = [], 0.0, 0
    for demo in demos:
        z = (demo.times - demo.times[0]) / (demo.times[-1] - demo.times[0])
        activation = np.exp(-widths * (z[:, None] - centres) ** 2)
        phi = activation / activation.sum(axis=1, keepdims=True)
        gram = phi.T @ phi
        lam = regularization * np.trace(gram) / n_basis
        w = np.linalg.solve(gram + lam * np.eye(n_basis), phi.T @ demo.positions)
        squares += float(np.sum((phi @ w - demo.positions) ** 2))
        count += demo.positions.size
        weights.append(w.T.ravel())
    weights = np.array(weights)
    mean = weights.mean(axis=0)
    covariance = (weights - mean).T @ (weights - mean) / len(demos)
    covariance += kappa * np.trace(covariance) / mean.size * np.eye(mean.size)
    return mean, covariance, squares / count


@pytest.mark.parametrize("defaults", [False, True])
def test_fit_is_its_equations_written_out(defaults):
    """Three 2-DOF demos on uneven times starting at t = 1.5 s, small enough that the
    weights' mean variance is below 1, fitted with strong ridge and prior terms (and with the
    defaults: 20 bases, 1e-8, 0.1); then demos of the same positions on other times, which
    must not be handed the first fits. Tolerance 1e-9 relative: the ridge Gram matrices'
    condition is below 100 here, so the two solves agree to ~1e-13."""
    rng = np.random.default_rng(21)
    options = (20, 1e-8, 0.1) if defaults else (6, 0.05, 0.3)
    u = np.linspace(0.0, 1.0, 40)
    positions = [
        0.1 * np.column_stack([np.sin(k + 3 * u), u**k]) + 0.01 * rng.normal(size=(40, 2))
        for k in range(1, 4)
    ]
    for spacing in (u**1.5, u**0.7):
        demos = [Trajectory.from_positions(1.5 + 2.0 * spacing, y) for y in positions]
        n_basis, regularization, kappa = options
        fit = (
            fit_promp(demos)
            if defaults
            else fit_promp(
                demos, n_basis, regularization=regularization, covariance_regularization=kappa
            )
        )
        mean, covariance, noise = _plain_fit(demos, *options)
        assert fit.n_basis == options[0]
        np.testing.assert_allclose(fit.mean.ravel(), mean, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(fit.covariance, covariance, rtol=1e-9, atol=1e-14)
        assert fit.noise_variance == pytest.approx(noise, rel=1e-9, abs=0)


def test_fit_errors_name_the_argument():
    times = np.linspace(0.0, 1.0, 10)
    one = Trajectory.from_positions(times, times[:, None])
    two = Trajectory.from_positions(times, np.column_stack([times, times]))
    with pytest.raises(ShapeError, match=r"^demonstrations\[1\] has 2 DOFs, demonstrations\[0\]"):
        fit_promp([one, two])
    with pytest.raises(InvalidInputError, match="^demonstrations"):
        fit_promp([one, "a trajectory"])
    for name in ("regularization", "covariance_regularization"):
        with pytest.raises(InvalidInputError, match=f"^{name} "):
            fit_promp([one, one], 5, **{name: -1.0})

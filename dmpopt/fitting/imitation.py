r"""Imitation learning: DMP weights from a demonstration (Section 3.4).

Three regressions, all on the same features (:func:`dmpopt.symbolic.features`):

``"position"`` (default)
    The plan is affine in the weights (:class:`dmpopt.dmp.AffinePlan`), so the weights that
    make the *rollout* closest to the demonstrated positions solve one regularised linear
    least-squares problem; the last sample is held to the goal exactly. This fits what a
    user sees, including the integration of the transformation system.
``"least_squares"``
    Global ridge regression of the forcing targets, eqs. (15)-(16).
``"lwr"``
    Locally weighted regression of the forcing targets, one local model per basis
    function (the paper's choice): :math:`w_i = \sum_t \psi_i s_t f_t / \sum_t \psi_i s_t^2`.
"""

from __future__ import annotations

import numpy as np

from .. import basis, symbolic
from ..dmp import DiscreteDMP, RhythmicDMP, goal_transform
from ..exceptions import FittingFailed, InvalidInputError, ShapeError
from ..trajectory import Trajectory
from ..validation import check_resources, flag, integer, real
from ._recall import Recall, exact

METHODS = ("position", "least_squares", "lwr")
GOAL_SCALINGS = ("auto", "paper", "rotation", "translation")
MAX_GOAL_AMPLIFICATION = 10.0
"""Largest factor by which a fitted DMP may amplify a goal change (:func:`goal_amplification`):
a goal moved by ``delta`` moves no point of the plan by more than this times ``|delta|``."""
PERIODICITY_TOLERANCE = 0.05
"""Default largest mismatch of a rhythmic demonstration with itself one period later,
relative to its extent (see :func:`periodicity_mismatch`)."""


def _check_demo(demo) -> Trajectory:
    if not isinstance(demo, Trajectory):
        raise InvalidInputError(
            f"demo must be a Trajectory, got {type(demo).__name__}; "
            "build one with Trajectory.from_positions(times, positions)"
        )
    if not demo.is_uniform:
        demo = demo.resampled(demo.n_steps)
    return demo


def _check_size(demo: Trajectory, n_features: int, n_basis: int) -> None:
    """Refuse underdetermined fits and fits whose regressors exceed the resource bounds."""
    if n_features > demo.n_steps:
        raise InvalidInputError(
            f"n_basis = {n_basis} gives {n_features} weights per DOF but demo has only "
            f"{demo.n_steps} samples, so the fit is underdetermined; lower n_basis or "
            "resample the demonstration (demo.resampled(n_steps))"
        )
    check_resources(
        f"a fit of {n_basis} basis functions to {demo.n_steps} samples",
        8.0 * (12 * demo.n_steps * (n_features + 3 + demo.n_dofs) + 3 * (n_features + 1) ** 2),
        "lower n_basis or resample the demonstration to fewer samples",
        n_samples=demo.n_steps,
    )


def _check_method(method: str) -> str:
    if method not in METHODS:
        raise InvalidInputError(f"method must be one of {METHODS}, got {method!r}")
    return method


def _ridge(features: np.ndarray, targets: np.ndarray, regularization: float, last_row=None):
    """Solve ``min |A X - B|^2 + lambda |X|^2`` (optionally with ``a_last X = b_last``).

    ``lambda`` is ``regularization`` times the mean diagonal of ``A^T A``, so that it is
    independent of the units and the number of samples.
    """
    gram = features.T @ features
    n = gram.shape[0]
    lam = regularization * np.trace(gram) / n
    rhs = features.T @ targets
    try:
        if last_row is None:
            return np.linalg.solve(gram + lam * np.eye(n), rhs)
        row, value = last_row
        kkt = np.zeros((n + 1, n + 1))
        kkt[:n, :n] = gram + lam * np.eye(n)
        kkt[:n, n] = row
        kkt[n, :n] = row
        return np.linalg.solve(kkt, np.vstack([rhs, value[None, :]]))[:n]
    except np.linalg.LinAlgError as error:
        raise FittingFailed(
            f"the least-squares problem is singular with regularization = {regularization!r}; "
            "raise regularization (e.g. 1e-9) or lower n_basis"
        ) from error


def _ratio(excursion, gap):
    """``excursion / gap``, infinite where the gap is zero."""
    return np.divide(excursion, gap, out=np.full(np.shape(gap), np.inf), where=gap > 0.0)


def goal_amplification(demo: Trajectory) -> tuple[float, np.ndarray]:
    r"""How much ``"rotation"`` and ``"paper"`` goal scaling amplify goal changes of ``demo``.

    Under ``"rotation"`` a goal moved by :math:`\delta` moves every point of the plan by
    :math:`\kappa |\delta|` at most, with :math:`\kappa = \max_t |y(t) - y_0| / |g - y_0|`
    (module docstring of :mod:`dmpopt.dmp`); under ``"paper"`` DOF :math:`d` moves by
    :math:`\kappa_d |\delta_d|`, :math:`\kappa_d = \max_t |y_d(t) - y_{0,d}| / |g_d -
    y_{0,d}|`; under ``"translation"`` by :math:`|\delta|` at most. :math:`\kappa \ge 1`;
    it is large when start and goal nearly coincide against the movement's extent.

    Returns
    -------
    rotation : float
        :math:`\kappa` (infinite if the demonstration ends where it starts).
    paper : ndarray, shape (n_dofs,)
        :math:`\kappa_d` (infinite for a DOF that ends where it starts).
    """
    offsets = demo.positions - demo.positions[0]
    rotation = _ratio(np.linalg.norm(offsets, axis=1).max(), np.linalg.norm(offsets[-1]))
    paper = _ratio(np.abs(offsets).max(axis=0), np.abs(offsets[-1]))
    return float(rotation), paper


def _fold(amplification: float) -> str:
    return f"{amplification:.3g}-fold" if np.isfinite(amplification) else "without bound"


def _goal_scaling(demo: Trajectory, goal_scaling: str) -> str:
    """The scaling to fit with: ``"auto"`` resolved, explicit choices checked against the
    amplification bound."""
    if goal_scaling not in GOAL_SCALINGS:
        raise InvalidInputError(
            f"goal_scaling must be one of {GOAL_SCALINGS}, got {goal_scaling!r}"
        )
    rotation, paper = goal_amplification(demo)
    bound = MAX_GOAL_AMPLIFICATION
    if goal_scaling == "auto":
        return "rotation" if rotation <= bound else "translation"
    if goal_scaling == "rotation" and rotation > bound:
        raise InvalidInputError(
            f"goal_scaling='rotation' would amplify goal changes {_fold(rotation)}, more than "
            f"the bound {bound:g} (MAX_GOAL_AMPLIFICATION): the demo's start-goal distance is "
            f"small against its extent; use goal_scaling='translation' (or 'auto', which picks "
            "it for such demos)"
        )
    if goal_scaling == "paper" and np.any(paper > bound):
        dofs = np.nonzero(paper > bound)[0].tolist()
        raise InvalidInputError(
            f"goal_scaling='paper' would amplify goal changes of DOF(s) {dofs} (largest: "
            f"{_fold(paper.max())}) more than the bound {bound:g} (MAX_GOAL_AMPLIFICATION): "
            "their start-goal distance is small (or zero) against their excursion; use "
            "goal_scaling='auto' (rotation or translation)"
        )
    return goal_scaling


def fit_discrete(
    demo: Trajectory,
    n_basis: int = 30,
    *,
    form: str = "velocity",
    method: str = "position",
    goal_scaling: str = "auto",
    regularization: float = 1e-9,
    alpha_z: float = 25.0,
    alpha_v: float = 25.0,
) -> DiscreteDMP:
    """Fit a discrete DMP to a point-to-point demonstration (Section 3.4).

    ``tau`` is chosen so that the unforced system is 95 % converged at the end of the
    demonstration; start and goal are the first and last samples. The DMP keeps the
    demonstrated start velocity (``scaled_start_velocity``), so that its default
    ``rollout()`` reproduces the demonstration and then comes to rest at the goal.

    Parameters
    ----------
    demo : Trajectory
        The demonstration, ``n_dofs`` DOFs (resampled to a uniform grid if needed).
    n_basis : int
        Basis functions per DOF.
    form : {"velocity", "acceleration"}
        Eq. (5) (follows demonstrations more closely: the forcing term acts on the
        velocity) or eq. (10) (continuous acceleration from rest, for controllers).
    method : {"position", "least_squares", "lwr"}
        See the module docstring.
    goal_scaling : {"auto", "rotation", "paper", "translation"}
        ``"auto"`` picks ``"rotation"`` if it amplifies goal changes at most
        :data:`MAX_GOAL_AMPLIFICATION`-fold (:func:`goal_amplification`), else
        ``"translation"`` (closed or nearly closed movements). An explicit ``"rotation"`` or
        ``"paper"`` beyond that bound is refused.
    regularization : float
        Ridge weight relative to the mean diagonal of the normal equations.
    alpha_z, alpha_v : float
        :math:`\\alpha_z` of eq. (5) or (10) and :math:`\\alpha_v` of eq. (6) (each
        :math:`\\beta = \\alpha / 4`), with ``alpha_v >= alpha_z / 50``
        (:data:`dmpopt.dmp.MAX_PHASE_SLOWDOWN`); a smaller ``alpha_v`` lengthens the default
        plan (:attr:`~dmpopt.DiscreteDMP.settling_time`), which lasts until the phase too is
        at rest.
    """
    demo = _check_demo(demo)
    method = _check_method(method)
    n_basis = basis.check_n_basis(n_basis)
    _check_size(demo, n_basis, n_basis)
    regularization = real("regularization", regularization, minimum=0.0)
    scaling = _goal_scaling(demo, goal_scaling)
    start, goal = demo.positions[0], demo.positions[-1]
    template = DiscreteDMP(
        weights=np.zeros((demo.n_dofs, n_basis)),
        start=start,
        goal=goal,
        tau=1.0,
        centres=np.zeros(n_basis),
        widths=np.ones(n_basis),
        form=form,
        goal_scaling="translation",
        alpha_z=alpha_z,
        alpha_v=alpha_v,
    )
    centres, widths = basis.discrete_basis(n_basis, template.gains)
    tau = demo.duration / basis.convergence_time(form, template.gains)
    unit = template.replace(tau=tau, centres=centres, widths=widths)
    dt = demo.duration / (demo.n_steps - 1)

    if method == "position":
        plan = unit.affine_plan(demo.duration, dt, start_velocity=demo.velocities[0])
        response = plan.weight_response[0]
        forcing = _ridge(
            response,
            demo.positions - plan.free[0],
            regularization,
            last_row=(response[-1], goal - plan.free[0][-1]),
        ).T
    else:
        states = unforced_states(unit, demo)
        targets = forcing_targets(unit, demo, states)
        regressors = _features(unit, states)
        if method == "least_squares":
            forcing = _ridge(regressors, targets, regularization).T
        else:
            forcing = _local_regression(unit, states[:, :2], targets)

    # stored per unit of the goal map at the demo's start and goal (see DiscreteDMP.goal_map),
    # a diagonal matrix there: diag(goal - start) under "paper", the identity otherwise
    displacement = goal - start
    reference = np.ones(demo.n_dofs) if scaling == "paper" else displacement
    per_unit = np.diag(goal_transform(scaling, reference, displacement))
    return unit.replace(
        weights=forcing / per_unit[:, None],
        scaled_start_velocity=tau * demo.velocities[0] / per_unit,
        goal_scaling=scaling,
        reference_displacement=displacement if scaling == "rotation" else None,
    )


def unforced_states(dmp: DiscreteDMP, demo: Trajectory) -> np.ndarray:
    """States of ``dmp``'s system with zero weights on the demo's grid, (n_steps, n_states).

    Integrated (:func:`dmpopt.symbolic.simulate`) from the demo's first position and velocity.
    With zero weights the forcing term is exactly zero, so the states do not depend on the
    basis: they are integrated with a single basis function, whose steps cost a fraction of
    those of many (the same numbers, bit for bit). The array is read-only: fits of the same
    demo and system share it (copy it to change it).
    """
    single = dmp.replace(
        weights=np.zeros((dmp.n_dofs, 1)), centres=dmp.centres[:1], widths=dmp.widths[:1]
    )
    initial = single.initial_state(demo.positions[0], demo.velocities[0], (0.0, 0.0))
    dt = demo.duration / (demo.n_steps - 1)
    parameters = single.parameters()
    key = ("states", single.signature, demo.n_steps, dt, exact(initial, *parameters.values()))
    return _RECALLED(
        key, lambda: symbolic.simulate(single.signature, demo.n_steps, initial, dt, parameters)[0]
    )


def forcing_targets(dmp: DiscreteDMP, demo: Trajectory, states: np.ndarray) -> np.ndarray:
    r"""Forcing terms that make the DMP follow the demonstration, eqs. (15) and (16).

    The transformation system solved for :math:`f` at every sample
    (:func:`dmpopt.symbolic.forcing_target`), with :math:`y, \dot y, \ddot y` of the
    demonstration. Acceleration form (16): the goal filter :math:`r(t)` comes from ``states``
    (the unforced system integrated from the demonstrated start). Velocity form (15): the
    state :math:`z` comes from :math:`\tau \dot z = \alpha_z(\beta_z(g - y) - z)` integrated
    along the demonstration (:func:`_filtered`). The array is read-only: fits of the same
    inputs share it (copy it to change it).
    """
    on_velocity = dmp.equations.forcing_on_velocity
    key = (
        "targets",
        dmp.signature,
        dmp.tau,
        exact(dmp.parameters()["goal"], dmp.gains, demo.times, demo.positions),
        exact(demo.velocities, demo.accelerations),
        None if on_velocity else exact(states[:, 2 + dmp.n_dofs :]),
    )

    def compute():
        if on_velocity:
            transformation = np.hstack([demo.positions, _filtered(dmp, demo, periodic=False)])
        else:
            transformation = np.hstack([demo.positions, states[:, 2 + dmp.n_dofs :]])
        return _solved_targets(dmp, demo, transformation)

    return _RECALLED(key, compute)


_RECALLED = Recall(8)
"""The unforced states and forcing targets of the last exact inputs: the fits of one
demonstration (several methods and basis counts) share those of their few distinct systems."""


def _solved_targets(dmp, demo: Trajectory, transformation: np.ndarray) -> np.ndarray:
    """:func:`dmpopt.symbolic.forcing_target` at every sample, shape (n_steps, n_dofs)."""
    target = symbolic.mapped(symbolic.forcing_target_function(dmp.signature), demo.n_steps)
    forcing = target(
        transformation=transformation.T,
        velocity=demo.velocities.T,
        acceleration=demo.accelerations.T,
        tau=dmp.tau,
        goal=dmp.parameters()["goal"],
        gains=np.asarray(dmp.gains),
    )["forcing"]
    return forcing.full().T


def _filtered(dmp, demo: Trajectory, periodic: bool) -> np.ndarray:
    r"""The state :math:`z` of eq. (15) along ``demo``, shape (n_steps, n_dofs).

    :func:`dmpopt.symbolic.filter_step` from sample to sample, the position held at the
    midpoint of each interval, starting from :math:`z = \tau \dot y(0)`. ``periodic``: a
    second pass starts where the first ends, and its end is taken for the first sample too
    (the filter's steady cycle on a periodic demonstration).
    """
    y = demo.positions
    accumulate = symbolic.accumulated(symbolic.filter_function(dmp.signature), demo.n_steps - 1)
    inputs = {
        "position": (0.5 * (y[1:] + y[:-1])).T,
        "dt": np.diff(demo.times)[None, :],
        "tau": dmp.tau,
        "goal": dmp.parameters()["goal"],
        "gains": np.asarray(dmp.gains),
    }
    first = dmp.tau * demo.velocities[0]
    z = accumulate(z=first, **inputs)["next_z"].full()
    if periodic:
        z = accumulate(z=z[:, -1], **inputs)["next_z"].full()
        first = z[:, -1]
    return np.vstack([first, z.T])


def _at_samples(function, canonical: np.ndarray, dmp) -> np.ndarray:
    """``function`` of (canonical state, centres, widths) at every sample, (n_steps, nnz).

    The mapped function (:func:`dmpopt.symbolic.mapped`) evaluated through CasADi's buffers
    on numpy memory: the same evaluation as calling it, bit for bit, without converting its
    answer to numpy (``DM.full()`` of n_steps x n_basis values cost as much as evaluating
    them).
    """
    n_steps = canonical.shape[0]
    mapped = symbolic.mapped(function, n_steps)
    inputs = [
        np.ascontiguousarray(canonical, dtype=float).ravel(),  # column-major (2, n_steps)
        np.tile(np.asarray(dmp.centres, dtype=float), n_steps),
        np.tile(np.asarray(dmp.widths, dtype=float), n_steps),
    ]
    values = np.empty((n_steps, function.nnz_out(0)))  # column-major (nnz, n_steps)
    if not mapped.sparsity_out(0).is_dense() or any(
        a.size != mapped.nnz_in(i) for i, a in enumerate(inputs)
    ):  # a sparse answer has no dense buffer layout: through the DM
        return mapped(canonical.T, dmp.centres, dmp.widths).full().T
    buffer, evaluate = mapped.buffer()
    for i, array in enumerate(inputs):
        buffer.set_arg(i, memoryview(array))
    buffer.set_res(0, memoryview(values.reshape(-1)))
    evaluate()
    # laid out as DM.full().T was: einsum and matmul sum in an order that follows the layout
    return np.ascontiguousarray(values.T).T


def _features(dmp, states: np.ndarray) -> np.ndarray:
    """Regressors at every sample, shape (n_steps, n_features)."""
    return _at_samples(symbolic.feature_function(dmp.signature), states[:, :2], dmp)


def _local_regression(dmp, canonical: np.ndarray, targets: np.ndarray) -> np.ndarray:
    r"""One weighted least-squares model per basis function (LWR), (n_dofs, n_features).

    Discrete: :math:`f \approx w_i v`, so :math:`w_i = \sum_t \psi_i v f / \sum_t \psi_i v^2`.
    Rhythmic: :math:`f \approx w_i^T \tilde v` with the 2-vector carrier :math:`\tilde v`, so
    :math:`w_i = (\sum_t \psi_i \tilde v \tilde v^T)^{-1} \sum_t \psi_i \tilde v f`.
    The carrier is read off the features, which are :math:`\bar\psi_i \tilde v` with
    normalised activations :math:`\bar\psi_i` summing to one.
    """
    n_steps = canonical.shape[0]
    activation = _at_samples(symbolic.activation_function(dmp.signature), canonical, dmp)
    regressors = _at_samples(symbolic.feature_function(dmp.signature), canonical, dmp)
    if dmp.equations.vectors_per_basis == 1:
        carrier = regressors.sum(axis=1)[:, None, None]  # the phase velocity v
    else:
        carrier = regressors.reshape(n_steps, dmp.n_basis, 2).sum(axis=1)[:, :, None]
    # moments[i] = sum_t psi_i(t) carrier carrier^T ; cross[i] = sum_t psi_i carrier f^T
    outer = carrier @ carrier.transpose(0, 2, 1)
    moments = np.einsum("ti,tab->iab", activation, outer)
    cross = np.einsum("ti,tad->iad", activation, carrier * targets[:, None, :])
    size = moments.shape[1]
    ridge = 1e-12 * np.trace(moments, axis1=1, axis2=2)[:, None, None] / size
    weights = np.linalg.solve(moments + ridge * np.eye(size) + 1e-300, cross)  # (basis, a, dofs)
    return weights.transpose(2, 0, 1).reshape(targets.shape[1], -1)


def reproduction_error(dmp, demo: Trajectory) -> float:
    """Root-mean-square Euclidean position error of the DMP's plan against ``demo``.

    A demonstration on a non-uniform grid is compared after resampling to a uniform one.
    """
    if not isinstance(dmp, (DiscreteDMP, RhythmicDMP)):
        raise InvalidInputError(
            f"dmp must be a DiscreteDMP or RhythmicDMP, got {type(dmp).__name__}"
        )
    demo = _check_demo(demo)
    if demo.n_dofs != dmp.n_dofs:
        raise ShapeError(
            f"demo has {demo.n_dofs} DOFs but dmp has {dmp.n_dofs}; compare the same DOFs"
        )
    dt = demo.duration / (demo.n_steps - 1)
    if isinstance(dmp, DiscreteDMP):
        plan = dmp.rollout(demo.duration, dt, start_velocity=demo.velocities[0])
    else:
        plan = dmp.rollout(demo.duration, dt, demo.positions[0], demo.velocities[0])
    return float(np.sqrt(np.mean(np.sum((plan.positions - demo.positions) ** 2, axis=1))))


def fit_to_accuracy(
    demo: Trajectory,
    tolerance: float,
    candidates=(5, 10, 15, 20, 30, 40, 60, 80, 100, 150, 200),
    rhythmic: bool = False,
    **options,
):
    """Fit with the fewest basis functions whose reproduction RMSE is below ``tolerance``.

    This is the automatic choice of the number of basis functions that LWPR gave the paper.
    ``rhythmic`` selects :func:`fit_rhythmic` instead of :func:`fit_discrete`; ``options``
    are passed on. Raises :class:`InvalidInputError` if no candidate reaches the tolerance.
    """
    tolerance = real("tolerance", tolerance, minimum=0.0, open_minimum=True)
    candidates = [basis.check_n_basis(n) for n in _sequence("candidates", candidates)]
    if not candidates:
        raise InvalidInputError("candidates is empty; give at least one number of basis functions")
    fit = fit_rhythmic if flag("rhythmic", rhythmic) else fit_discrete
    errors = []
    for n_basis in candidates:
        dmp = fit(demo, n_basis, **options)
        errors.append(reproduction_error(dmp, demo))
        if errors[-1] <= tolerance:
            return dmp
    raise InvalidInputError(
        f"no number of basis functions in {tuple(candidates)} reaches tolerance {tolerance}; "
        f"the best RMSE was {min(errors):.3g}: raise the tolerance or add candidates"
    )


def _sequence(name: str, value) -> list:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise InvalidInputError(f"{name} must be a sequence of integers, got {value!r}")
    return list(value)


def periodicity_mismatch(demo: Trajectory, period: float) -> tuple[float, float]:
    """How far ``demo`` is from repeating itself after ``period``, relative to its extent.

    Compares the positions and velocities at ``t`` and ``t + period`` over the overlap (for a
    demonstration of one period or a bit less: its end against its start) and returns the
    largest root-mean-square difference over the DOFs, divided by the largest peak-to-peak
    range of the positions (and of the velocities) over the DOFs, so that a DOF at rest does
    not count as non-periodic. Both are zero for a periodic demonstration.
    """
    shift = min(period, demo.duration)
    times = demo.times[demo.times + shift <= demo.times[-1] + 1e-12 * demo.duration]
    mismatch = []
    for values in (demo.positions, demo.velocities):
        later = np.column_stack([np.interp(times + shift, demo.times, v) for v in values.T])
        earlier = np.column_stack([np.interp(times, demo.times, v) for v in values.T])
        rms = np.sqrt(np.mean((later - earlier) ** 2, axis=0))
        extent = max(float(np.ptp(values, axis=0).max()), 1e-300)
        mismatch.append(float(np.max(rms) / extent))
    return mismatch[0], mismatch[1]


def estimate_period(demo: Trajectory) -> float:
    """Period of a periodic demonstration [s].

    The spectrum's peak gives a first guess; the period is then the shift ``P`` that
    minimises the mean squared difference between ``y(t)`` and ``y(t + P)``, found on a
    fine grid and refined by a parabola. The demonstration must cover more than 1.3 cycles.
    """
    demo = _check_demo(demo)
    centred = demo.positions - demo.positions.mean(axis=0)
    power = (np.abs(np.fft.rfft(centred, axis=0)) ** 2).sum(axis=1)
    power[0] = 0.0
    peak = int(np.argmax(power))
    if peak < 1:
        raise InvalidInputError("demo does not oscillate; pass period= explicitly")
    guess = demo.duration * demo.n_steps / (demo.n_steps - 1) / peak
    shifts = np.linspace(0.5 * guess, min(1.6 * guess, demo.duration / 1.3), 400)
    if shifts[-1] <= shifts[0]:
        raise InvalidInputError(
            "demo covers too few cycles to estimate its period; pass period= explicitly"
        )
    mismatch = np.array([_self_mismatch(demo, shift) for shift in shifts])
    k = int(np.argmin(mismatch))
    if k in (0, len(shifts) - 1):
        raise InvalidInputError(
            f"demo's self-similarity has no minimum between {shifts[0]:.4g} s and "
            f"{shifts[-1]:.4g} s around the spectral peak's period {guess:.4g} s (a "
            "demonstration of at least 1.3 cycles has one): pass period= explicitly"
        )
    left, centre, right = mismatch[k - 1 : k + 2]
    curvature = left - 2 * centre + right
    offset = 0.5 * (left - right) / curvature if curvature > 0 else 0.0
    return float(shifts[k] + offset * (shifts[1] - shifts[0]))


def _self_mismatch(demo: Trajectory, shift: float) -> float:
    times = demo.times
    inside = times + shift <= times[-1]
    shifted = np.column_stack(
        [np.interp(times[inside] + shift, times, column) for column in demo.positions.T]
    )
    return float(np.mean((shifted - demo.positions[inside]) ** 2))


def fit_rhythmic(
    demo: Trajectory,
    n_basis: int = 15,
    *,
    period: float | None = None,
    form: str = "phase",
    method: str = "position",
    kernel: str = "von_mises",
    amplitude: float = 1.0,
    regularization: float = 1e-9,
    alpha_z: float = 25.0,
    warm_up_periods: int = 2,
    periodicity_tolerance: float = PERIODICITY_TOLERANCE,
) -> RhythmicDMP:
    """Fit a rhythmic DMP to a periodic demonstration (Section 3.4, rhythmic case).

    The demonstration starts at oscillator phase 0 and should cover at least one period.
    The setpoint is the demonstration's mean.

    Parameters
    ----------
    demo : Trajectory
        Periodic demonstration of ``n_dofs`` DOFs.
    n_basis : int
        Basis functions per DOF (each with a 2-vector of weights).
    period : float, optional
        Period [s]; estimated from the spectrum if omitted.
    form : {"phase", "energy"}
        Eqs. (11)-(12) or (13)-(14).
    method : {"position", "least_squares", "lwr"}
        ``"position"`` fits the plan's limit cycle (after ``warm_up_periods`` periods of
        integration from the demonstrated start) to the demonstration; ``"least_squares"``
        and ``"lwr"`` regress the forcing targets of eq. (15).
    kernel : {"von_mises", "paper"}
    amplitude : float
        Amplitude the weights are learned at; scaling it later scales the movement.
    regularization : float
        Ridge weight (zero or positive) relative to the mean diagonal of the normal equations.
    warm_up_periods : int
        Periods integrated before the fitted window (``"position"`` method).
    periodicity_tolerance : float
        A demonstration that does not repeat itself after one period cannot be reproduced
        by a limit cycle: if :func:`periodicity_mismatch` of its positions or velocities
        exceeds this fraction of their extent, the fit is refused (``np.inf`` disables).
    """
    demo = _check_demo(demo)
    method = _check_method(method)
    n_basis = basis.check_n_basis(n_basis)
    _check_size(demo, 2 * n_basis, n_basis)
    regularization = real("regularization", regularization, minimum=0.0)
    warm_up_periods = integer("warm_up_periods", warm_up_periods, minimum=0)
    tolerance = periodicity_tolerance
    if tolerance != np.inf:
        tolerance = real("periodicity_tolerance", tolerance, minimum=0.0, open_minimum=True)
    period = (
        estimate_period(demo)
        if period is None
        else real("period", period, minimum=0.0, open_minimum=True)
    )
    if demo.duration < 0.95 * period:
        raise InvalidInputError(
            f"demo lasts {demo.duration:.4g} s, less than one period ({period:.4g} s); "
            "demonstrate at least one full cycle"
        )
    position_mismatch, velocity_mismatch = periodicity_mismatch(demo, period)
    if max(position_mismatch, velocity_mismatch) > tolerance:
        raise InvalidInputError(
            f"demo is not periodic with period {period:.4g} s: one period later its positions "
            f"differ by {position_mismatch:.2%} and its velocities by {velocity_mismatch:.2%} "
            f"of their extent (RMS), above periodicity_tolerance = {tolerance:.2%}; a rhythmic "
            "DMP would reproduce it wrongly. Trim the demonstration to whole cycles, fix "
            "period, or fit a discrete DMP"
        )
    centres, widths = basis.rhythmic_basis(n_basis, kernel)
    template = RhythmicDMP(
        weights=np.zeros((demo.n_dofs, n_basis, 2)),
        setpoint=demo.positions.mean(axis=0),
        tau=1.0,
        centres=centres,
        widths=widths,
        form=form,
        amplitude=amplitude,
        kernel=kernel,
        alpha_z=alpha_z,
    )
    # one turn of the phase per period: d(phase)/d(t / tau) is 1 for eq. (11) and -k = -1
    # for eq. (13) (the fit keeps k = 1; its oscillator turns clockwise)
    unit = template.replace(tau=period / (2 * np.pi))
    dt = demo.duration / (demo.n_steps - 1)
    direction = template.equations.turn_direction

    if method == "position":
        n_warm = int(round(warm_up_periods * period / dt))
        start_phase = -direction * n_warm * dt / unit.tau
        plan = unit.affine_plan(
            (n_warm + demo.n_steps - 1) * dt,
            dt,
            start=demo.positions[0],
            start_velocity=demo.velocities[0],
            phase=start_phase,
        )
        window = slice(n_warm, n_warm + demo.n_steps)
        response = plan.weight_response[0][window]
        forcing = _ridge(response, demo.positions - plan.free[0][window], regularization).T
    else:
        phases = direction * (demo.times - demo.times[0]) / unit.tau
        canonical = np.array([unit.canonical_state(p) for p in phases])
        regressors = _at_samples(symbolic.feature_function(unit.signature), canonical, unit)
        transformation = np.hstack([demo.positions, _filtered(unit, demo, periodic=True)])
        targets = _solved_targets(unit, demo, transformation)
        if method == "least_squares":
            forcing = _ridge(regressors, targets, regularization).T
        else:
            forcing = _local_regression(unit, canonical, targets)
    return unit.replace(weights=forcing.reshape(demo.n_dofs, n_basis, 2))

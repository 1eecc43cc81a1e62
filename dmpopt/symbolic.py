r"""The DMP systems assembled from their forms, and every function built from them.

Each form's equations are written once, in :mod:`dmpopt.forms`; this module assembles the
whole system (canonical and transformation states of all DOFs) from them and builds the
compiled functions. Every numeric result of dmpopt (rollouts, online steps, fitting matrices,
gradients) is evaluated from these expressions; nothing re-implements them in numpy. (To
evaluate one expression at tens of thousands of points, :class:`ArrayFunction` runs CasADi's
own instruction list on numpy arrays, and :func:`numba_source` translates it into Python for
numba, for the compiled pass of a rollout's response matrices, :mod:`dmpopt.response`.)

The discrete canonical system (6) is integrated normalised (start 0, goal 1), so that its
phase does not depend on any DOF's goal; the forcing term's dependence on the goal is carried
by the ``forcing_weights`` matrix that the caller builds from the weights (see
:mod:`dmpopt.dmp`). Time enters only as ``t / tau``: a step of ``dt`` with time constant
``tau`` is exactly a step of ``dt / tau`` with time constant 1.

Orientation (Cartesian DMPs, :mod:`dmpopt.cartesian`): the quaternion exponential and
logarithm and the map from the log-space state of a discrete system to an orientation,
angular velocity and angular acceleration (:func:`orientation_function`).

Discretisation: classical Runge-Kutta 4 with inputs held over the step. Velocities and
accelerations of the plan are the exact time derivatives of the continuous system at each
sample (accelerations by automatic differentiation along the flow).
"""

from __future__ import annotations

import hashlib
import math
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np

from .forms import (  # noqa: F401 (re-exported: the kernels)
    FORMS,
    KERNELS,
    Form,
    basis_log_activations,
    kernel_basis_terms,
    kernel_log_activations,
    kernel_phase_terms,
    kernel_phase_terms_slope,
    normalised_activations,
)
from .validation import check_resources


def n_transformation_states(form: str) -> int:
    """Transformation states per DOF: ``y, z`` and, in the acceleration form, ``r``."""
    return FORMS[form].n_transformation


def n_features(form: str, n_basis: int) -> int:
    """Weights per DOF: one per basis (discrete), a 2-vector per basis (rhythmic)."""
    return FORMS[form].n_features(n_basis)


@dataclass(frozen=True)
class Signature:
    """The sizes and choices that fix one compiled system."""

    form: str
    n_dofs: int
    n_basis: int
    kernel: str

    @property
    def n_states(self) -> int:
        """Length of the state vector."""
        return 2 + n_transformation_states(self.form) * self.n_dofs

    @property
    def n_features(self) -> int:
        """Length of the feature vector that multiplies the weights."""
        return n_features(self.form, self.n_basis)

    @property
    def equations(self) -> Form:
        """The form's object (:mod:`dmpopt.forms`)."""
        return FORMS[self.form]


# ---------------------------------------------------------------------------------------
# The equations
# ---------------------------------------------------------------------------------------


PARAMETER_NAMES = (
    "tau",
    "goal",
    "canonical_target",
    "forcing_weights",
    "centres",
    "widths",
    "gains",
    "coupling",
    "canonical_coupling",
)
"""Named inputs of every compiled function besides ``state`` (and ``dt``), in call order."""
PLAN_OUTPUTS = ("position", "velocity", "acceleration")
"""Outputs of the step and output functions, after ``next_state`` in the step's."""


@dataclass(frozen=True)
class Symbols:
    """Symbolic inputs of one system: the state, the step and the parameters."""

    state: ca.SX
    dt: ca.SX
    tau: ca.SX
    goal: ca.SX
    canonical_target: ca.SX
    forcing_weights: ca.SX
    centres: ca.SX
    widths: ca.SX
    gains: ca.SX
    coupling: ca.SX
    canonical_coupling: ca.SX

    def parameters(self) -> dict:
        """The parameter symbols by name, in :data:`PARAMETER_NAMES` order."""
        return {name: getattr(self, name) for name in PARAMETER_NAMES}


def parameters(**values) -> dict:
    """Every parameter input by name: ``values`` where given, else ``tau = 1`` and zero (a
    scalar fills a vector or matrix input)."""
    unknown = sorted(set(values) - set(PARAMETER_NAMES))
    if unknown:
        raise ValueError(f"unknown parameters {unknown}; the parameters are {PARAMETER_NAMES}")
    return {name: values.get(name, 1.0 if name == "tau" else 0.0) for name in PARAMETER_NAMES}


def make_symbols(signature: Signature) -> Symbols:
    """Fresh symbols sized for ``signature``."""
    d, n = signature.n_dofs, signature.n_basis
    return Symbols(
        state=ca.SX.sym("state", signature.n_states),
        dt=ca.SX.sym("dt"),
        tau=ca.SX.sym("tau"),
        goal=ca.SX.sym("goal", d),
        canonical_target=ca.SX.sym("canonical_target"),
        forcing_weights=ca.SX.sym("forcing_weights", d, signature.n_features),
        centres=ca.SX.sym("centres", n),
        widths=ca.SX.sym("widths", n),
        gains=ca.SX.sym("gains", len(FORMS[signature.form].gain_names)),
        coupling=ca.SX.sym("coupling", d),
        canonical_coupling=ca.SX.sym("canonical_coupling"),
    )


def function(name: str, inputs: dict, outputs: dict, options=None) -> ca.Function:
    """A ``casadi.Function`` whose inputs and outputs carry the names of the dicts' keys."""
    return ca.Function(
        name,
        list(inputs.values()),
        list(outputs.values()),
        list(inputs),
        list(outputs),
        options or {},
    )


def system_rhs(signature: Signature, s: Symbols, state):
    """Time derivative of the whole state (canonical then transformation), eqs. (5)-(14)."""
    form = signature.equations
    canonical, transformation = state[:2], state[2:]
    phi = form.features(signature.kernel, canonical, s.centres, s.widths)
    forcing = s.forcing_weights @ phi
    canonical_rate = form.canonical_rhs(
        canonical, s.canonical_target, s.gains, s.canonical_coupling
    )
    transformation_rate = form.transformation_rhs(
        transformation, s.goal, forcing, s.gains, s.coupling
    )
    return ca.vertcat(canonical_rate, transformation_rate) / s.tau


def plan_outputs(signature: Signature, s: Symbols) -> dict:
    """Position, velocity and acceleration of every DOF at the state ``s.state``.

    The acceleration is the derivative of the velocity along the flow (inputs held).
    """
    d = signature.n_dofs
    rate = system_rhs(signature, s, s.state)
    velocity = rate[2 : 2 + d]
    return {
        "position": s.state[2 : 2 + d],
        "velocity": velocity,
        "acceleration": ca.jtimes(velocity, s.state, rate),
    }


def forcing_target(form: Form, transformation, velocity, acceleration, tau, goal, gains):
    r"""The forcing term :math:`f` that gives the transformation system ``velocity`` and
    ``acceleration`` at ``transformation``: eq. (5) or (10) solved for :math:`f`.

    Velocity and rhythmic forms, eq. (15): :math:`f` enters :math:`\tau\dot y = z + f`, so
    :math:`f = \tau \dot y - z` with the :math:`z` of ``transformation``.
    Acceleration form, eq. (16): :math:`\tau \dot y = z` fixes :math:`z = \tau\dot y` and
    :math:`f` enters :math:`\tau \dot z`: :math:`f = \tau^2 \ddot y - \alpha_z(\beta_z(r - y)
    - \tau \dot y)`.
    """
    n = goal.shape[0]
    if form.forcing_on_velocity:
        forced, rate = slice(0, n), tau * velocity
    else:
        transformation = ca.vertcat(transformation[:n], tau * velocity, transformation[2 * n :])
        forced, rate = slice(n, 2 * n), tau**2 * acceleration
    unforced = form.transformation_rhs(transformation, goal, ca.SX.zeros(n), gains, 0.0)
    return rate - unforced[forced]


def filter_step(form: Form, z, position, dt, tau, goal, gains):
    r"""Exact step ``dt`` of :math:`\tau \dot z = \alpha_z(\beta_z(g - y) - z)` (eq. (5)
    unforced) with the position :math:`y` held: the :math:`z` of eq. (15) along a
    demonstration.

    The equation is linear in :math:`z`, :math:`\dot z = a (z - z^*)`, so
    :math:`z(dt) = e^{a\,dt} z + (1 - e^{a\,dt}) z^*`; :math:`a` and the equilibrium
    :math:`z^*` are read off the form's ``transformation_rhs``.
    """
    n = goal.shape[0]
    zeros = ca.SX.zeros(n)
    rate = form.transformation_rhs(ca.vertcat(position, z), goal, zeros, gains, 0.0)[n:] / tau
    slope = ca.diag(ca.jacobian(rate, z))
    equilibrium = -ca.substitute(rate, z, zeros) / slope
    decay = ca.exp(slope * dt)
    return decay * z + (1.0 - decay) * equilibrium


# ---------------------------------------------------------------------------------------
# Compiled functions (cached)
# ---------------------------------------------------------------------------------------


def runge_kutta_4(rate, state, dt) -> tuple[list, ca.SX]:
    """One classical Runge-Kutta 4 step of ``state`` by ``dt``, the discretisation of every
    system: ``(stages, next_state)``.

    ``rate(x, stage)`` is the time derivative at ``x`` in stage ``0 .. 3``; ``stages`` are the
    four states at which it is evaluated (the forcing term enters each stage at the canonical
    part of that stage's state, :func:`canonical_step_function`).
    """
    k1 = rate(state, 0)
    second = state + 0.5 * dt * k1
    k2 = rate(second, 1)
    third = state + 0.5 * dt * k2
    k3 = rate(third, 2)
    fourth = state + dt * k3
    k4 = rate(fourth, 3)
    return [state, second, third, fourth], state + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


STEP_BYTES_PER_FEATURE, STEP_BYTES_PER_FEATURE_AND_DOF = 48e3, 8e3
"""Memory [bytes] that building :func:`step_function` takes per basis feature, plus per
feature and DOF: a little above the 40 kB and 6.2 kB measured (peak resident size while
building steppers of 1000-4000 bases and 1-4 DOFs, all four forms; 0.6-1.3 s per 1000 bases).
A stepper of 10^5 bases took 183 s and 4.8 GB before this bound refused it."""


@lru_cache(maxsize=64)
def step_function(signature: Signature) -> ca.Function:
    """One RK4 step: ``(state, dt, **parameters) -> (next_state, position, velocity,
    acceleration)``, the last three at ``next_state``. Refused before it is built beyond
    :data:`dmpopt.validation.MEMORY_BUDGET` (:data:`STEP_BYTES_PER_FEATURE`)."""
    d, n = signature.n_dofs, signature.n_features
    check_resources(
        f"the symbolic step of {d} DOFs x {n} basis features (a stepper's)",
        n * (STEP_BYTES_PER_FEATURE + STEP_BYTES_PER_FEATURE_AND_DOF * d),
        "use fewer basis functions (the step grows with their number times the DOFs)",
    )
    s = make_symbols(signature)
    _, next_state = runge_kutta_4(lambda x, _: system_rhs(signature, s, x), s.state, s.dt)
    outputs = output_function(signature)(state=next_state, **s.parameters())  # a dict by name
    return function(
        "dmp_step",
        {"state": s.state, "dt": s.dt, **s.parameters()},
        {"next_state": next_state, **{name: outputs[name] for name in PLAN_OUTPUTS}},
        {"cse": True},
    )


@lru_cache(maxsize=64)
def output_function(signature: Signature) -> ca.Function:
    """``(state, **parameters) -> (position, velocity, acceleration)`` at one state."""
    s = make_symbols(signature)
    return function(
        "dmp_outputs",
        {"state": s.state, **s.parameters()},
        plan_outputs(signature, s),
    )


@lru_cache(maxsize=64)
def feature_function(signature: Signature) -> ca.Function:
    """``(canonical_state, centres, widths) -> features`` (the regressors of imitation)."""
    s = make_symbols(signature)
    canonical = ca.SX.sym("canonical", 2)
    phi = signature.equations.features(signature.kernel, canonical, s.centres, s.widths)
    return ca.Function("dmp_features", [canonical, s.centres, s.widths], [phi])


@lru_cache(maxsize=64)
def activation_function(signature: Signature) -> ca.Function:
    """``(canonical_state, centres, widths) -> psi`` (unnormalised, for local regression)."""
    s = make_symbols(signature)
    canonical = ca.SX.sym("canonical", 2)
    log_psi = signature.equations.log_activations(signature.kernel, canonical, s.centres, s.widths)
    return ca.Function("dmp_activations", [canonical, s.centres, s.widths], [ca.exp(log_psi)])


@lru_cache(maxsize=64)
def forcing_target_function(signature: Signature) -> ca.Function:
    """``(transformation, velocity, acceleration, tau, goal, gains) -> forcing`` at one sample
    (:func:`forcing_target`); ``.map(n)`` evaluates a whole demonstration."""
    s = make_symbols(signature)
    d = signature.n_dofs
    transformation = ca.SX.sym("transformation", signature.n_states - 2)
    velocity, acceleration = ca.SX.sym("velocity", d), ca.SX.sym("acceleration", d)
    target = forcing_target(
        signature.equations, transformation, velocity, acceleration, s.tau, s.goal, s.gains
    )
    inputs = {"transformation": transformation, "velocity": velocity}
    inputs |= {"acceleration": acceleration, "tau": s.tau, "goal": s.goal, "gains": s.gains}
    return function("dmp_forcing_target", inputs, {"forcing": target})


@lru_cache(maxsize=64)
def filter_function(signature: Signature) -> ca.Function:
    """``(z, position, dt, tau, goal, gains) -> next_z`` (:func:`filter_step`);
    ``.mapaccum(n)`` runs it along a demonstration."""
    s = make_symbols(signature)
    d = signature.n_dofs
    z, position = ca.SX.sym("z", d), ca.SX.sym("position", d)
    following = filter_step(signature.equations, z, position, s.dt, s.tau, s.goal, s.gains)
    inputs = {"z": z, "position": position, "dt": s.dt}
    inputs |= {"tau": s.tau, "goal": s.goal, "gains": s.gains}
    return function("dmp_filter", inputs, {"next_z": following})


@lru_cache(maxsize=32)
def rollout_function(signature: Signature, n_steps: int) -> ca.Function:
    """Whole rollout in one call: ``(initial_state, dt, **parameters) -> (positions,
    velocities, accelerations, states)``.

    Outputs are ``(n_dofs, n_steps)`` matrices, samples at ``k * dt`` for
    ``k = 0 .. n_steps - 1``; ``states`` is ``(n_states, n_steps)``.
    """
    s = make_symbols(signature)
    x0 = ca.MX.sym("initial_state", signature.n_states)
    dt = ca.MX.sym("dt")
    params = {name: ca.MX.sym(name, p.shape) for name, p in s.parameters().items()}
    first = output_function(signature)(state=x0, **params)
    columns = [first["position"], first["velocity"], first["acceleration"], x0]
    if n_steps > 1:
        accumulated = step_function(signature).mapaccum("dmp_accumulate", n_steps - 1)
        later = accumulated(state=x0, dt=dt, **params)
        rows = ("position", "velocity", "acceleration", "next_state")
        columns = [ca.horzcat(c, later[name]) for c, name in zip(columns, rows)]
    names = ("positions", "velocities", "accelerations", "states")
    return function(
        "dmp_rollout", {"initial_state": x0, "dt": dt, **params}, dict(zip(names, columns))
    )


# ---------------------------------------------------------------------------------------
# The parts of a rollout of one DOF (the response matrices of dmpopt.dmp)
# ---------------------------------------------------------------------------------------


@lru_cache(maxsize=64)
def canonical_step_function(signature: Signature) -> ca.Function:
    """One RK4 step of the canonical system alone, in time normalised by ``tau``, uncoupled:
    ``(canonical, dt, canonical_target, gains) -> (next_canonical, stages)``, ``stages`` of
    shape (2, 4).

    The canonical system does not depend on the transformation states, so these are the
    canonical parts of the stages of :func:`step_function` (:func:`runge_kutta_4`): the
    states at which the whole step evaluates the forcing term's features.
    """
    form, s = signature.equations, make_symbols(signature)
    canonical = ca.SX.sym("canonical", 2)
    stages, following = runge_kutta_4(
        lambda x, _: form.canonical_rhs(x, s.canonical_target, s.gains, 0.0), canonical, s.dt
    )
    inputs = {"canonical": canonical, "dt": s.dt}
    inputs |= {"canonical_target": s.canonical_target, "gains": s.gains}
    outputs = {"next_canonical": following, "stages": ca.horzcat(*stages)}
    return function("dmp_canonical_step", inputs, outputs)


CANONICAL_BLOCK = 256
"""Steps of :func:`canonical_steps_function` per call (a few microseconds of call overhead
each; the last block of a trajectory may run past its end)."""


@lru_cache(maxsize=64)
def canonical_steps_function(signature: Signature) -> ca.Function:
    """:data:`CANONICAL_BLOCK` steps of :func:`canonical_step_function` in one call
    (``mapaccum``): the inputs besides ``canonical`` are given per step, the outputs are
    those of every step side by side."""
    step = canonical_step_function(signature)
    return step.mapaccum("dmp_canonical_steps", CANONICAL_BLOCK, [0], [0])


@lru_cache(maxsize=16)
def transformation_matrices(form_name: str) -> ca.Function:
    r"""The transformation system of one DOF as matrices, in time normalised by ``tau``:
    ``(dt, gains) -> (step, step_goal, step_forcing, output, output_goal, output_forcing)``.

    The system (eq. (5) or (10)) is linear in its state :math:`s`, the goal :math:`g` and the
    forcing term, so its RK4 step (:func:`runge_kutta_4`, the forcing term :math:`f_j` given
    at each stage :math:`j`) and its position, velocity and acceleration (as in
    :func:`plan_outputs`, with the forcing term's time derivative :math:`\dot f` given) are

    .. math:: s_{k+1} = S s_k + S_g g + S_f (f_1, f_2, f_3, f_4)^T, \quad
              (y, \dot y, \ddot y)^T = O s + O_g g + O_f (f, \dot f)^T

    with the Jacobians of the form's equations as the matrices (shapes (n, n), (n, 1),
    (n, 4), (3, n), (3, 1), (3, 2), ``n`` transformation states).
    """
    form = FORMS[form_name]
    transformation = ca.SX.sym("transformation", form.n_transformation)
    goal, dt = ca.SX.sym("goal"), ca.SX.sym("dt")
    gains = ca.SX.sym("gains", len(form.gain_names))
    stage_forcing, forcing = ca.SX.sym("stage_forcing", 4), ca.SX.sym("forcing", 2)

    def rate(x, stage):
        return form.transformation_rhs(x, goal, stage_forcing[stage], gains, 0.0)

    _, following = runge_kutta_4(rate, transformation, dt)
    rate_now = form.transformation_rhs(transformation, goal, forcing[0], gains, 0.0)
    velocity = rate_now[0]
    both = ca.vertcat(transformation, forcing[0])
    acceleration = ca.jtimes(velocity, both, ca.vertcat(rate_now, forcing[1]))
    outputs = ca.vertcat(transformation[0], velocity, acceleration)
    return function(
        "dmp_transformation_matrices",
        {"dt": dt, "gains": gains},
        {
            name: ca.densify(ca.jacobian(expression, wrt))
            for name, expression, wrt in (
                ("step", following, transformation),
                ("step_goal", following, goal),
                ("step_forcing", following, stage_forcing),
                ("output", outputs, transformation),
                ("output_goal", outputs, goal),
                ("output_forcing", outputs, forcing),
            )
        },
    )


@lru_cache(maxsize=64)
def feature_rate_function(signature: Signature) -> ca.Function:
    """``(canonical, centres, widths, canonical_target, gains) -> (features, feature_rate)``:
    the forcing term's features and their time derivative along the uncoupled canonical
    system, in time normalised by ``tau`` (what the acceleration of :func:`plan_outputs`
    takes from the canonical state)."""
    form, s = signature.equations, make_symbols(signature)
    canonical = ca.SX.sym("canonical", 2)
    phi = form.features(signature.kernel, canonical, s.centres, s.widths)
    rate = form.canonical_rhs(canonical, s.canonical_target, s.gains, 0.0)
    inputs = {"canonical": canonical, "centres": s.centres, "widths": s.widths}
    inputs |= {"canonical_target": s.canonical_target, "gains": s.gains}
    outputs = {"features": phi, "feature_rate": ca.jtimes(phi, canonical, rate)}
    return function("dmp_feature_rate", inputs, outputs)


@lru_cache(maxsize=16)
def phase_point_function(form_name: str, kernel: str) -> ca.Function:
    r"""``(canonical, canonical_target, gains) -> (phase, phase_rate, carrier, carrier_rate,
    phase_terms, phase_terms_slope)`` at one canonical state of the uncoupled canonical system,
    in time normalised by ``tau``: the basis functions' argument (:meth:`Form.basis_phase`),
    the vector the normalised activations multiply (:meth:`Form.carrier`, padded with zeros to
    2 entries), their time derivatives along the canonical system (eqs. (6), (11), (13)), and
    what the kernel's log-activations need of the state (:meth:`Form.phase_terms`) with its
    derivative in the phase (:func:`forms.kernel_phase_terms_slope`). With
    :func:`log_activation_function` these are the form- and kernel-specific parts of the
    features (:meth:`Form.features`), evaluated piecewise by :mod:`dmpopt.response`."""
    form = FORMS[form_name]
    canonical, target = ca.SX.sym("canonical", 2), ca.SX.sym("canonical_target")
    gains = ca.SX.sym("gains", len(form.gain_names))
    rate = form.canonical_rhs(canonical, target, gains, 0.0)
    phase = form.basis_phase(canonical)
    carrier = ca.vertcat(form.carrier(canonical), ca.SX.zeros(2 - form.vectors_per_basis))
    terms = form.phase_terms(kernel, canonical)
    outputs = {
        "phase": phase,
        "phase_rate": ca.jtimes(phase, canonical, rate),
        "carrier": carrier,
        "carrier_rate": ca.jtimes(carrier, canonical, rate),
        "phase_terms": ca.vertcat(*terms),
        "phase_terms_slope": ca.vertcat(*kernel_phase_terms_slope(kernel, terms)),
    }
    inputs = {"canonical": canonical, "canonical_target": target, "gains": gains}
    return function(
        "dmp_phase_point", inputs, {name: ca.densify(value) for name, value in outputs.items()}
    )


@lru_cache(maxsize=16)
def phase_terms_function(kernel: str) -> ca.Function:
    r"""``phase -> phase_terms``: what the kernel's log-activations need of a phase
    (:func:`forms.kernel_phase_terms`; at a canonical state, :func:`phase_point_function`
    gives them with their slope)."""
    phase = ca.SX.sym("phase")
    terms = ca.vertcat(*kernel_phase_terms(kernel, phase))
    return function("dmp_phase_terms", {"phase": phase}, {"phase_terms": terms})


@lru_cache(maxsize=16)
def basis_terms_function(kernel: str) -> ca.Function:
    """``(centre, width) -> basis_terms``: what the kernel's log-activations need of one basis
    (:func:`forms.kernel_basis_terms`), taken once per basis."""
    centre, width = ca.SX.sym("centre"), ca.SX.sym("width")
    terms = ca.vertcat(*kernel_basis_terms(kernel, centre, width))
    return function("dmp_basis_terms", {"centre": centre, "width": width}, {"basis_terms": terms})


@lru_cache(maxsize=16)
def log_activation_function(kernel: str, slope: bool = True) -> ca.Function:
    r"""``(phase_terms, phase_terms_slope, basis_terms) -> (log_activation,
    log_activation_slope)``: the logarithm :math:`l` of one basis function's activation
    (:func:`basis_log_activations`) from the terms of :func:`phase_terms_function` and
    :func:`basis_terms_function`, and :math:`\partial l / \partial \phi`; ``slope=False``:
    ``(phase_terms, basis_terms) -> log_activation``, by the same instructions less those of
    the slope."""
    n_phase = phase_terms_function(kernel).nnz_out(0)
    n_basis = basis_terms_function(kernel).nnz_out(0)
    terms, basis = ca.SX.sym("phase_terms", n_phase), ca.SX.sym("basis_terms", n_basis)
    log_psi = kernel_log_activations(kernel, ca.vertsplit(terms), ca.vertsplit(basis))
    if not slope:
        inputs = {"phase_terms": terms, "basis_terms": basis}
        return function("dmp_log_activation", inputs, {"log_activation": log_psi})
    terms_slope = ca.SX.sym("phase_terms_slope", n_phase)
    inputs = {"phase_terms": terms, "phase_terms_slope": terms_slope, "basis_terms": basis}
    outputs = {
        "log_activation": log_psi,
        "log_activation_slope": ca.jtimes(log_psi, terms, terms_slope),
    }
    return function("dmp_log_activation", inputs, outputs)


_NUMBA_UNARY = {
    ca.OP_ASSIGN: "{0}",
    ca.OP_NEG: "-{0}",
    ca.OP_EXP: "math.exp({0})",
    ca.OP_LOG: "math.log({0})",
    ca.OP_SQRT: "math.sqrt({0})",
    ca.OP_SQ: "{0} * {0}",
    ca.OP_INV: "1.0 / {0}",
    ca.OP_SIN: "math.sin({0})",
    ca.OP_COS: "math.cos({0})",
    ca.OP_TAN: "math.tan({0})",
    ca.OP_FABS: "abs({0})",
    ca.OP_SIGN: "np.sign({0})",
    ca.OP_FLOOR: "np.floor({0})",
    ca.OP_CEIL: "np.ceil({0})",
    ca.OP_NOT: "float({0} == 0.0)",
    ca.OP_TWICE: "{0} + {0}",
}
_NUMBA_BINARY = {
    ca.OP_ADD: "{0} + {1}",
    ca.OP_SUB: "{0} - {1}",
    ca.OP_MUL: "{0} * {1}",
    ca.OP_DIV: "{0} / {1}",
    ca.OP_POW: "{0} ** {1}",
    ca.OP_CONSTPOW: "{0} ** {1}",
    ca.OP_FMIN: "np.fmin({0}, {1})",
    ca.OP_FMAX: "np.fmax({0}, {1})",
    ca.OP_FMOD: "np.fmod({0}, {1})",
    ca.OP_ATAN2: "math.atan2({0}, {1})",
    ca.OP_COPYSIGN: "math.copysign({0}, {1})",
    ca.OP_LT: "float({0} < {1})",
    ca.OP_LE: "float({0} <= {1})",
    ca.OP_EQ: "float({0} == {1})",
    ca.OP_NE: "float({0} != {1})",
    ca.OP_AND: "float({0} != 0.0 and {1} != 0.0)",
    ca.OP_OR: "float({0} != 0.0 or {1} != 0.0)",
    ca.OP_IF_ELSE_ZERO: "({1} if {0} != 0.0 else 0.0)",
}
"""CasADi's scalar operations as Python expressions that numba compiles (the operations of
:data:`_UNARY` and :data:`_BINARY`, the same C library functions for exp, sin, ...)."""


def numba_source(function: ca.Function, name: str) -> str:
    """Python source of a function ``name`` that computes the SX ``function``, one line per
    CasADi instruction, for numba to compile (:mod:`dmpopt.response`).

    An input with one nonzero is a float argument, a larger one an array argument indexed
    by nonzero; the result is the tuple of every output's nonzeros, in order. The
    expressions are CasADi's own instruction list, so the compiled code performs the same
    operations in the same order as CasADi's virtual machine.
    """
    arguments = [f"a{i}" for i in range(function.n_in())]
    offsets = np.cumsum([0] + [function.nnz_out(i) for i in range(function.n_out())])
    results = ["0.0"] * int(offsets[-1])
    lines = [f"def {name}({', '.join(arguments)}):"]
    for k in range(function.n_instructions()):
        op = function.instruction_id(k)
        inputs, outputs = function.instruction_input(k), function.instruction_output(k)
        target = f"w{outputs[0]}"
        if op == ca.OP_INPUT:
            single = function.nnz_in(inputs[0]) == 1
            value = arguments[inputs[0]] + ("" if single else f"[{inputs[1]}]")
        elif op == ca.OP_OUTPUT:  # a fresh name: a later instruction may reuse the entry
            index = int(offsets[outputs[0]]) + outputs[1]
            results[index] = f"r{index}"
            lines.append(f"    r{index} = w{inputs[0]}")
            continue
        elif op == ca.OP_CONST:
            constant = function.instruction_constant(k)
            special = {math.inf: "math.inf", -math.inf: "-math.inf"}.get(constant, "math.nan")
            value = repr(constant) if math.isfinite(constant) else special
        elif op in _NUMBA_UNARY:
            value = _NUMBA_UNARY[op].format(f"w{inputs[0]}")
        elif op in _NUMBA_BINARY:
            value = _NUMBA_BINARY[op].format(f"w{inputs[0]}", f"w{inputs[1]}")
        else:
            raise NotImplementedError(
                f"{function.name()}: CasADi operation {op} has no numba expression; add it "
                "to symbolic._NUMBA_UNARY or _NUMBA_BINARY"
            )
        lines.append(f"    {target} = {value}")
    lines.append(f"    return ({', '.join(results)},)")
    return "\n".join(lines) + "\n"


_UNARY = {
    ca.OP_ASSIGN: np.positive,  # a copy: no two entries of the work vector share memory
    ca.OP_NEG: np.negative,
    ca.OP_EXP: np.exp,
    ca.OP_LOG: np.log,
    ca.OP_SQRT: np.sqrt,
    ca.OP_SQ: np.square,
    ca.OP_INV: np.reciprocal,
    ca.OP_SIN: np.sin,
    ca.OP_COS: np.cos,
    ca.OP_TAN: np.tan,
    ca.OP_FABS: np.absolute,
    ca.OP_SIGN: np.sign,
    ca.OP_FLOOR: np.floor,
    ca.OP_CEIL: np.ceil,
    ca.OP_NOT: np.logical_not,
}
_BINARY = {
    ca.OP_ADD: np.add,
    ca.OP_SUB: np.subtract,
    ca.OP_MUL: np.multiply,
    ca.OP_DIV: np.divide,
    ca.OP_POW: np.power,
    ca.OP_CONSTPOW: np.power,
    ca.OP_FMIN: np.fmin,
    ca.OP_FMAX: np.fmax,
    ca.OP_FMOD: np.fmod,
    ca.OP_ATAN2: np.arctan2,
    ca.OP_COPYSIGN: np.copysign,
    ca.OP_LT: np.less,
    ca.OP_LE: np.less_equal,
    ca.OP_EQ: np.equal,
    ca.OP_NE: np.not_equal,
    ca.OP_AND: np.logical_and,
    ca.OP_OR: np.logical_or,
}
"""CasADi's scalar operations and the numpy functions that apply them elementwise (comparisons
give 1.0 or 0.0, as CasADi's; ``if_else_zero`` and ``twice`` are handled apart)."""


class ArrayFunction:
    """An SX ``casadi.Function`` evaluated at many points at once, on numpy arrays.

    Each scalar instruction of the function runs as one numpy operation over all points, so
    the points cost what the arithmetic costs (CasADi's virtual machine evaluates a function
    at 40k points one after the other, several times more slowly). The expressions are
    CasADi's; only their operations are mapped to numpy's (1 ulp may differ in ``exp``,
    ``sin``, ...).
    """

    work_size = 2**21
    """Floats in the work arrays (one per entry of CasADi's work vector, 16 MiB): the points
    are evaluated in chunks of at most ``work_size / sz_w`` (and 16384, fastest as measured
    on the LASA demo's plan)."""

    def __init__(self, function: ca.Function):
        self.function = function
        self._instructions = []
        for k in range(function.n_instructions()):
            op = function.instruction_id(k)
            known = (ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_TWICE, ca.OP_IF_ELSE_ZERO)
            if op not in (*known, *_UNARY, *_BINARY):
                raise NotImplementedError(
                    f"{function.name()}: CasADi operation {op} has no numpy equivalent in "
                    "ArrayFunction; add it to symbolic._UNARY or _BINARY"
                )
            constant = function.instruction_constant(k) if op == ca.OP_CONST else None
            self._instructions.append(
                (op, function.instruction_input(k), function.instruction_output(k), constant)
            )

    def __call__(self, *inputs, n_points: int, out=None) -> list[np.ndarray]:
        """Outputs at ``n_points`` points, each of shape (n_points, nnz) (entries column-major).

        ``inputs`` in the function's order: arrays of shape (nnz, n_points), or (nnz,) for an
        input shared by all points. ``out``: arrays to write the outputs into (optional).
        """
        function = self.function
        if out is None:
            out = [np.empty((n_points, function.nnz_out(i))) for i in range(function.n_out())]
        inputs = [np.atleast_1d(np.asarray(value, dtype=float)) for value in inputs]
        size = max(64, min(16384, self.work_size // max(function.sz_w(), 1)))
        for begin in range(0, n_points, size):
            points = slice(begin, min(begin + size, n_points))
            chunk = [value if value.ndim == 1 else value[:, points] for value in inputs]
            self._evaluate(chunk, [array[points] for array in out])
        return out

    def _evaluate(self, inputs: list, out: list) -> None:
        """One chunk: each entry of CasADi's work vector is a float (constants and shared
        inputs), a row of an input, or its own buffer, written in place."""
        n = out[0].shape[0]
        buffers = np.empty((self.function.sz_w(), n))
        work = [0.0] * self.function.sz_w()
        for op, arguments, results, constant in self._instructions:
            result = results[0]
            if op == ca.OP_INPUT:
                value = inputs[arguments[0]][arguments[1]]
                work[result] = float(value) if np.ndim(value) == 0 else value
            elif op == ca.OP_OUTPUT:
                out[result][:, results[1]] = work[arguments[0]]
            elif op == ca.OP_CONST:
                work[result] = constant
            elif op in _UNARY:
                a = work[arguments[0]]
                if type(a) is float:
                    work[result] = float(_UNARY[op](a))
                else:
                    work[result] = _UNARY[op](a, out=buffers[result])
            else:
                a = work[arguments[0]]
                b = a if op == ca.OP_TWICE else work[arguments[1]]  # 2 a = a + a, exactly
                if op == ca.OP_IF_ELSE_ZERO:  # b where a is true, else 0
                    work[result] = np.where(np.not_equal(a, 0.0), b, 0.0)
                    continue
                function = _BINARY.get(op, np.add)
                if type(a) is float and type(b) is float:
                    work[result] = float(function(a, b))
                else:
                    work[result] = function(a, b, out=buffers[result])


@lru_cache(maxsize=256)
def mapped(function: ca.Function, n: int) -> ca.Function:
    """``function.map(n)``, built once per function and ``n`` (building a map costs about as
    much as evaluating it on a demonstration)."""
    return function.map(n)


@lru_cache(maxsize=256)
def accumulated(function: ca.Function, n: int) -> ca.Function:
    """``function.mapaccum(n)``, built once per function and ``n``."""
    return function.mapaccum(n)


@lru_cache(maxsize=64)
def array_function(function: ca.Function) -> ArrayFunction:
    """The :class:`ArrayFunction` of a (cached) ``function``, decoded once."""
    return ArrayFunction(function)


class NumericFunction:
    """Low-overhead repeated evaluation of a ``casadi.Function`` on numpy buffers.

    Inputs and outputs live in preallocated float64 arrays (``inputs[name]``,
    ``outputs[name]``, flattened column-major); ``evaluate()`` runs the function on them
    in about a microsecond of call overhead, which the online stepper needs.
    """

    def __init__(self, function: ca.Function):
        self.function = function
        self.inputs = {
            function.name_in(i): np.zeros(function.nnz_in(i)) for i in range(function.n_in())
        }
        self.outputs = {
            function.name_out(i): np.zeros(function.nnz_out(i)) for i in range(function.n_out())
        }
        self._buffer, self._evaluate = function.buffer()
        for i, array in enumerate(self.inputs.values()):
            self._buffer.set_arg(i, memoryview(array))
        for i, array in enumerate(self.outputs.values()):
            self._buffer.set_res(i, memoryview(array))

    def set_inputs(self, **values) -> None:
        """Copy ``values`` into the input buffers of those names."""
        for name, value in values.items():
            self.inputs[name][:] = np.ravel(value, order="F")

    def evaluate(self) -> None:
        """Evaluate on the current input buffers, writing the output buffers."""
        self._evaluate()


def linear_blocks(n_steps: int) -> tuple[int, int]:
    """Block length of :func:`linear_states` for ``n_steps`` states, about their square root,
    and the steps ``states`` must hold: that length times the number of blocks."""
    length = max(1, math.isqrt(n_steps))
    return length, length * -(-n_steps // length)


def linear_states(step, first, states: np.ndarray, length: int) -> np.ndarray:
    r"""States of :math:`x_{k+1} = A x_k + u_k` for ``m`` columns at once, in place.

    ``step`` :math:`A` (n, n); ``first`` :math:`x_0` (n, m); ``states`` (n, K, m) holds
    :math:`u_k` in ``states[:, k]`` for :math:`k < n_\mathrm{steps} - 1` and zeros after,
    with ``length`` and ``K`` from :func:`linear_blocks`; it is overwritten by :math:`x_k`
    (the first ``n_steps`` are the answer) and returned.

    The steps go in blocks of ``length``: the states within all blocks from a zero start are
    iterated together, then the blocks' starts one after the other, then :math:`A^i` times
    its start is added to the i-th state of each block. So numpy runs about :math:`3
    \sqrt{n_\mathrm{steps}}` operations on whole blocks rather than one per step (the sums
    differ from the plain recurrence's by rounding only).
    """
    n, m = first.shape
    n_blocks = states.shape[1] // length
    blocks = states.reshape(n, n_blocks, length, m)  # a view: u_k replaced by x_k
    current = np.zeros((n, n_blocks, m))
    for i in range(length):  # each block from a zero start
        following = (step @ current.reshape(n, -1)).reshape(current.shape) + blocks[:, :, i]
        blocks[:, :, i] = current
        current = following
    powers = np.empty((length, n, n))
    powers[0] = np.eye(n)
    for i in range(1, length):
        powers[i] = step @ powers[i - 1]
    block_step = step @ powers[-1]  # A^length
    starts = np.empty((n, n_blocks, m))
    starts[:, 0] = first
    for block in range(n_blocks - 1):
        starts[:, block + 1] = block_step @ starts[:, block] + current[:, block]
    for i in range(length):  # plus A^i times each block's start
        blocks[:, :, i] += (powers[i] @ starts.reshape(n, -1)).reshape(starts.shape)
    return states


def canonical_trajectory(signature, n_steps, dt, canonical0, target, gains, with_stages=True):
    """Canonical states at the samples, shape (2, n_steps), and (``with_stages``) at the four
    RK4 stages of each step, shape (4, 2, n_steps - 1), else ``None``, by
    :func:`canonical_step_function` (the stepper's arithmetic), :data:`CANONICAL_BLOCK`
    steps per call. Each row is contiguous."""
    block = CANONICAL_BLOCK
    function = NumericFunction(canonical_steps_function(signature))
    function.set_inputs(
        canonical=canonical0,
        dt=np.full(block, dt),
        canonical_target=np.full(block, target),
        gains=np.tile(np.asarray(gains, dtype=float), block),
    )
    n_blocks = -(-(n_steps - 1) // block)
    samples = np.empty((2, n_blocks * block + 1))
    stages = np.empty((4, 2, n_blocks * block)) if with_stages else None
    samples[:, 0] = canonical0
    state, following = function.inputs["canonical"], function.outputs["next_canonical"]
    following, stage_values = following.reshape(block, 2), function.outputs["stages"]
    for first in range(0, n_blocks * block, block):
        function.evaluate()
        samples[:, first + 1 : first + block + 1] = following.T
        if with_stages:
            stages[:, :, first : first + block] = stage_values.reshape(block, 4, 2).transpose(
                1, 2, 0
            )
        state[:] = following[-1]
    return samples[:, :n_steps], None if stages is None else stages[:, :, : n_steps - 1]


SIMULATION_BLOCK = 256
"""Steps per call of :func:`steps_function` (the last block of a simulation may run past its
end): one call costs a few microseconds besides the steps' own arithmetic."""


@lru_cache(maxsize=64)
def steps_function(signature: Signature) -> ca.Function:
    """:data:`SIMULATION_BLOCK` steps of :func:`step_function` in one call (``mapaccum``): the
    inputs besides ``state`` are given per step, the outputs are those of every step side by
    side."""
    return step_function(signature).mapaccum("dmp_steps", SIMULATION_BLOCK, [0], [0])


def simulate(signature: Signature, n_steps: int, initial_state, dt: float, parameters: dict):
    """Integrate ``n_steps - 1`` RK4 steps from ``initial_state`` (``parameters`` by name).

    Returns ``(states, positions, velocities, accelerations)`` with shapes
    ``(n_steps, n_states)`` and ``(n_steps, n_dofs)``; samples at ``k * dt``. The steps run
    :data:`SIMULATION_BLOCK` per call, with the arithmetic of the stepper's step.
    """
    d, block = signature.n_dofs, SIMULATION_BLOCK
    step = step_function(signature)
    steps = NumericFunction(steps_function(signature))
    for name, value in {"dt": dt, **parameters}.items():  # the same inputs at every step
        value = np.broadcast_to(np.ravel(value, order="F"), step.nnz_in(name))
        steps.set_inputs(**{name: np.tile(value, block)})
    n_blocks = -(-(n_steps - 1) // block)
    states = np.empty((n_blocks * block + 1, signature.n_states))
    plan = np.empty((3, n_blocks * block + 1, d))
    states[0] = initial_state
    first = output_function(signature)(state=initial_state, **parameters)
    names = ("position", "velocity", "acceleration")
    for i, name in enumerate(names):
        plan[i, 0] = first[name].full().ravel()
    state = steps.inputs["state"]
    state[:] = initial_state
    following = steps.outputs["next_state"].reshape(block, -1)
    outputs = [steps.outputs[name].reshape(block, d) for name in names]
    for begin in range(1, n_blocks * block + 1, block):
        steps.evaluate()
        states[begin : begin + block] = following
        for i, output in enumerate(outputs):
            plan[i, begin : begin + block] = output
        state[:] = following[-1]
    return states[:n_steps], plan[0, :n_steps], plan[1, :n_steps], plan[2, :n_steps]


def cache_dir() -> Path:
    r"""The folder of dmpopt's on-disk caches (compiled C, numba kernels), never the package's.

    ``$DMPOPT_CACHE`` if set; else ``dmpopt`` in the user's cache folder: ``$XDG_CACHE_HOME``
    (if absolute) or ``~/.cache`` on Linux, ``~/Library/Caches`` on macOS, ``%LOCALAPPDATA%``
    on Windows.
    """
    if os.environ.get("DMPOPT_CACHE"):
        return Path(os.environ["DMPOPT_CACHE"]).expanduser()
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or "~/.cache").expanduser()
        if not base.is_absolute():  # the XDG specification ignores relative paths
            base = Path.home() / ".cache"
    return base / "dmpopt"


def c_compiler() -> list[str] | None:
    """The command that compiles generated C: ``$CC`` if set, else ``cc`` or ``gcc`` on PATH.

    ``None`` if that program is not found.
    """
    command = shlex.split(os.environ.get("CC", "")) or [shutil.which("cc") or "gcc"]
    program = shutil.which(command[0])
    return None if program is None else [program, *command[1:]]


def compiled(function: ca.Function) -> ca.Function:
    """The same function generated as C and compiled with the system's C compiler.

    The shared library is cached in :func:`cache_dir` under a hash of the generated code and
    the compiler, so each system compiles once per machine (a few seconds). Without a working
    compiler (see :func:`c_compiler`) this warns once and returns ``function`` itself, which
    CasADi's virtual machine evaluates to the same numbers, a few times more slowly.
    """
    command = c_compiler()
    if command is None:
        requested = os.environ.get("CC")
        missing = f"$CC={requested!r} was not found" if requested else "no cc or gcc on PATH"
        return _uncompiled(function, f"{missing} (install gcc, or set CC to a C compiler)")
    return _compiled(function, tuple(command), cache_dir())


@lru_cache(maxsize=64)
def _compiled(function: ca.Function, command: tuple, folder: Path) -> ca.Function:
    """:func:`compiled` with ``command`` and the cache ``folder``, kept per function object,
    compiler and folder: generating the code that names the library costs ~45 ms, which a
    process pays once per step function (:func:`step_function` keeps one per signature)
    instead of once per stepper (the biped study makes one per walk)."""
    command = list(command)
    with tempfile.TemporaryDirectory() as scratch:
        generator = ca.CodeGenerator("dmp_function.c", {"with_header": False})
        generator.add(function)
        source = Path(generator.generate(scratch + os.sep))
        key = source.read_bytes() + " ".join([*command, platform.machine()]).encode()
        library = folder / f"{function.name()}_{hashlib.sha1(key).hexdigest()[:16]}.so"
        if not library.exists():
            try:
                _build(command, source, library)
            except (OSError, subprocess.CalledProcessError) as error:
                reason = f"{command[0]} could not build it in {library.parent}: {_why(error)}"
                return _uncompiled(function, reason)
    return ca.external(function.name(), str(library))


def _build(command: list[str], source: Path, library: Path) -> None:
    """Compile ``source`` into ``library``, which appears whole or not at all."""
    library.parent.mkdir(parents=True, exist_ok=True)
    partial = library.with_suffix(f".{os.getpid()}.tmp")
    try:
        subprocess.run(
            [*command, "-O1", "-fPIC", "-shared", str(source), "-o", str(partial)],
            check=True,
            capture_output=True,
            text=True,
        )
        partial.replace(library)
    finally:
        partial.unlink(missing_ok=True)


def _why(error: Exception) -> str:
    """One line on why a build failed: the compiler's first message, or the system's."""
    if isinstance(error, subprocess.CalledProcessError):
        lines = (error.stderr or "").strip().splitlines()
        return lines[0] if lines else f"exit status {error.returncode}"
    return f"{error.strerror or error}: {error.filename}" if error.filename else str(error)


def _uncompiled(function: ca.Function, reason: str) -> ca.Function:
    warnings.warn(
        f"{function.name()} is not compiled to C: {reason}; it runs on the CasADi VM instead, "
        "with identical results, a few times more slowly per call",
        RuntimeWarning,
        stacklevel=3,
    )
    return function


# ---------------------------------------------------------------------------------------
# Orientation: unit quaternions (w, x, y, z) and their logarithm
# ---------------------------------------------------------------------------------------

SMALL_ANGLE_SQUARED = 1e-6
"""Below this squared angle [rad^2] the quotients of :func:`quaternion_exp` and
:func:`quaternion_log` are evaluated by their Taylor series (truncation error below 1e-21)."""


def quaternion_product(p, q):
    r"""Hamilton product :math:`p \otimes q` of quaternions stored ``(w, x, y, z)``."""
    pw, pv, qw, qv = p[0], p[1:], q[0], q[1:]
    return ca.vertcat(pw * qw - ca.dot(pv, qv), pw * qv + qw * pv + ca.cross(pv, qv))


def quaternion_conjugate(q):
    r""":math:`\bar q`, the inverse of a unit quaternion."""
    return ca.vertcat(q[0], -q[1:])


def quaternion_exp(rotation):
    r"""The unit quaternion of the rotation vector ``rotation`` (angle times axis):
    :math:`\exp(e/2) = (\cos\frac{\theta}{2}, \sin\frac{\theta}{2}\, e / \theta)`,
    :math:`\theta = |e|`; smooth at :math:`e = 0` to every order."""
    squared = ca.dot(rotation, rotation)
    small = squared < SMALL_ANGLE_SQUARED
    angle = ca.sqrt(ca.if_else(small, 1.0, squared))  # never sqrt(0): finite derivatives
    series = 1.0 - squared / 8.0 + squared**2 / 384.0
    cosine = ca.if_else(small, series, ca.cos(angle / 2))
    series = 0.5 - squared / 48.0 + squared**2 / 3840.0
    sine_over_angle = ca.if_else(small, series, ca.sin(angle / 2) / angle)
    return ca.vertcat(cosine, sine_over_angle * rotation)


def quaternion_log(q):
    r"""The rotation vector :math:`e = 2 \log q = 2\,\mathrm{atan2}(|v|, w)\, v / |v|` of a
    unit quaternion :math:`q = (w, v)`, the inverse of :func:`quaternion_exp`.

    The angle :math:`|e|` lies in :math:`[0, 2\pi)`: ``q`` and ``-q`` (the same rotation) give
    the short and the long way round, and :math:`e` is continuous along any path of
    quaternions that avoids :math:`q = -1`.
    """
    w, v = q[0], q[1:]
    squared = ca.dot(v, v)
    small = ca.logic_and(squared < SMALL_ANGLE_SQUARED, w > 0)  # near q = 1 only
    norm = ca.sqrt(ca.if_else(small, 1.0, squared))  # q = -1 itself is refused by callers
    safe_w = ca.if_else(small, w, 1.0)
    series = (1.0 - squared / (3 * safe_w**2) + squared**2 / (5 * safe_w**4)) / safe_w
    return 2 * ca.if_else(small, series, ca.atan2(norm, w) / norm) * v


@lru_cache(maxsize=1)
def orientation_function() -> ca.Function:
    r"""The orientation of a Cartesian DMP from the state of its log-space system.

    ``(log, log_rate, log_acceleration, goal_orientation) -> (orientation, angular_velocity,
    angular_acceleration, log_jacobian)``. The orientation is :math:`q = \exp(e/2) \otimes
    g` (:func:`quaternion_exp`, unit to rounding by construction); the angular velocity, in
    the world frame (:math:`\dot q = \frac12 \omega \otimes q`), is :math:`\omega = 2\,
    \mathrm{vec}(\dot p \otimes \bar p)` with :math:`p = \exp(e/2)`, :math:`\dot p =
    \partial_e p\, \dot e`; the angular acceleration is its derivative along :math:`(\dot e,
    \ddot e)`; ``log_jacobian`` is :math:`J(e) = \partial\omega / \partial\dot e`
    (:math:`\omega = J(e)\,\dot e`, the left Jacobian of SO(3)). All by automatic
    differentiation of the exponential map.
    """
    log, rate, acceleration = (ca.SX.sym(name, 3) for name in ("log", "rate", "acceleration"))
    goal = ca.SX.sym("goal_orientation", 4)
    p = quaternion_exp(log)
    p_rate = ca.jtimes(p, log, rate)
    angular_velocity = 2 * quaternion_product(p_rate, quaternion_conjugate(p))[1:]
    both, both_rates = ca.vertcat(log, rate), ca.vertcat(rate, acceleration)
    return function(
        "dmp_orientation",
        {"log": log, "log_rate": rate, "log_acceleration": acceleration, "goal_orientation": goal},
        {
            "orientation": quaternion_product(p, goal),
            "angular_velocity": angular_velocity,
            "angular_acceleration": ca.jtimes(angular_velocity, both, both_rates),
            "log_jacobian": ca.jacobian(angular_velocity, rate),
        },
    )


@lru_cache(maxsize=1)
def orientation_log_function() -> ca.Function:
    r"""``(orientation, goal_orientation) -> log``: :math:`e = 2 \log(q \otimes \bar g)`, the
    state of the orientation part of a Cartesian DMP (:func:`quaternion_log`)."""
    q, goal = ca.SX.sym("orientation", 4), ca.SX.sym("goal_orientation", 4)
    log = quaternion_log(quaternion_product(q, quaternion_conjugate(goal)))
    return function(
        "dmp_orientation_log", {"orientation": q, "goal_orientation": goal}, {"log": log}
    )

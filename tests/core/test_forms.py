"""DMP forms as objects (dmpopt.forms): each form's constants and state, and a new form added
in one place (here, in the test) runs through rollouts and steppers unchanged."""

import casadi as ca
import numpy as np
import pytest
from problems import random_discrete, random_rhythmic

from dmpopt import DiscreteDMP, InvalidInputError, forms
from dmpopt.basis import discrete_basis


@pytest.mark.parametrize(
    "dmp",
    [
        random_discrete(form="velocity"),
        random_discrete(form="acceleration"),
        random_rhythmic(form="phase"),
        random_rhythmic(form="energy"),
    ],
    ids=lambda dmp: dmp.form,
)
def test_gains_follow_the_forms_gain_names(dmp):
    """``gains`` is the DMP's fields named by its form, in that order (the compiled functions
    read them by position)."""
    expected = {
        "velocity": (dmp.alpha_z, dmp.beta_z, getattr(dmp, "alpha_v", None)),
        "acceleration": (dmp.alpha_z, dmp.beta_z, getattr(dmp, "alpha_v", None)),
        "phase": (dmp.alpha_z, dmp.beta_z, getattr(dmp, "alpha_r", None)),
        "energy": (dmp.alpha_z, dmp.beta_z, getattr(dmp, "alpha_E", None)),
    }[dmp.form]
    assert dmp.gains[:3] == expected
    assert len(dmp.gains) == {"velocity": 4, "acceleration": 5, "phase": 3, "energy": 4}[dmp.form]
    n_transformation = 3 if dmp.form == "acceleration" else 2
    assert dmp.signature.n_states == 2 + n_transformation * dmp.n_dofs


def test_an_unknown_form_is_named_with_the_choices():
    with pytest.raises(InvalidInputError) as error:
        random_discrete(form="phase")
    assert str(error.value) == "form must be one of ('velocity', 'acceleration'), got 'phase'"
    with pytest.raises(InvalidInputError, match=r"one of \('phase', 'energy'\), got 'velocity'"):
        random_rhythmic(form="velocity")


def test_a_form_by_name_of_any_kind():
    assert forms.get("energy") is forms.FORMS["energy"]
    with pytest.raises(InvalidInputError) as error:
        forms.get("jerk")
    assert str(error.value) == (
        "form must be one of ('velocity', 'acceleration', 'phase', 'energy'), got 'jerk'"
    )


class SlowPhaseForm(forms.VelocityForm):
    """A scratch discrete form: eq. (5) driven by a first-order phase, tau x' = alpha_v (1 - x)
    (its second canonical state v follows x' so that the features keep eq. (7)'s gate)."""

    name = "scratch"

    def canonical_rhs(self, canonical, target, gains, coupling):
        rate = gains[2] * (1 - canonical[0])
        return forms.ca.vertcat(rate, -gains[2] * canonical[1] + coupling)


def test_a_new_form_is_one_class(monkeypatch):
    """Registering a form in ``forms.FORMS`` alone makes DMPs, rollouts and steppers of it:
    the unforced plan of the scratch form is eq. (5) critically damped, whose closed form is
    y(t) = g + (y0 - g)(1 + w t) exp(-w t), w = alpha_z / (2 tau); RK4 at w dt = 0.0125 is
    within 1e-9 of it (local error (w dt)^5 / 120 per step over 1000 steps). A bug that keeps
    a list of forms elsewhere (the stepper's, the DMP's check) refuses the form."""
    monkeypatch.setitem(forms.FORMS, "scratch", SlowPhaseForm())
    centres, widths = discrete_basis(5, (25.0, 6.25, 25.0, 6.25))
    dmp = DiscreteDMP(
        np.zeros((1, 5)), [0.0], [1.0], 1.0, centres, widths, form="scratch",
        goal_scaling="translation",
    )  # fmt: skip
    plan = dmp.rollout(1.0, 0.001)
    w = 25.0 / 2
    closed = 1.0 - (1.0 + w * plan.times) * np.exp(-w * plan.times)
    np.testing.assert_allclose(plan.positions[:, 0], closed, atol=1e-9)
    stepper = dmp.stepper(0.001)
    stepped = [stepper.position[0]] + [stepper.step()[0][0] for _ in range(plan.n_steps - 1)]
    np.testing.assert_allclose(stepped, plan.positions[:, 0], atol=1e-12)


def test_von_mises_features_with_unequal_widths_are_eq_12_written_out():
    """Eq. (12) with the periodic kernel psi_i = exp(h_i (cos(phi - c_i) - 1)) and widths that
    differ (with equal widths a constant added to every log-activation cancels in the
    normalisation, so only unequal ones test the kernel's constant)."""
    from dmpopt import symbolic

    centres, widths = np.array([0.0, 2.0, 4.0]), np.array([1.0, 2.5, 4.0])
    phi, r = 1.3, 0.8
    psi = np.exp(widths * (np.cos(phi - centres) - 1.0))
    expected = np.outer(psi / psi.sum(), [r * np.cos(phi), r * np.sin(phi)]).ravel()
    function = symbolic.feature_function(symbolic.Signature("phase", 1, 3, "von_mises"))
    got = function([phi, r], centres, widths).full().ravel()
    np.testing.assert_allclose(got, expected, rtol=1e-14)


@pytest.mark.parametrize("kernel", forms.KERNELS)
def test_the_phase_terms_slope_is_their_derivative_in_the_phase(kernel):
    """kernel_phase_terms_slope, written from the terms, equals CasADi's derivative of
    kernel_phase_terms in the phase (automatic differentiation: another derivation), and for
    von Mises (-sin, cos) written out, to rounding (the terms are within 1 ulp of cos and sin)."""
    phase = ca.SX.sym("phase")
    terms = forms.kernel_phase_terms(kernel, phase)
    slope = ca.Function(
        "slope", [phase], [ca.vertcat(*forms.kernel_phase_terms_slope(kernel, terms))]
    )
    derivative = ca.Function("derivative", [phase], [ca.jacobian(ca.vertcat(*terms), phase)])
    for value in np.linspace(-7.0, 7.0, 29):
        got = slope(value).full().ravel()
        np.testing.assert_allclose(got, derivative(value).full().ravel(), rtol=0, atol=4e-16)
        if kernel == "von_mises":
            np.testing.assert_allclose(got, [-np.sin(value), np.cos(value)], rtol=0, atol=4e-16)


def test_energy_form_basis_direction_is_the_unit_vector_of_its_phase():
    """The energy form gives the von Mises kernel its phase's unit vector as (x, v) / |(x, v)|:
    (cos, sin) of atan2(v, x) (eq. (14)) within a few eps (each side within 2 ulp of a value at
    most 1), on states of every quadrant and size; the log-activations through it equal those
    from the phase, h (cos(theta - c) - 1), within their rounding (12 h eps, tests/core/
    test_response.py)."""
    form = forms.FORMS["energy"]
    canonical = ca.SX.sym("canonical", 2)
    direction = ca.Function(
        "direction", [canonical], [ca.vertcat(*form.basis_direction(canonical))]
    )
    centres, widths = np.linspace(0, 2 * np.pi, 7, endpoint=False), np.full(7, 40.0)
    logs = ca.Function(
        "logs", [canonical], [form.log_activations("von_mises", canonical, centres, widths)]
    )
    rng = np.random.default_rng(0)
    for state in rng.normal(size=(200, 2)) * 10.0 ** rng.uniform(-3, 3, size=(200, 1)):
        theta = np.arctan2(state[1], state[0])
        got = direction(state).full().ravel()
        np.testing.assert_allclose(got, [np.cos(theta), np.sin(theta)], rtol=0, atol=8e-16)
        expected = widths * (np.cos(theta - centres) - 1.0)
        np.testing.assert_allclose(
            logs(state).full().ravel(), expected, rtol=0, atol=16 * 40.0 * 2.3e-16
        )

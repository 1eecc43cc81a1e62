"""Tests of dmpopt.recognition._checks: the input checks shared by the recognition modules."""

import re
import sys

import numpy as np
import pytest
from recognition_shapes import (
    _line_dmp,
    _raises,
    _shape,
)

from dmpopt import Trajectory
from dmpopt.exceptions import InvalidInputError, MissingDependency, ShapeError
from dmpopt.recognition import (
    NearestNeighbourClassifier,
    PartialObservationClassifier,
    ShrinkageLdaClassifier,
    arc_length_resampled,
    confusion_matrix,
    first_part,
    leave_one_out,
    movement_features,
    normalised_plan,
    normalised_weights,
    plan_metric_factor,
)


def test_error_not_a_dmp():
    """Only DiscreteDMPs have normalised weights."""
    with _raises(
        InvalidInputError,
        "dmp must be a DiscreteDMP, got ndarray; fit one with dmpopt.fit_discrete(demo, n_basis)",
    ):
        normalised_weights(np.zeros((2, 3)))


@pytest.mark.parametrize(
    "call, module, user",
    [
        (
            lambda: NearestNeighbourClassifier().fit(np.eye(2), [0, 1]),
            "sklearn.neighbors",
            "NearestNeighbourClassifier",
        ),
        (
            lambda: ShrinkageLdaClassifier().fit(np.eye(4), [0, 0, 1, 1]),
            "sklearn.discriminant_analysis",
            "ShrinkageLdaClassifier",
        ),
        (lambda: confusion_matrix([0, 1], [0, 0]), "sklearn.metrics", "confusion_matrix"),
        (
            # the nearest-neighbour classifier leaves one out from its own tree: another
            # classifier goes through scikit-learn's splitter
            lambda: leave_one_out(ShrinkageLdaClassifier(), np.eye(4), [0, 0, 1, 1]),
            "sklearn.model_selection",
            "leave_one_out",
        ),
    ],
)
def test_without_scikit_learn_the_error_names_the_extra(monkeypatch, call, module, user):
    """MissingDependency names the function and the extra that installs scikit-learn."""
    monkeypatch.setitem(sys.modules, module, None)
    extra = re.escape("pip install 'dmpopt[recognition]'")
    message = f"^{user} needs scikit-learn, which is not installed: {extra}$"
    with pytest.raises(MissingDependency, match=message):
        call()


BAD_INPUTS = {
    "positions 1-D": (lambda d: arc_length_resampled(np.ones(5), 10), ShapeError, "positions"),
    "positions nan": (
        lambda d: arc_length_resampled([[0, 0], [np.nan, 1]], 10),
        InvalidInputError,
        r"positions\[1, 0\] is nan",
    ),
    "resample n_samples": (
        lambda d: arc_length_resampled(np.eye(3), 2),
        InvalidInputError,
        "n_samples",
    ),
    "plan start_velocity": (
        lambda d: normalised_plan(d, [np.nan, 0.0]),
        InvalidInputError,
        r"start_velocity\[0\] is nan",
    ),
    "plan n_samples": (
        lambda d: normalised_plan(d, n_samples=10**6),
        Exception,
        "^n_samples = 1000000 exceeds the bound 100000 of this function; a few hundred suffice$",
    ),
    "factor n_samples": (
        lambda d: plan_metric_factor(d, n_samples=2),
        InvalidInputError,
        "n_samples",
    ),
    "factor dmp": (
        lambda d: plan_metric_factor("x"),
        InvalidInputError,
        "dmp must be a DiscreteDMP",
    ),
    "features start_velocities": (
        lambda d: movement_features([d], start_velocities=[[np.nan, 0.0]]),
        InvalidInputError,
        r"start_velocities\[0, 0\] is nan",
    ),
    "features n_samples": (
        lambda d: movement_features([d], n_samples=1.5),
        InvalidInputError,
        "n_samples",
    ),
    "features dmps str": (
        lambda d: movement_features("abc"),
        InvalidInputError,
        "dmps must be a sequence",
    ),
    "features dmps[1]": (
        lambda d: movement_features([d, 3]),
        InvalidInputError,
        r"dmps\[1\] must be",
    ),
    "partial n_samples": (
        lambda d: PartialObservationClassifier(n_samples=2).fit([d], [0]),
        InvalidInputError,
        "^n_samples",
    ),
    "partial plan_samples": (
        lambda d: PartialObservationClassifier(plan_samples=2).fit([d], [0]),
        InvalidInputError,
        "^plan_samples",
    ),
    "partial fractions nan": (
        lambda d: PartialObservationClassifier(fractions=[np.nan]).fit([d], [0]),
        InvalidInputError,
        r"fractions\[0\] is nan",
    ),
    "partial fractions 0": (
        lambda d: PartialObservationClassifier(fractions=[0.0, 0.5]).fit([d], [0]),
        InvalidInputError,
        "fractions must be",
    ),
    "partial fractions 2-D": (
        lambda d: PartialObservationClassifier(fractions=[[0.5]]).fit([d], [0]),
        InvalidInputError,
        "fractions must be",
    ),
    "partial labels": (
        lambda d: PartialObservationClassifier().fit([d], [0, 1]),
        ShapeError,
        r"labels has shape \(2,\), expected \(1,\)",
    ),
    "partial DOFs": (
        lambda d: PartialObservationClassifier().fit([d, _line_dmp(3)], [0, 1]),
        ShapeError,
        r"dmps\[1\] has 3 DOFs, expected 2",
    ),
    "observation DOFs": (
        lambda d: (
            PartialObservationClassifier()
            .fit([d], [0])
            .match(Trajectory.from_positions(np.arange(5.0), np.arange(5.0)[:, None]))
        ),
        ShapeError,
        "observation has 1 DOFs, expected 2",
    ),
    "partial unfitted": (
        lambda d: PartialObservationClassifier().predict([_shape(0)]),
        InvalidInputError,
        "PartialObservationClassifier is not fitted",
    ),
    "lda unfitted": (
        lambda d: ShrinkageLdaClassifier().predict(np.eye(2)),
        InvalidInputError,
        "ShrinkageLdaClassifier is not fitted",
    ),
    "lda columns": (
        lambda d: ShrinkageLdaClassifier().fit(np.eye(4), [0, 0, 1, 1]).predict(np.eye(2)),
        ShapeError,
        r"features has shape \(2, 2\), expected \(n_samples, 4\)",
    ),
    "knn bool": (
        lambda d: NearestNeighbourClassifier(True).fit(np.eye(3), [0, 1, 1]),
        InvalidInputError,
        "n_neighbours",
    ),
    "knn kneighbours columns": (
        lambda d: NearestNeighbourClassifier().fit(np.eye(3), [0, 1, 1]).kneighbours(np.eye(2)),
        ShapeError,
        r"features has shape \(2, 2\)",
    ),
    "labels nan": (
        lambda d: NearestNeighbourClassifier().fit(np.eye(3), [0, np.nan, 1]),
        InvalidInputError,
        "labels must be integers or strings",
    ),
    "loo one sample": (
        lambda d: leave_one_out(NearestNeighbourClassifier(), np.eye(1), [0]),
        InvalidInputError,
        "at least two samples",
    ),
    "loo samples str": (
        lambda d: leave_one_out(NearestNeighbourClassifier(), "abc", [0, 1, 2]),
        InvalidInputError,
        "samples must be",
    ),
    "loo queries int": (
        lambda d: leave_one_out(NearestNeighbourClassifier(), np.eye(3), [0, 1, 1], 5),
        InvalidInputError,
        "queries must be an array or a list with one entry per sample, got int",
    ),
    "first_part too short": (
        lambda d: first_part(_shape(0), 0.001),
        InvalidInputError,
        r"the first 0% of the trajectory holds 1 samples, at least 3",
    ),
}


@pytest.mark.parametrize("case", BAD_INPUTS, ids=list(BAD_INPUTS))
def test_bad_inputs_name_the_argument(case):
    """Every refused input says which argument was wrong (message checked per case)."""
    call, error, message = BAD_INPUTS[case]
    with pytest.raises(error, match=message):
        call(_line_dmp())


def test_feature_checks_at_their_edges():
    """Empty features are named; 1e150 is the largest magnitude accepted."""
    with _raises(ShapeError, "features has shape (0, 3), expected (n_samples, n_features)"):
        NearestNeighbourClassifier().fit(np.zeros((0, 3)), [])
    big = NearestNeighbourClassifier().fit([[1e150], [-1e150]], ["a", "b"])
    assert big.predict([[1e150]]).tolist() == ["a"]

"""Movement recognition from DMP weights (Section 3.8 of [dmpopt-paper]).

- :mod:`~dmpopt.recognition.features`: features of the weights, invariant to translation,
  uniform scaling and time stretching (the concepts are in its docstring);
- :mod:`~dmpopt.recognition.classifiers`: k-nearest neighbours and shrinkage LDA on the
  features, computed by scikit-learn (``pip install 'dmpopt[recognition]'``);
- :mod:`~dmpopt.recognition.evaluation`: leave-one-out predictions, confusion matrices;
- :mod:`~dmpopt.recognition.partial`: recognition from the beginning of a movement.

Only the classifiers and the evaluation need scikit-learn; without it they raise
:class:`~dmpopt.exceptions.MissingDependency` naming the extra.
"""

from .classifiers import NearestNeighbourClassifier, ShrinkageLdaClassifier
from .evaluation import confusion_matrix, leave_one_out, leave_one_out_sets
from .features import (
    METRICS,
    arc_length_resampled,
    movement_feature_sets,
    movement_features,
    normalised_plan,
    normalised_weights,
    plan_metric_factor,
)
from .partial import PartialObservationClassifier, first_part

__all__ = [
    "METRICS",
    "NearestNeighbourClassifier",
    "PartialObservationClassifier",
    "ShrinkageLdaClassifier",
    "arc_length_resampled",
    "confusion_matrix",
    "first_part",
    "leave_one_out",
    "leave_one_out_sets",
    "movement_feature_sets",
    "movement_features",
    "normalised_plan",
    "normalised_weights",
    "plan_metric_factor",
]

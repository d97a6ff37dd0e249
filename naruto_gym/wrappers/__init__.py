"""Wrappers around the envs: the final reconstruction metrics (:mod:`.metrics`), and
observations shaped for learning: their transforms on batches (:mod:`.observation`), the
single-env wrappers and :func:`for_learning` (:mod:`.learning`), and the vector-env wrapper
(:mod:`.vector`)."""

from naruto_gym.wrappers.learning import (
    EgocentricMap,
    FlatPose,
    NormalizeDepth,
    ResizeFrames,
    for_learning,
)
from naruto_gym.wrappers.metrics import FinalReconstructionMetrics
from naruto_gym.wrappers.observation import LearningObservation, ObservationTransform
from naruto_gym.wrappers.vector import VectorTransformObservation

__all__ = [
    "EgocentricMap",
    "FinalReconstructionMetrics",
    "FlatPose",
    "LearningObservation",
    "NormalizeDepth",
    "ObservationTransform",
    "ResizeFrames",
    "VectorTransformObservation",
    "for_learning",
]

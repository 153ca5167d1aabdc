"""Models used by the filters: the five networks (`networks`), their wiring into the filter
interfaces with geometry (`learned`, `physics`; what they read about a push in `context`, how
they see a sigma point in `encoding`), and analytic models (`analytic`)."""

from pushtoknow.models.analytic import (
    ConstantObservationNoise,
    LinearDynamics,
    LinearObservation,
    PoseObservation,
)
from pushtoknow.models.context import PushContext
from pushtoknow.models.encoding import EncodingConfig, ShapeActionEncoding, sigma_point_features
from pushtoknow.models.learned import (
    LearnedDynamics,
    LearnedModels,
    LearnedModelsConfig,
    LearnedObservation,
    LearnedObservationNoise,
    build_filter,
    build_learned_models,
)
from pushtoknow.models.networks import (
    EncoderConfig,
    ObsNoiseNet,
    ObsNoiseNetConfig,
    ProcessNet,
    ProcessNetConfig,
    ShapeActionEncoderNet,
    TacNet,
    TacNetConfig,
    VisNet,
    VisNetConfig,
)

__all__ = [
    "ConstantObservationNoise",
    "EncoderConfig",
    "EncodingConfig",
    "LearnedDynamics",
    "LearnedModels",
    "LearnedModelsConfig",
    "LearnedObservation",
    "LearnedObservationNoise",
    "LinearDynamics",
    "LinearObservation",
    "ObsNoiseNet",
    "ObsNoiseNetConfig",
    "PoseObservation",
    "ProcessNet",
    "ProcessNetConfig",
    "PushContext",
    "ShapeActionEncoderNet",
    "ShapeActionEncoding",
    "TacNet",
    "TacNetConfig",
    "VisNet",
    "VisNetConfig",
    "build_filter",
    "build_learned_models",
    "sigma_point_features",
]

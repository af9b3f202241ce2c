"""Simulated sensors: noise models (paper Table I) and point observations of a case."""

from dgse.sensing.noise import (
    NoiseModel,
    NoiseParams,
    NoiseRanges,
    draw_noise_params,
    gas_reading,
    wind_reading,
)
from dgse.sensing.sensors import (
    Observations,
    check_sensor_cells,
    measure,
    observation_counts,
    random_observation_count,
    random_observations,
    random_sensor_cells,
)

__all__ = [
    "NoiseModel",
    "NoiseParams",
    "NoiseRanges",
    "Observations",
    "check_sensor_cells",
    "draw_noise_params",
    "gas_reading",
    "measure",
    "observation_counts",
    "random_observation_count",
    "random_observations",
    "random_sensor_cells",
    "wind_reading",
]

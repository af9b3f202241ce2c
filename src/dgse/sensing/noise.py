"""Sensor noise models of the paper's Table I (spec section 5).

Each training sample draws its own noise parameters (:func:`draw_noise_params`)
and then corrupts the true values read at the sensor cells:

- gas: ``z ~ N(c, sigma_g^2)`` with ``sigma_g = alpha_g * c + sigma_env``,
  negatives clipped to 0 (:func:`gas_reading`);
- wind speed: ``N(|w|, (alpha_w |w|)^2)``, wind direction:
  ``N(angle(w), sigma_a^2)``, then back to ``(x, y)`` components
  (:func:`wind_reading`).

Parameter ranges (:class:`NoiseRanges`, defaults from Table I):
``alpha_g ~ U[0, 1]``, ``sigma_env ~ U[0, 0.5] * mean(c over free cells)``,
``alpha_w ~ U[0, 0.5]``, ``sigma_a ~ U[0, 15] deg``.

Every function is pure apart from the numpy ``Generator`` it is given; the
true values are never modified (readings are new arrays).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from dgse.errors import InputDataError

__all__ = [
    "NoiseModel",
    "NoiseParams",
    "NoiseRanges",
    "draw_noise_params",
    "gas_reading",
    "wind_reading",
]


@dataclass(frozen=True)
class NoiseParams:
    """The noise parameters of one sample.

    Attributes:
        alpha_g: gas noise proportional to the concentration (dimensionless).
        sigma_env: gas noise floor in ppm (absolute, already scaled by the
            environment's mean concentration).
        alpha_w: wind speed noise proportional to the speed (dimensionless).
        sigma_a_deg: wind direction noise standard deviation in degrees.
    """

    alpha_g: float
    sigma_env: float
    alpha_w: float
    sigma_a_deg: float

    def __post_init__(self) -> None:
        for name in (f.name for f in fields(self)):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise InputDataError(f"noise parameter {name} must be finite and >= 0, got {v}")
            object.__setattr__(self, name, v)

    @classmethod
    def zero(cls) -> NoiseParams:
        """No noise at all: readings equal the truth."""
        return cls(0.0, 0.0, 0.0, 0.0)

    @property
    def sigma_a_rad(self) -> float:
        return math.radians(self.sigma_a_deg)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def _check_range(name: str, r: tuple[float, float]) -> tuple[float, float]:
    lo, hi = (float(r[0]), float(r[1]))
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
        raise InputDataError(f"noise range {name} must satisfy 0 <= low <= high, got {r}")
    return lo, hi


@dataclass(frozen=True)
class NoiseRanges:
    """Uniform ranges the per-sample :class:`NoiseParams` are drawn from (Table I).

    ``sigma_env_frac`` multiplies the mean concentration over free cells to
    give ``sigma_env`` in ppm.
    """

    alpha_g: tuple[float, float] = (0.0, 1.0)
    sigma_env_frac: tuple[float, float] = (0.0, 0.5)
    alpha_w: tuple[float, float] = (0.0, 0.5)
    sigma_a_deg: tuple[float, float] = (0.0, 15.0)

    def __post_init__(self) -> None:
        for name in ("alpha_g", "sigma_env_frac", "alpha_w", "sigma_a_deg"):
            object.__setattr__(self, name, _check_range(name, getattr(self, name)))

    @classmethod
    def noiseless(cls) -> NoiseRanges:
        """All ranges ``[0, 0]``: every drawn parameter set is :meth:`NoiseParams.zero`."""
        z = (0.0, 0.0)
        return cls(z, z, z, z)


def draw_noise_params(
    rng: np.random.Generator,
    mean_free_concentration: float,
    ranges: NoiseRanges | None = None,
) -> NoiseParams:
    """Draw one sample's noise parameters.

    Args:
        rng: the random generator (consumes exactly four uniform draws, in the
            order ``alpha_g``, ``sigma_env``, ``alpha_w``, ``sigma_a``).
        mean_free_concentration: mean true concentration over the free cells
            of the environment, ppm (``c_bar`` of Table I).
        ranges: the ranges to draw from; Table I's by default.

    Returns:
        ``NoiseParams`` with ``sigma_env = U[sigma_env_frac] * mean_free_concentration``.
    """
    r = ranges or NoiseRanges()
    cbar = float(mean_free_concentration)
    if not (math.isfinite(cbar) and cbar >= 0):
        raise InputDataError(f"mean concentration must be finite and >= 0, got {cbar}")
    u = rng.uniform(size=4)

    def pick(k: int, lohi: tuple[float, float]) -> float:
        return lohi[0] + (lohi[1] - lohi[0]) * float(u[k])

    return NoiseParams(
        alpha_g=pick(0, r.alpha_g),
        sigma_env=pick(1, r.sigma_env_frac) * cbar,
        alpha_w=pick(2, r.alpha_w),
        sigma_a_deg=pick(3, r.sigma_a_deg),
    )


def gas_reading(c_true: np.ndarray, params: NoiseParams, rng: np.random.Generator) -> np.ndarray:
    """Noisy gas readings ``max(0, N(c, (alpha_g c + sigma_env)^2))``.

    Args:
        c_true: true concentrations, ppm, any shape (typically ``(n,)``), >= 0.
        params: the sample's noise parameters.
        rng: consumes ``c_true.size`` standard normal draws.

    Returns:
        float64 readings in ppm, same shape as ``c_true``, clipped at 0.
    """
    c = np.asarray(c_true, dtype=np.float64)
    sigma = params.alpha_g * c + params.sigma_env
    z = c + sigma * rng.standard_normal(c.shape)
    return np.maximum(z, 0.0)


def wind_reading(w_true: np.ndarray, params: NoiseParams, rng: np.random.Generator) -> np.ndarray:
    """Noisy wind readings: speed and direction perturbed, back to components.

    ``speed ~ N(|w|, (alpha_w |w|)^2)`` and ``angle ~ N(atan2(w_y, w_x), sigma_a^2)``;
    the reading is ``speed * (cos angle, sin angle)``.  A negative speed draw
    (possible for ``alpha_w`` near 0.5, about 2 % of draws) is clipped to 0,
    as an anemometer reports a magnitude; a zero true wind reads exactly 0.

    Args:
        w_true: true wind vectors ``(n, 2)`` as ``[u_x, u_y]`` in m/s.
        params: the sample's noise parameters.
        rng: consumes ``n`` speed draws then ``n`` direction draws
            (standard normal).

    Returns:
        float64 readings ``(n, 2)`` in m/s.
    """
    w = np.asarray(w_true, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 2:
        raise InputDataError(f"wind vectors must have shape (n, 2), got {w.shape}")
    n = w.shape[0]
    speed = np.hypot(w[:, 0], w[:, 1])
    angle = np.arctan2(w[:, 1], w[:, 0])
    s = np.maximum(speed + params.alpha_w * speed * rng.standard_normal(n), 0.0)
    a = angle + params.sigma_a_rad * rng.standard_normal(n)
    return np.stack([s * np.cos(a), s * np.sin(a)], axis=1)


@dataclass(frozen=True)
class NoiseModel:
    """Per-sample noise: the ranges to draw parameters from, and the readings.

    Example:
        >>> rng = np.random.default_rng(0)
        >>> p = NoiseModel().draw(rng, mean_free_concentration=10.0)
        >>> 0 <= p.sigma_env <= 5.0
        True
        >>> NoiseModel.noiseless().draw(rng, 10.0) == NoiseParams.zero()
        True
    """

    ranges: NoiseRanges = field(default_factory=NoiseRanges)

    @classmethod
    def noiseless(cls) -> NoiseModel:
        """A model whose readings equal the truth."""
        return cls(NoiseRanges.noiseless())

    def draw(self, rng: np.random.Generator, mean_free_concentration: float) -> NoiseParams:
        """One sample's parameters (see :func:`draw_noise_params`)."""
        return draw_noise_params(rng, mean_free_concentration, self.ranges)

    @staticmethod
    def gas(c_true: np.ndarray, params: NoiseParams, rng: np.random.Generator) -> np.ndarray:
        """See :func:`gas_reading`."""
        return gas_reading(c_true, params, rng)

    @staticmethod
    def wind(w_true: np.ndarray, params: NoiseParams, rng: np.random.Generator) -> np.ndarray:
        """See :func:`wind_reading`."""
        return wind_reading(w_true, params, rng)

"""Physical constants and model coefficients of spec section 4."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Physics:
    """Fluid, gas and turbulence-model parameters (SI units)."""

    nu: float = 1.5e-5  #: kinematic viscosity of air, m^2/s
    D_m: float = 1.2e-5  #: molecular diffusivity of ethanol in air, m^2/s
    Sc_t: float = 0.7  #: turbulent Schmidt number
    turbulence_intensity: float = 0.05  #: at the inlet
    mixing_length_factor: float = 0.07  #: inlet mixing length / inlet width
    slab_depth: float = 1.0  #: depth h of the 2-D slab, m
    molar_mass: float = 46.07  #: ethanol, g/mol
    molar_volume: float = 24.45  #: L/mol at 25 C, 1 atm
    # standard k-epsilon (Launder-Spalding) and wall-function constants
    C_mu: float = 0.09
    C_1: float = 1.44
    C_2: float = 1.92
    sigma_k: float = 1.0
    sigma_eps: float = 1.3
    kappa: float = 0.41
    E: float = 9.8

    @property
    def ppm_per_gm3(self) -> float:
        """``ppm = c[g/m^3] * ppm_per_gm3``."""
        return self.molar_volume / self.molar_mass * 1000.0

    @property
    def y_plus_lam(self) -> float:
        """Intersection of the viscous and log layers (as OpenFOAM computes it)."""
        ypl = 11.0
        for _ in range(10):
            ypl = __import__("math").log(max(self.E * ypl, 1.0)) / self.kappa
        return ypl

    def inlet_turbulence(self, inlet_velocity: float, inlet_width: float) -> tuple[float, float]:
        """Inlet ``(k, epsilon)`` from the intensity and the mixing length."""
        k = 1.5 * (self.turbulence_intensity * inlet_velocity) ** 2
        length = self.mixing_length_factor * inlet_width
        eps = self.C_mu**0.75 * k**1.5 / length
        return k, eps

    def to_dict(self) -> dict:
        return asdict(self)


DEFAULT_PHYSICS = Physics()

#: ``max_filaments`` of ``dgse plume`` and the benchmarks (:mod:`dgse.physics.filament`): a minute
#: per 100 x 100 case at most.  Here, without numba, so that the command's help can show it.
RECOMMENDED_MAX_FILAMENTS = 20_000

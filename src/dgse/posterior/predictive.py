r"""The predictive of a gas reading under a posterior mixed over flow hypotheses.

``p(z at x | readings) = sum_h p(h | .) sum_s p(s | ., h) p(z | x, s, h)``: a
:class:`~dgse.belief.predictive.ReadingMixture` with one component per flow hypothesis
``h`` and source cell ``s`` (the sources that stand for each hypothesis's posterior,
:func:`~dgse.posterior.mixture.predictive_sources`).  A component's noise-free reading at
``x`` is the forward field of ``s`` under ``h`` at the posterior's release rate
``clip(qhat(s), 0, q_max)`` (what the likelihood reads as ``q a_x(s)``; the fields are
computed once per source, for every cell at once), and its noise is the likelihood's:
``sigma = sigma_floor (1 + kappa mu / cbar)``
(:meth:`~dgse.posterior.adjoint.AdjointResponseModel.reading_sigma`), the reading clipped
at 0 as the censored likelihood reads zeros.  The rate's own spread within a cell is left
out, as in the belief's predicted concentration; so is DGSE-S's share of ``dgse-phys``'s
source posterior (``fusion``), which predicts no reading of a source.  The components and
the noise are those of the first noise-weight mode (what the predicted fields use).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from dgse.belief.predictive import ReadingMixture
from dgse.errors import InputDataError
from dgse.posterior.adjoint import AdjointResponseModel, FlowModel

__all__ = ["HypothesisPredictive", "SourceComponents"]


@dataclass(frozen=True, eq=False)
class SourceComponents:
    """One flow hypothesis's part of the predictive.

    Attributes:
        flow: the hypothesis's flow (its forward fields).
        sources: ``(k,)`` mesh indices of the source cells that stand for its posterior.
        weights: ``(k,)`` their weights in the whole mixture (the hypothesis's weight times
            each source's share).
        rates: ``(k,)`` their release rates, g/s.
        fields: ``(k, n_free)`` their concentration fields at those rates, ppm (mesh order).
    """

    flow: FlowModel
    sources: np.ndarray
    weights: np.ndarray
    rates: np.ndarray
    fields: np.ndarray


@dataclass(frozen=True, eq=False)
class HypothesisPredictive:
    """The predictive of a gas reading under a mixture over flow hypotheses (module docstring).

    Attributes:
        parts: one :class:`SourceComponents` per hypothesis in the predictive.
        noise: the likelihood's noise model (its ``reading_sigma``).
    """

    parts: Sequence[SourceComponents]
    noise: AdjointResponseModel
    _weights: np.ndarray = field(init=False, repr=False)
    _sources: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.parts:
            raise InputDataError("a hypothesis predictive needs at least one hypothesis")
        w = np.concatenate([np.asarray(p.weights, dtype=np.float64) for p in self.parts])
        if not (w >= 0).all() or not w.sum() > 0:
            raise InputDataError("the predictive's weights must be >= 0 with some mass")
        mesh = self.parts[0].flow.mesh
        flat = mesh.cells[np.concatenate([p.sources for p in self.parts])]
        object.__setattr__(self, "_weights", w / w.sum())
        object.__setattr__(self, "_sources", flat[:, 0] * mesh.shape[1] + flat[:, 1])

    @classmethod
    def from_posteriors(
        cls,
        flows: Sequence[FlowModel],
        hypothesis_weights: Sequence[float],
        sources: Sequence[np.ndarray],
        source_weights: Sequence[np.ndarray],
        rates: Sequence[np.ndarray],
        noise: AdjointResponseModel,
        fields: Sequence[np.ndarray] | None = None,
    ) -> HypothesisPredictive:
        """From each hypothesis's flow, weight, representative sources (mesh indices), their
        shares of its posterior and release rates; ``fields``: their forward fields at those
        rates where the caller has them already (else solved here, cached by the flows)."""
        parts = []
        for k, (fm, hw, src, sw, q) in enumerate(
            zip(flows, hypothesis_weights, sources, source_weights, rates, strict=True)
        ):
            src = np.asarray(src, dtype=np.int64)
            q = np.asarray(q, dtype=np.float64)
            f = fm.forward(fm.mesh.cells[src], q) if fields is None else np.asarray(fields[k])
            parts.append(SourceComponents(fm, src, float(hw) * np.asarray(sw, dtype=np.float64), q, f))
        return cls(parts, noise)

    @property
    def weights(self) -> np.ndarray:
        """``(K,)`` every component's weight (hypotheses in order, then their sources)."""
        return self._weights

    @property
    def sources(self) -> np.ndarray:
        """``(K,)`` every component's source cell as a flat map index (row-major)."""
        return self._sources

    def at(self, cells: np.ndarray) -> ReadingMixture:
        """The predictive at ``cells`` (``(C, 2)`` free cells ``(i, j)``)."""
        c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        mesh = self.parts[0].flow.mesh
        idx = mesh.index[c[:, 0], c[:, 1]]
        if (idx < 0).any():
            raise InputDataError("a reading's predictive is asked for at a wall cell")
        mean = np.concatenate([p.fields[:, idx] for p in self.parts], axis=0).T  # (C, K)
        mean = np.maximum(mean, 0.0)
        return ReadingMixture(self._weights, mean, self.noise.reading_sigma(mean), self._sources)

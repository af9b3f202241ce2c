"""The physics posterior over the source: what ``dgse-phys`` and the adjoint baselines share.

* :mod:`~dgse.posterior.adjoint`: flows with their factorized transport operator
  (:class:`~dgse.posterior.adjoint.FlowModel`, cached per layout and inlet speed) and the
  adjoint evidence ``log p(readings | source, flow)`` with the release rate and the
  Table I noise marginalized, the zero readings' censored factor included;
* :mod:`~dgse.posterior.mixture`: flow hypotheses, their wind likelihood and the mixture
  of their posteriors;
* :mod:`~dgse.posterior.predictive`: the predictive of a gas reading under that mixture
  (one component per hypothesis and source, the likelihood's noise and clipping);
* :mod:`~dgse.posterior.evidence_kernel`, :mod:`~dgse.posterior.censored_kernel`: the
  compiled loops of the evidence and of the censored factor;
* :mod:`~dgse.posterior.student_t`: Student-t interval masses of the release rate.

Everything here takes and returns arrays; nothing reads files or knows about searches.
"""

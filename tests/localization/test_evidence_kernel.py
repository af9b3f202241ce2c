"""The compiled sums of the evidence with each candidate's own noise weights, against NumPy."""

import numpy as np
import pytest

from dgse.localization.adjoint import _evidence, _weighted_sums, adjoint_log_evidence
from dgse.localization.evidence_kernel import candidate_sums


@pytest.mark.parametrize("c", [0.0, 0.3, 40.0, 1e60])
def test_candidate_sums_equal_the_numpy_sums(c):
    rng = np.random.default_rng(3)
    m, n = 23, 57
    A = rng.random((m, n)) ** 3
    A[:, 5] = 0.0  # a candidate no reading sees
    own = A * rng.random(n) * 5.0
    z = rng.random(m) * 10.0
    r = 1.0 + c * own
    aa, az, zz = _weighted_sums(A, A * A, z, r)
    log_r = np.log(r).sum(axis=0)
    got = candidate_sums(A, own, z, c)
    # c = 1e60 makes weights near 1e60: the running products must be flushed, not overflow
    for want, have in zip((aa, az, zz, log_r), got, strict=True):
        np.testing.assert_allclose(have, want, rtol=1e-12, atol=1e-12)
    assert got[0][5] == 1e-300


@pytest.mark.parametrize("mode", ["candidate", "larger"])
def test_evidence_with_own_weights_matches_the_weights_it_reports(mode):
    """The compiled path gives the evidence of the noise weights it reports (kappa = best)."""
    rng = np.random.default_rng(4)
    m, n = 15, 40
    A = rng.random((m, n)) ** 2
    z = np.maximum(A[:, 7] * 2.0 + rng.normal(0.0, 0.05, m), 0.0)
    z[:3] = 0.0
    logl, det = adjoint_log_evidence(A, z, kappas=(2.0,), noise_weights=mode, censored=False)
    # kappas = (2,) alone: the homoscedastic pass only gives the plug-in concentrations
    r = det["r"]
    want = _evidence(A, A * A, z, r, 5.0, 1.0, det["s0"] ** 2)[0]
    np.testing.assert_allclose(logl, want, rtol=1e-10, atol=1e-9)
    assert int(np.argmax(logl)) == 7


def test_sums_of_several_kappas_in_one_pass_are_each_kappas_to_the_bit():
    from dgse.localization.evidence_kernel import candidate_sums_many

    rng = np.random.default_rng(5)
    A = rng.random((31, 44)) ** 3
    own = A * rng.random(44) * 5.0
    z = rng.random(31) * 10.0
    cs = np.array([0.3, 40.0, 1e60, 0.0])
    many = candidate_sums_many(A, own, z, cs)
    for j, c in enumerate(cs):
        for all_rows, one in zip(many, candidate_sums(A, own, z, c), strict=True):
            np.testing.assert_array_equal(all_rows[j], one)


def test_plug_in_evidence_averages_each_kappas_evidence():
    """With the plug-in weights, the sums of every kappa come from one matrix product each; the
    evidence is still the mean over kappas of each one's own evidence."""
    rng = np.random.default_rng(6)
    m, n = 18, 50
    A = rng.random((m, n)) ** 2
    z = np.maximum(A[:, 11] * 3.0 + rng.normal(0.0, 0.1, m), 0.0) + 0.01
    kappas = (0.0, 0.5, 8.0)
    logl, det = adjoint_log_evidence(A, z, kappas=kappas, noise_weights="plug-in", censored=False)
    beta0 = det["s0"] ** 2
    each = [_evidence(A, A * A, z, 1.0 + k * det["chat"] / det["cbar"], 5.0, 1.0, beta0)[0] for k in kappas]
    top = np.max(each, axis=0)
    want = top + np.log(np.mean(np.exp(np.array(each) - top), axis=0))
    np.testing.assert_allclose(logl, want, rtol=1e-10, atol=1e-9)

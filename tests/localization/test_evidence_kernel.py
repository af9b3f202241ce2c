"""The compiled sums of the positive readings' evidence, against NumPy."""

import numpy as np
import pytest

from dgse.posterior.adjoint import (
    _evidence_from_sums,
    _weighted_sums,
    adjoint_log_evidence,
    censored_correction,
)
from dgse.posterior.evidence_kernel import candidate_sums_many, own_weights, row_sums


def _numpy_evidence(A, z, r, q_max, alpha0, beta0):
    """The evidence of every column of ``A`` with the noise weights ``r``, from NumPy sums."""
    sums = (*_weighted_sums(A, A * A, z, r), np.log(r).sum(axis=0))
    return _evidence_from_sums(sums, z.size, q_max, alpha0, beta0)[0]


@pytest.mark.parametrize("c", [0.0, 0.3, 40.0, 1e60])
@pytest.mark.parametrize("larger", [False, True])
def test_candidate_sums_equal_the_numpy_sums(c, larger):
    rng = np.random.default_rng(3)
    m, n = 23, 57
    A = rng.random((m, n)) ** 3
    A[:, 5] = 0.0  # a candidate no reading sees
    q = rng.random(n) * 5.0
    z = rng.random(m) * 10.0
    floor = rng.random(m) * 0.5 if larger else np.zeros(m)
    rows = np.flatnonzero(rng.random(m) < 0.7)  # some readings left out (the zeros)
    r = 1.0 + c * np.maximum(A * q, floor[:, None])
    aa, az, zz = _weighted_sums(A[rows], A[rows] ** 2, z[rows], r[rows])
    log_r = np.log(r[rows]).sum(axis=0)
    got = [x[0] for x in candidate_sums_many(A, rows, q, floor, z, np.array([c]))]
    # c = 1e60 makes weights near 1e60: the running products must be flushed, not overflow
    for want, have in zip((aa, az, zz, log_r), got, strict=True):
        np.testing.assert_allclose(have, want, rtol=1e-12, atol=1e-12)
    assert got[0][5] == 1e-300


def test_row_sums_equal_the_numpy_sums():
    rng = np.random.default_rng(7)
    m, n = 19, 33
    A = rng.random((m, n)) ** 2
    A[:, 2] = 0.0
    z = rng.random(m) * 4.0
    W = rng.random((3, m)) + 0.1
    rows = np.array([0, 3, 4, 9, 18])
    aa, az = row_sums(A, rows, z, W)
    for j in range(3):
        want = _weighted_sums(A[rows], A[rows] ** 2, z[rows], W[j, rows] ** -0.5)
        np.testing.assert_allclose(aa[j], want[0], rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(az[j], want[1], rtol=1e-12)
    assert aa[0][2] == 1e-300
    empty = row_sums(A, np.zeros(0, dtype=np.int64), z, W)
    assert (empty[0] == 1e-300).all() and (empty[1] == 0.0).all()


def test_evidence_with_own_weights_matches_the_weights_it_reports():
    """The compiled path gives the evidence of the noise weights it reports (kappa = best)."""
    rng = np.random.default_rng(4)
    m, n = 15, 40
    A = rng.random((m, n)) ** 2
    z = np.maximum(A[:, 7] * 2.0 + rng.normal(0.0, 0.05, m), 0.0)
    z[:3] = 0.0
    logl, det = adjoint_log_evidence(A, z, kappas=(2.0,), noise_weights="candidate", censored=False)
    # kappas = (2,) alone: the homoscedastic pass only gives the plug-in concentrations
    want = _numpy_evidence(A, z, det["r"], 5.0, 1.0, det["s0"] ** 2)
    np.testing.assert_allclose(logl, want, rtol=1e-10, atol=1e-9)
    assert int(np.argmax(logl)) == 7


def test_sums_of_several_kappas_in_one_pass_are_each_kappas_to_the_bit():
    rng = np.random.default_rng(5)
    A = rng.random((31, 44)) ** 3
    q = rng.random(44) * 5.0
    floor = rng.random(31)
    z = rng.random(31) * 10.0
    rows = np.arange(1, 31, 2)
    cs = np.array([0.3, 40.0, 1e60, 0.0])
    many = candidate_sums_many(A, rows, q, floor, z, cs)
    for j in range(cs.size):
        for all_rows, one in zip(many, candidate_sums_many(A, rows, q, floor, z, cs[j : j + 1]), strict=True):
            np.testing.assert_array_equal(all_rows[j], one[0])


def test_plug_in_evidence_averages_each_kappas_evidence():
    """With the plug-in weights, the sums of every kappa come from one pass; the evidence is
    still the mean over kappas of each one's own evidence."""
    rng = np.random.default_rng(6)
    m, n = 18, 50
    A = rng.random((m, n)) ** 2
    z = np.maximum(A[:, 11] * 3.0 + rng.normal(0.0, 0.1, m), 0.0) + 0.01
    kappas = (0.0, 0.5, 8.0)
    logl, det = adjoint_log_evidence(A, z, kappas=kappas, noise_weights="plug-in", censored=False)
    beta0 = det["s0"] ** 2
    each = [_numpy_evidence(A, z, 1.0 + k * det["chat"] / det["cbar"], 5.0, 1.0, beta0) for k in kappas]
    top = np.max(each, axis=0)
    want = top + np.log(np.mean(np.exp(np.array(each) - top), axis=0))
    np.testing.assert_allclose(logl, want, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("mode", ["plug-in", "candidate"])
def test_deferred_zeros_get_the_sums_of_the_weights_they_report(mode):
    """The zeros' factor reuses the evidence's sums: they are those of the weights it reports."""
    rng = np.random.default_rng(8)
    m, n = 25, 60
    A = rng.random((m, n)) ** 2
    z = np.maximum(A[:, 20] * 2.0 + rng.normal(0.0, 0.3, m), 0.0)
    z[[1, 4, 9]] = 0.0
    _logl, det = adjoint_log_evidence(A, z, noise_weights=mode, censored="deferred")
    censor = det["censor"]
    pos = z > 0
    want = _weighted_sums(A[pos], A[pos] ** 2, z[pos], det["r"][pos])
    for have, w in zip(censor["sums"], want, strict=True):
        np.testing.assert_allclose(have, w, rtol=1e-12)
    # the zeros' factor gets the zeros' rows of the weights (every reading's is an (m, N) array
    # in the modes with each candidate's own, built only when read)
    np.testing.assert_array_equal(censor["r"], det["r"][~pos])
    full = dict(censor, r=det["r"])
    np.testing.assert_array_equal(
        censored_correction(logl=_logl, **censor), censored_correction(logl=_logl, **full)
    )


def test_own_weights_are_the_numpy_weights():
    rng = np.random.default_rng(9)
    A = rng.random((7, 12))
    q = rng.random(12) * 3.0
    floor = rng.random(7)
    want = 1.0 + 0.7 * np.maximum(A * q, floor[:, None])
    np.testing.assert_array_equal(own_weights(A, q, floor, 0.7), want)


def test_details_compute_a_lazy_entry_once_on_first_read():
    from dgse.posterior.adjoint import Details

    calls = []
    d = Details(a=1)
    d.lazy("r", lambda: calls.append(1) or np.arange(3))
    assert "r" in d and d.get("missing") is None and not calls
    np.testing.assert_array_equal(d["r"], np.arange(3))
    np.testing.assert_array_equal(d.get("r"), np.arange(3))
    assert calls == [1]
    with pytest.raises(KeyError):
        d["missing"]

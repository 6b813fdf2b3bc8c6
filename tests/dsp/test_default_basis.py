"""The shipped default basis is exactly what fitting shared/datasets/hatt-psd gives."""

from __future__ import annotations

import numpy as np
import pytest

from vibsynth.research.basis_fit import HATT_CITATION, fit_default_basis


@pytest.mark.shared
def test_refit_reproduces_the_shipped_basis(basis, hatt_psd):
    refit = fit_default_basis(hatt_psd)
    assert refit.id == basis.id
    assert np.allclose(refit.components, basis.components, atol=1e-7)
    assert np.allclose(refit.mean_db, basis.mean_db, atol=1e-7)
    assert refit.n_spectra == 1425


def test_shipped_basis_carries_provenance_and_citation(basis):
    assert basis.provenance["citation"] == HATT_CITATION
    assert "hatt-psd" in basis.provenance["source"]
    assert basis.n_spectra == 1425

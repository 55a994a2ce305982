import numpy as np
import pytest

from ident.library import PolynomialForcingLibrary


def test_names_follow_the_paper():
    lib = PolynomialForcingLibrary(2, 3)
    assert lib.names == ["1", "x1", "x2", "x1^2", "x1 x2", "x2^2", "x1^3", "x1^2 x2", "x1 x2^2",
                         "x2^3", "F"]


def test_columns_match_pysindy_polynomial_library_and_forcing_is_one_column():
    """Independent computation: pysindy's PolynomialLibrary gives the same monomials."""
    import pysindy as ps

    rng = np.random.default_rng(0)
    x = rng.standard_normal((50, 3))
    f = rng.standard_normal(50)
    ours = PolynomialForcingLibrary(3, 3)
    theta = ours.transform(x, f)
    ref = ps.PolynomialLibrary(degree=3).fit(x)
    ref_theta = ref.transform(x)
    ref_names = ref.get_feature_names(["x1", "x2", "x3"])
    assert theta.shape == (50, len(ref_names) + 1)
    for k, name in enumerate(ref_names):
        # pysindy writes "x1^2 x2"; ours uses the same spelling
        j = ours.names.index(name)
        np.testing.assert_allclose(theta[:, j], np.asarray(ref_theta)[:, k], rtol=1e-12)
    np.testing.assert_array_equal(theta[:, -1], f)  # F appended once, not multiplied in


def test_batch_shapes_and_errors():
    lib = PolynomialForcingLibrary(2, 2)
    x = np.ones((4, 5, 2))
    assert lib.transform(x, np.ones((4, 5))).shape == (4, 5, lib.n_terms)
    with pytest.raises(ValueError, match="forcing"):
        lib.transform(np.ones((3, 2)))
    with pytest.raises(ValueError, match="states"):
        lib.transform(np.ones((3, 3)), np.ones(3))
    with pytest.raises(ValueError, match="degree"):
        PolynomialForcingLibrary(2, 9)

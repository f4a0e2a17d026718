"""The shared test helpers of tests/_checks.py can fail: the dot test rejects a wrong
adjoint, accepts a right one, real and complex."""

import numpy as np
import pytest

from _checks import dottest


@pytest.mark.parametrize("complex_input", [False, True])
def test_dottest_accepts_the_adjoint_and_rejects_others(complex_input):
    rng = np.random.default_rng(0)
    A = rng.standard_normal((7, 5)) + (1j * rng.standard_normal((7, 5)) if complex_input else 0)
    AH = A.conj().T
    assert dottest(lambda x: A @ x, lambda y: AH @ y, (5,), (7,), rng=rng, complex_input=complex_input)
    # the transpose without conjugation is not the adjoint of a complex matrix
    wrong = [lambda y: 1.01 * (AH @ y), lambda y: A[:5, :5].conj().T @ y[:5]]
    if complex_input:
        wrong.append(lambda y: A.T @ y)
    for adj in wrong:
        assert not dottest(lambda x: A @ x, adj, (5,), (7,), rng=rng, complex_input=complex_input,
                           raise_error=False)
        with pytest.raises(AssertionError, match="dottest failed"):
            dottest(lambda x: A @ x, adj, (5,), (7,), rng=rng, complex_input=complex_input)


def test_dottest_checks_shapes():
    A = np.ones((3, 2))
    with pytest.raises(AssertionError, match="expected"):
        dottest(lambda x: A @ x, lambda y: A @ y[:2], (2,), (3,))

"""Validation helpers: clear messages eagerly, runtime errors under jit, x64 requirement."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag._validate import JaxcoagInputError, check, require_x64


def test_eager_messages_say_what_to_change():
    with pytest.raises(JaxcoagInputError, match=r"`alpha` must be finite and >= 0; use 1e-4"):
        check(-1.0, "alpha", nonnegative=True, hint="use 1e-4")
    with pytest.raises(JaxcoagInputError, match="2 of 3 entries"):
        check(np.array([1.0, np.nan, -2.0]), "T", positive=True)
    np.testing.assert_array_equal(check(np.array([1.0, 2.0]), "x", positive=True), [1.0, 2.0])


def test_traced_check_raises_at_runtime():
    f = jax.jit(lambda x: check(x, "rho_g", positive=True) * 2)
    assert float(f(2.0)) == 4.0
    # the equinox runtime check surfaces through XLA's host callback: a JaxRuntimeError on a first
    # dispatch, a ValueError ("INTERNAL: CpuCallback error") from an already-compiled executable
    with pytest.raises((jax.errors.JaxRuntimeError, ValueError), match="rho_g") as err:
        jax.block_until_ready(f(-1.0))
    assert "EquinoxRuntimeError" in str(err.value)  # the runtime check, not an eager one


def test_require_x64_passes_in_tests():
    require_x64("test")  # conftest enables x64
    assert jnp.asarray(1.0).dtype == jnp.float64


def test_python_constants_inside_jit_stay_concrete():
    # ints and floats written inside a jitted function are checked eagerly (no tracer conversion error)
    f = jax.jit(lambda x: check(3, "n", positive=True) * check(2.0, "y", positive=True) * x)
    assert float(f(1.0)) == 6.0
    with pytest.raises(JaxcoagInputError, match="`n`"):
        jax.jit(lambda x: check(-3, "n", positive=True) * x)(1.0)

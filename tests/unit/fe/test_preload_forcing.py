"""The preload's inexact Newton steps (fem_squeal.fe.preload.forcing): how exactly each GMRES step is
solved on the kept factorisation."""
import pytest

from fem_squeal.fe.kept_factorisation import KRYLOV_RTOL
from fem_squeal.fe.preload import FORCING_FINAL, FORCING_MAX, forcing, reached


def test_steps_are_loose_while_the_closed_set_moves_and_exact_once_it_stays():
    """Eisenstat–Walker's choice 2 while the closed set changes: FORCING_MAX for the first step, then the
    last reduction squared (capped), never finer than a tenth of the tolerance needs nor than the exact
    steps' 1e-11; a settled closed set gets the exact step (the values of the 348k brake's history)."""
    tol = 1e-9
    assert forcing([1.0], tol, settled=False) == FORCING_MAX
    assert forcing([1.0, 0.9], tol, settled=False) == FORCING_MAX                     # 0.81 capped
    assert forcing([1.0, 0.206], tol, settled=False) == pytest.approx(0.206 ** 2)
    assert forcing([2.18e-2, 1.05e-3], tol, settled=False) == pytest.approx((1.05e-3 / 2.18e-2) ** 2)
    assert forcing([1.05e-3, 1.01e-5], tol, settled=False) == pytest.approx((1.01e-5 / 1.05e-3) ** 2)
    assert forcing([1e-6, 1e-9], tol, settled=False) == pytest.approx(0.1)         # a tenth of tol/‖R‖
    assert forcing([1.05e-3, 1.01e-5], tol, settled=True) == KRYLOV_RTOL
    assert forcing([1.0, 1e-30], 1e-40, settled=False) == KRYLOV_RTOL               # never below 1e-11


def test_a_state_an_inexact_step_reached_converges_only_well_below_the_tolerance():
    """After an exact step ‖R‖/‖f‖ ≤ tol ends the preload; after an inexact one only FORCING_FINAL × tol
    does (else one more step, exact: the 348k brake stopped at 5e-10 after an inexact step, 4.4e-10 from
    the exact steps' displacement, against the issue's 1e-10)."""
    tol = 1e-9
    assert reached(5e-10, tol, KRYLOV_RTOL) and reached(tol, tol, KRYLOV_RTOL)
    assert not reached(5e-10, tol, 9e-5) and not reached(2 * FORCING_FINAL * tol, tol, 1e-2)
    assert reached(FORCING_FINAL * tol, tol, 9e-5) and reached(7e-12, tol, 1e-2)

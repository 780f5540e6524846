"""The preload's inexact Newton steps (fem_squeal.fe.preload.forcing): how exactly each GMRES step is
solved on the kept factorisation."""
import pytest

from fem_squeal.fe.kept_factorisation import KRYLOV_RTOL
from fem_squeal.fe.preload import FORCING_MAX, forcing


def test_steps_are_loose_while_the_closed_set_moves_and_exact_once_it_stays():
    """Eisenstat–Walker's choice 2 while the closed set changes: FORCING_MAX for the first step, then the
    last reduction squared (capped), never finer than a tenth of the tolerance needs nor than the exact
    steps' 1e-11; a settled closed set gets the exact step (the values of the 348k brake's history)."""
    tol = 1e-9
    assert forcing([1.0], tol, settled=False) == FORCING_MAX
    assert forcing([1.0, 0.206], tol, settled=False) == FORCING_MAX                  # 0.042 > 1e-2
    assert forcing([0.117, 2.18e-2], tol, settled=False) == FORCING_MAX               # 0.035 capped
    assert forcing([2.18e-2, 1.05e-3], tol, settled=False) == pytest.approx((1.05e-3 / 2.18e-2) ** 2)
    assert forcing([1.05e-3, 1.01e-5], tol, settled=False) == pytest.approx((1.01e-5 / 1.05e-3) ** 2)
    assert forcing([1e-6, 1e-9], tol, settled=False) == pytest.approx(0.1)         # a tenth of tol/‖R‖
    assert forcing([1.05e-3, 1.01e-5], tol, settled=True) == KRYLOV_RTOL
    assert forcing([1.0, 1e-30], 1e-40, settled=False) == KRYLOV_RTOL               # never below 1e-11

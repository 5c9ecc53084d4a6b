"""The paper's own numbers (Table II) from its formulas: eqs. (10)-(11) and (13)-(14)."""

import pytest

from pmdcid.identify.electrical import paper_electrical
from pmdcid.identify.mechanical import paper_mechanical


def test_electrical_table_ii():
    # Ke = 0.421762 A/V, tau_e = 0.0075 s -> R = 2.3724 ohm, L = 17.7933 mH. 1/Ke is 2.37101:
    # the paper's R is rounded/derived differently by 0.06 %, so R is checked to 0.1 %, and L
    # = tau_e*R exactly with the paper's R.
    r, L = paper_electrical(0.421762, 0.0075)
    assert r == pytest.approx(2.3724, rel=1e-3)
    assert L == pytest.approx(17.7933e-3, rel=1e-3)
    assert 0.0075 * 2.3724 == pytest.approx(17.7933e-3, rel=1e-4)


def test_mechanical_table_ii():
    # Kmot = 0.545287, tau_mot = 0.08 s, km = 50.2e-3 N m/A, R = 2.3724 ohm
    b, J = paper_mechanical(0.545287, 0.08, 50.2e-3, 2.3724)
    assert b == pytest.approx(0.0388, rel=1e-3)
    assert J == pytest.approx(3.10442e-3, rel=1e-4)

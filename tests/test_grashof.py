"""One Grashof classification (vloop.method.equations.grashof_class) for the loop text, studies and synthesis,
checked against the inequality worked by hand."""

from __future__ import annotations

import numpy as np

from vloop.method.equations import grashof_class

# (ground, input side, coupler, output side): s + l against p + q by hand, and the shortest link's place
CASES = [
    ((4.0, 1.0, 3.0, 3.5), "Grashof crank-rocker", True),  # 1 + 4 = 5 < 6.5, input shortest
    ((1.0, 4.0, 3.0, 3.5), "Grashof double-crank", True),  # ground shortest
    ((4.0, 3.0, 1.0, 3.5), "Grashof double-rocker", True),  # coupler shortest
    ((4.0, 3.5, 3.0, 1.0), "Grashof rocker-crank", True),  # output shortest
    ((4.0, 2.0, 3.0, 3.0), "special Grashof (change point)", True),  # 2 + 4 = 6 = 3 + 3
    ((4.0, 2.5, 1.0, 2.0), "non-Grashof triple-rocker", False),  # 1 + 4 = 5 > 4.5
]


def test_each_class_as_worked_by_hand():
    for lengths, name, grashof in CASES:
        cls, is_g = grashof_class(np.array(lengths))
        assert (str(cls), bool(is_g)) == (name, grashof), lengths


def test_many_four_bars_at_once_keep_their_shape():
    lengths = np.array([c[0] for c in CASES]).reshape(2, 3, 4)
    cls, is_g = grashof_class(lengths)
    assert cls.shape == is_g.shape == (2, 3)
    assert [str(c) for c in cls.ravel()] == [c[1] for c in CASES]

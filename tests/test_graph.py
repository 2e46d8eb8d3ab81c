"""The cycle basis: J − L + 1 independent loops, as short as networkx's exact minimum cycle basis on every
catalog mechanism (and identical to it there), and near-linear in the size of the mechanism."""

from __future__ import annotations

import networkx as nx
import pytest

import vloop
from tests.conftest import MECHANISMS
from vloop.method import graph


def edges(cycle: list) -> frozenset:
    return frozenset(frozenset(e) for e in zip(cycle, cycle[1:] + cycle[:1], strict=True))


@pytest.mark.parametrize("path", sorted(MECHANISMS.glob("*.toml")), ids=lambda p: p.stem)
def test_cycle_basis_is_the_minimum_one(path):
    mech = vloop.load(path)
    G = graph.build_graph(mech, mech.bodies()).G
    ours = graph.cycle_basis(G)
    L, J, _ = mech.gruebler()
    assert len(ours) == J - L + 1
    exact = [graph._walk_cycle(G, c) for c in nx.minimum_cycle_basis(G)]
    assert {edges(c) for c in ours} == {edges(c) for c in exact}
    for c in ours:  # every loop is a closed walk along graph edges
        assert all(G.has_edge(u, v) for u, v in zip(c, c[1:] + c[:1], strict=True))

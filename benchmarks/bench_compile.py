"""Compile time against mechanism size: a chain of N RRR dyads (2N + 1 moving links, N loops).

    python benchmarks/bench_compile.py [N ...]

Prints, for each N, the links, loops, compile time and the time per link, and the growth exponent
between successive sizes (1 = linear). The chain: a crank O–A; dyad i joins the previous dyad's
middle pin P(i−1) (A for i = 1) to a new ground pivot G(i) through a new pin P(i).
"""

from __future__ import annotations

import math
import sys
import time

import vloop


def dyad_chain(n: int) -> vloop.Mechanism:
    """A crank and ``n`` RRR dyads in a chain, assembled at t = 0 (every loop closes by construction)."""
    joints = {"O": [0.0, 0.0], "A": [0.0, 1.0]}
    links = {"ground": {"joints": ["O"], "ground": True}, "crank": {"joints": ["O", "A"]}}
    prev = "A"
    for i in range(1, n + 1):
        px, py = joints[prev]
        P = [px + 2.0, py + 0.3 * math.sin(i)]  # the new middle pin
        G = [P[0] + 0.5, P[1] - 2.0]  # its ground pivot, 2.06 below
        joints[f"P{i}"], joints[f"G{i}"] = P, G
        links["ground"]["joints"].append(f"G{i}")
        links[f"c{i}"] = {"joints": [prev, f"P{i}"]}
        links[f"r{i}"] = {"joints": [f"G{i}", f"P{i}"]}
        prev = f"P{i}"
    return vloop.from_dict(
        {
            "name": f"chain{n}",
            "joints": joints,
            "links": links,
            "drivers": [{"link": "crank", "omega": 0.1}],
            "time": {"start": 0.0, "stop": 0.1, "step": 0.05},
        }
    )


def main(sizes: list[int]) -> None:
    print(
        f"{'dyads':>6} {'links':>6} {'loops':>6} {'load [s]':>9} {'compile [s]':>12}"
        f" {'per link [ms]':>14} {'growth':>7}"
    )
    prev = None
    for n in sizes:
        t0 = time.perf_counter()
        mech = dyad_chain(n)
        t1 = time.perf_counter()
        system = vloop.compile(mech)
        t2 = time.perf_counter()
        vloop.solve(system)
        links = len(mech.links) - 1
        growth = ""
        if prev is not None:
            growth = f"{math.log((t2 - t1) / prev[1]) / math.log(links / prev[0]):7.2f}"
        print(
            f"{n:6d} {links:6d} {len(system.loops):6d} {t1 - t0:9.3f} {t2 - t1:12.3f}"
            f" {1e3 * (t2 - t1) / links:14.2f} {growth}"
        )
        prev = (links, t2 - t1)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [5, 10, 20, 40, 80, 160, 200])

"""NSGA-II's parts against their definitions (domination by brute force, crowding on a
known front), and the whole on ZDT1, whose front is known (f2 = 1 - sqrt(f1))."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.stats import qmc

from closedloop.analysis.nsga2 import (
    crowding_distance,
    nondominated_fronts,
    nsga2,
    survivors,
    variation,
)


def brute_dominates(f, v, g, w) -> bool:
    """Deb's constrained domination of design (f, v) over (g, w), written out."""
    if v == 0 and w == 0:
        return all(a <= b for a, b in zip(f, g, strict=True)) and any(
            a < b for a, b in zip(f, g, strict=True)
        )
    return w > 0 and v < w


designs = st.integers(1, 12).flatmap(
    lambda m: st.tuples(
        arrays(float, (m, 2), elements=st.sampled_from([0.0, 1.0, 2.0, 3.0])),
        arrays(float, (m,), elements=st.sampled_from([0.0, 0.0, 0.5, 1.0, np.inf])),
    )
)


@settings(max_examples=100, deadline=None)
@given(designs)
def test_fronts_are_those_of_the_definition(case):
    F, V = case
    fronts = nondominated_fronts(F, V)
    assert sorted(np.concatenate(fronts).tolist()) == list(range(len(F)))
    placed: set[int] = set()
    for front in fronts:
        for j in front:  # nothing left dominates a member of the front...
            assert not any(brute_dominates(F[i], V[i], F[j], V[j])
                           for i in range(len(F)) if i not in placed)  # fmt: skip
        placed |= set(front.tolist())
        # ...and each later design is dominated by one of this front or an earlier one
    for r, front in enumerate(fronts[1:], start=1):
        before = np.concatenate(fronts[:r])
        for j in front:
            assert any(brute_dominates(F[i], V[i], F[j], V[j]) for i in before)


def test_crowding_distance_of_a_known_front():
    F = np.array([[0.0, 4.0], [1.0, 3.0], [3.0, 1.0], [4.0, 0.0]])
    d = crowding_distance(F)
    # inner points: (gap in f1 + gap in f2) / extent 4 each
    np.testing.assert_allclose(d, [np.inf, (3 - 0) / 4 + (4 - 1) / 4, (4 - 1) / 4 + (3 - 0) / 4,
                                   np.inf])  # fmt: skip


def test_survivors_keep_whole_fronts_then_the_most_isolated():
    F = np.array([[0, 3], [1, 2], [2, 1], [3, 0], [1.1, 2.1], [5, 5]], dtype=float)
    kept = survivors(F, np.zeros(6), 5)
    assert sorted(kept.tolist()) == [0, 1, 2, 3, 4]
    assert sorted(survivors(F, np.zeros(6), 3).tolist()) in ([0, 1, 3], [0, 2, 3])


def test_variation_stays_in_the_box_and_reaches_its_bounds():
    rng = np.random.default_rng(0)
    U = rng.random((40, 3))
    children = variation(U, np.zeros(40, dtype=int), np.zeros(40), rng)
    assert children.shape == U.shape and np.all((children >= 0) & (children <= 1))
    assert np.any(children == 0.0) or np.any(children == 1.0)  # clipped onto a bound


def test_zdt1_converges_to_its_front():
    """ZDT1 with 10 variables, 40 designs a generation: the last front within 2e-2 of
    f2 = 1 - sqrt(f1) on average (NSGA-II's usual figure after 10^4 evaluations is a few
    1e-3) and spread over f1 in [0, 1]."""
    rng = np.random.default_rng(0)
    found = []

    def zdt1(U):
        f1 = U[:, 0]
        g = 1 + 9 * U[:, 1:].mean(axis=1)
        F = np.column_stack([f1, g * (1 - np.sqrt(f1 / g))])
        found.append(F)
        return F, np.zeros(len(U))

    nsga2(zdt1, qmc.LatinHypercube(d=10, rng=rng).random(40), 250, rng)
    last = np.vstack(found[-10:])
    front = last[nondominated_fronts(last, np.zeros(len(last)))[0]]
    assert np.mean(front[:, 1] - (1 - np.sqrt(front[:, 0]))) < 2e-2
    assert front[:, 0].min() < 0.01 and front[:, 0].max() > 0.99

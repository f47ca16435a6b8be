"""The committed decay rates (codegen.design.rates): the candidates and the search over them."""
import numpy as np
import pytest

from codegen.design import rates


@pytest.mark.parametrize("digits, resolution", [(2, 2.0 ** -14), (3, 2.0 ** -30)])
def test_candidates_are_every_rounded_rate_below_the_top(digits, resolution):
    rng = np.random.default_rng(digits)
    for top in [*rng.uniform(1e-3, 200.0, 50), 2.55, 100.0]:
        candidates = rates.committable_rates(top, digits, resolution)
        assert candidates == sorted(set(candidates)) and candidates[-1] <= top
        assert candidates[0] >= resolution * top
        assert all(rates.round_down(q, digits) == q for q in candidates)
        assert rates.round_down(top, digits) == candidates[-1]
        # a random rate in the range rounds down onto a candidate
        for x in rng.uniform(resolution * top * 10, top, 20):
            assert rates.round_down(x, digits) in candidates


@pytest.mark.parametrize("near_top", [True, False])
def test_search_asks_few_and_finds_the_largest(near_top):
    """For every threshold of a monotone answer (none, the smallest, the top, anywhere between) the
    largest candidate that holds, asking about candidates only: at most 2 log2(n) + 3 of them near the
    top (one when the answer is the top, two when it is the one below, three when there is none), log2(n) + 1 otherwise."""
    rng = np.random.default_rng(3)
    for top in [*rng.uniform(1e-3, 100.0, 100), 2.55]:
        candidates = rates.committable_rates(top, 2 if near_top else 3, 2.0 ** -14 if near_top else 2.0 ** -30)
        for k in {-1, 0, len(candidates) - 1, len(candidates) - 2, int(rng.integers(len(candidates)))}:
            asked = []

            def holds(q):
                asked.append(q)
                return candidates.index(q) <= k
            assert rates.largest_holding(candidates, holds, near_top) == (candidates[k] if k >= 0 else None)
            if near_top:
                assert len(asked) <= 2 * np.log2(len(candidates)) + 3
                if k == len(candidates) - 1:
                    assert len(asked) == 1
                if k == len(candidates) - 2:            # the one below the top: two questions
                    assert len(asked) == 2
                if k == -1:                     # none holds: the top, the next, the smallest
                    assert len(asked) <= 3
            else:
                assert len(asked) <= np.ceil(np.log2(len(candidates) + 1))


def test_bisection_of_the_rate_rounds_to_the_search():
    """Where feasibility switches at a* (not at a rounding boundary), a bisection of the real rate on
    [0, top] rounded down gives the search's answer."""
    rng = np.random.default_rng(7)
    top = 200.0
    candidates = rates.committable_rates(top, 3, 2.0 ** -30)
    for a_star in rng.uniform(1e-4, top, 200):
        holds = lambda a: a <= a_star            # noqa: E731
        lo, hi = 0.0, top
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if holds(mid) else (lo, mid)
        if rates.round_down(lo, 3) == rates.round_down(a_star, 3):      # no boundary between lo and a*
            assert rates.largest_holding(candidates, holds, near_top=False) == rates.round_down(lo, 3)

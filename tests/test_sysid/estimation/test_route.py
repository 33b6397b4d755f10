"""Which route identifies a session (sysid.estimation.route): the checks of the options and the decisions."""

import dataclasses

import numpy as np
import pytest

from sysid.core.errors import IdentificationError
from sysid.core.thresholds import SEARCH_MAX_ORDER, SEARCH_SHORT_ORDER
from sysid.estimation import route
from sysid.estimation.order_curve import OrderCurve
from sysid.identify import IdentificationOptions


@pytest.mark.parametrize("cap", [0, -3, 2.5, "10", True])
def test_a_bad_cap_is_refused(cap):
    with pytest.raises(IdentificationError, match="max_order"):
        route.check_route(IdentificationOptions(max_order=cap))


def test_a_bad_route_is_refused():
    with pytest.raises(IdentificationError, match="route must be one of"):
        route.check_route(IdentificationOptions(route="fast"))


def test_the_search_orders_stay_under_the_cap():
    assert route.search_orders_of(IdentificationOptions()) == tuple(range(1, SEARCH_MAX_ORDER + 1))
    assert route.search_orders_of(IdentificationOptions(max_order=6)) == tuple(range(1, 7))
    assert route.search_orders_of(IdentificationOptions(orders=(8, 9, 10), max_order=9)) == (8, 9)
    # Orders beyond the search's reach are the long route's: the search and the seed grid keep to their own.
    assert route.search_orders_of(IdentificationOptions(orders=(600,))) == tuple(range(1, SEARCH_MAX_ORDER + 1))
    assert max(route.grid_orders(IdentificationOptions(orders=(600,)))) <= SEARCH_MAX_ORDER
    assert route.grid_orders(IdentificationOptions(orders=(8, 9, 600))) == (8, 9)


def test_given_orders_within_the_search_skip_the_long_estimate():
    assert route.wants_long(IdentificationOptions())
    assert not route.wants_long(IdentificationOptions(orders=(8, 9, 10)))
    assert not route.wants_long(IdentificationOptions(route="search"))
    assert route.wants_long(IdentificationOptions(orders=(8, 9, 10), route="long"))


@dataclasses.dataclass
class _Estimate:
    curve: OrderCurve
    lengths: dict


def _estimate(floor_order: int) -> _Estimate:
    orders = [4, floor_order // 2, floor_order, 2 * floor_order]
    return _Estimate(OrderCurve(orders, [10.0, 3.0, 1.0, 1.0], 1.0, np.ones(1), "test"), {100: 1.0})


def test_the_search_runs_where_the_long_route_is_short_or_short_of_the_floor():
    options = IdentificationOptions()
    # No long model (the FIR does not hold the response): the search.
    assert route.wants_search(options, None, None, None, 1.0)
    # A short long-route model: the search beside it.
    assert route.wants_search(options, _estimate(40), 1.0, SEARCH_SHORT_ORDER, 1.0)
    # A long model at the floor: enough.
    assert not route.wants_search(options, _estimate(40), 1.0, 40, 1.0)
    # Above the floor, where the curve asks for an order the search reaches: the search too; beyond it: not.
    assert route.wants_search(options, _estimate(20), 2.0, 20, 1.0)
    assert not route.wants_search(options, _estimate(200), 2.0, 100, 1.0)
    assert not route.wants_search(IdentificationOptions(route="long"), _estimate(20), 2.0, 20, 1.0)

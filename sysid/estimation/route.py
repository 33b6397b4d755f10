"""Which route identifies a session: the order search, the long route, or both.

``sysid.identify`` has two ways to a model. The order search (``sysid.estimation.order_search``:
output error from several starts at every order, then delay trials and reduction) is best for
short rational plants, the seed's and random helmets', however lightly damped their modes; its
cost grows with every order it tries, and it stops at ``SEARCH_MAX_ORDER``. The long route
(``sysid.estimation.long_route``: a least-squares FIR, its frequency-limited truncation to every
order, output error at the order chosen) reaches hundreds of states in seconds, but only where
an FIR of at most ``FIR_MAX_TAPS`` taps holds the response (a mode of Q 50 at 35 Hz rings for 0.45 s
per neper: no FIR holds it, the order search does).

The decision is taken from the data, cheapest first:

1. The long estimate is made (``wants_long``) unless the route is forced to the search, or the
   caller asked for given orders all within the search's reach (the refits' re-identifications
   at the model's own order and two above).
2. Where its FIR holds the response, the long route's model is made; it is enough when it
   validates at what the data allow: within ``min_gain`` of the FIR's own validation rms (the
   nonparametric best of this session), or within ``at_floor`` times the noise floor.
3. Otherwise, and in doubt (``wants_search``), the order search runs too, and ``identify`` keeps
   the fewer states among the models within ``min_gain`` of the better validation rms: where the
   FIR does not hold the response; where the long route's model is above what the data allow and
   the search can reach the order its curve asks for; and where that model has at most
   ``SEARCH_SHORT_ORDER`` states, a short plant, whose own order the search's fits from several starts
   find where a truncation may need more (random helmet 85, short session: 11 states from the
   truncation ladder, 4 from the search, the plant's own; over its whole range of orders: capped at
   the long route's order, it lost its way on helmets 32, 35 and 38, 11-31x). A dense response
   needing more states (the FABIAN HRIR: 24 states at 1.10x the floor from the long route in 3 s
   of CPU) is left to the long route: the search took 20 s there for 21 states at 2.9x.
"""

from __future__ import annotations


from ..core.errors import IdentificationError
from ..core.thresholds import DEFAULT_ORDERS, SEARCH_MAX_ORDER, SEARCH_SHORT_ORDER
from .long_route import LongEstimate

__all__ = ["ROUTES", "check_route", "wants_long", "wants_search", "search_orders_of", "grid_orders", "ladder_orders",
           "enough"]

ROUTES = ("auto", "search", "long")


def check_route(options) -> None:
    """IdentificationError for a route or an order cap ``identify`` cannot take."""
    if options.route not in ROUTES:
        raise IdentificationError(f"route must be one of {', '.join(ROUTES)}; found {options.route!r}")
    cap = options.max_order
    if cap is not None and (isinstance(cap, bool) or not isinstance(cap, int) or cap < 1):
        raise IdentificationError(f"max_order must be a whole number of states of at least 1, or None; found {cap!r}")


def _explicit(options) -> bool:
    return tuple(options.orders) != DEFAULT_ORDERS


def search_orders_of(options) -> tuple[int, ...]:
    """The orders the order search tries: those given within its reach (SEARCH_MAX_ORDER) and the cap, or
    1 .. SEARCH_MAX_ORDER under the cap (orders given all beyond its reach are the long route's)."""
    top = SEARCH_MAX_ORDER if options.max_order is None else min(SEARCH_MAX_ORDER, options.max_order)
    given = tuple(n for n in options.orders if n <= top) if _explicit(options) else ()
    return given or tuple(range(1, top + 1))


def grid_orders(options) -> tuple[int, ...]:
    """The seed grid's orders: those given within the order search's reach, else the seed's (a subspace fit of
    hundreds of states has not the frequencies it needs: orders beyond SEARCH_MAX_ORDER are the long route's)."""
    return tuple(n for n in options.orders if n <= SEARCH_MAX_ORDER) or DEFAULT_ORDERS


def ladder_orders(options) -> int | None:
    """The highest order the truncation ladder walks to: the largest order given, when orders are given."""
    return max(options.orders) if _explicit(options) else None


def wants_long(options) -> bool:
    """Step 1 of the module docstring."""
    if options.route == "long":
        return True
    if options.route == "search":
        return False
    return not (_explicit(options) and max(options.orders) <= SEARCH_MAX_ORDER)


def enough(estimate: LongEstimate, rms: float, floor: float, at_floor: float, min_gain: float) -> bool:
    """True when the long route's model (validation rms ``rms``, FS) validates at what the data allow (step 2)."""
    return rms <= max(at_floor * floor, min(estimate.lengths.values()) * (1 + min_gain))


def wants_search(options, estimate: LongEstimate | None, long_rms: float | None, long_order: int | None,
                 floor: float) -> bool:
    """Step 3 of the module docstring (``long_rms``, FS, and ``long_order``: the long route's model's)."""
    if options.route == "search" or estimate is None or long_rms is None:
        return True
    if options.route == "long":
        return False
    if long_order <= SEARCH_SHORT_ORDER:
        return True
    if enough(estimate, long_rms, floor, options.at_floor, options.min_gain):
        return False
    asked = estimate.curve.lowest_at_floor(options.at_floor, options.min_gain, options.max_order)
    return asked <= SEARCH_MAX_ORDER

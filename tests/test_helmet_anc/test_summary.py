"""helmet_anc.commands.common.identification_summary: what identify prints says what happened to the model."""

import copy
import dataclasses

from helmet_anc.commands.common import identification_summary


def _from_the_search(result):
    """``result`` with its model's provenance as the order search writes it (the route that reduces)."""
    model = copy.deepcopy(result.model)
    info = model.identification
    info.update(route="order search", refined=True)
    info["refinement"] = dict(info.get("refinement", {}), order=model.order, start_gamma=info["gamma"])
    return dataclasses.replace(result, model=model)


def test_a_reduction_after_the_order_search_is_said(identifications):
    result = _from_the_search(identifications["ff"])
    model = result.model
    model.identification["refinement"].update(order=model.order + 1,
                                              reduced="1 state of negligible Hankel singular value left out")
    summary = identification_summary(result)
    chosen = next(line for line in summary.splitlines() if "chosen model" in line)
    assert (f"order {model.order} (reduced from {model.order + 1}: 1 state of negligible Hankel singular value "
            "left out)") in chosen


def test_no_reduction_no_note(identifications):
    for result in (identifications["ff"], _from_the_search(identifications["ff"])):
        assert "reduced from" not in identification_summary(result)


def test_the_route_is_named(identifications):
    for result in identifications.values():
        chosen = next(line for line in identification_summary(result).splitlines() if "chosen model" in line)
        route = result.model.identification.get("route")
        assert ("long route" in chosen) == (route == "long route")

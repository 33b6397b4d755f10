"""helmet_anc.commands.common.identification_summary: what identify prints says what happened to the model."""

import copy
import dataclasses

from helmet_anc.commands.common import identification_summary


def test_a_reduction_after_the_order_search_is_said(identifications):
    result = identifications["ff"]
    model = copy.deepcopy(result.model)
    model.identification["refinement"] = dict(model.identification["refinement"], order=model.order + 1,
                                              reduced="1 state of negligible Hankel singular value left out")
    summary = identification_summary(dataclasses.replace(result, model=model))
    chosen = next(line for line in summary.splitlines() if "chosen model" in line)
    assert (f"order {model.order} (reduced from {model.order + 1}: 1 state of negligible Hankel singular value "
            "left out)") in chosen


def test_no_reduction_no_note(identifications):
    result = identifications["ff"]
    assert result.model.identification["refinement"]["order"] == result.model.order
    assert "reduced from" not in identification_summary(result)

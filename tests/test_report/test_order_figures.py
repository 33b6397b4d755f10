"""The order/error/cost figure (report.order_figures): drawn from the model's provenance as stored."""

import numpy as np

from report.order_figures import has_order_curve, order_curve_figure
from sysid.core.board import board_cost
from sysid.core.model import Model


def _model(capped: bool) -> Model:
    orders = [1, 2, 4, 8, 16, 32]
    ratio = [40.0, 20.0, 6.0, 1.6, 1.05, 1.02]
    curve = {"source": "frequency-limited balanced truncation of the least-squares FIR", "noise_floor": 1e-4,
             "orders": orders, "rms": [r * 1e-4 for r in ratio], "ratio": ratio,
             "hankel_singular_values": list(np.geomspace(1.0, 1e-4, 40)),
             "sections": [board_cost(n).sections for n in orders], "q15_block": [board_cost(n).block for n in orders],
             "q15_step": [board_cost(n).step for n in orders], "refined_orders": [8], "refined_rms": [1.3e-4],
             "refined_ratio": [1.3], "chosen": 8}
    info = {"order_curve": curve}
    if capped:
        info["capped"] = {"max_order": 8, "ratio": 1.3, "floor_order": 16, "floor_ratio": 1.05,
                          "floor_instructions": board_cost(16).step}
    A = np.diag(np.linspace(0.1, 0.8, 8))
    return Model(path="fb", fs=44100.0, A=A, B=np.ones((8, 1)), C=np.ones((1, 8)), D=np.zeros((1, 1)),
                 identification=info)


def test_the_curve_is_drawn_as_stored():
    model = _model(capped=True)
    assert has_order_curve(model)
    figure = order_curve_figure(model)
    top = figure.axes[0]
    curve = model.identification["order_curve"]
    lines = {line.get_label(): line for line in top.get_lines()}
    ladder = lines[curve["source"]]
    np.testing.assert_array_equal(ladder.get_ydata(), curve["ratio"])
    assert "chosen: 8 states" in lines and "at the floor: 16 states" in lines
    cost = figure.axes[-1]
    np.testing.assert_allclose(cost.get_lines()[0].get_ydata(), curve["q15_step"])


def test_a_model_without_a_curve_has_no_figure():
    model = _model(capped=False)
    model.identification = {}
    assert not has_order_curve(model)

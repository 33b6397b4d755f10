"""The order/error/cost trade-off of an identified model, drawn from its provenance.

``identify`` stores the curve in ``model.identification["order_curve"]`` (``sysid.core.model``):
per model order the validation rms on the sweeps over the noise floor, the frequency-limited
Hankel singular values of the estimate the orders were cut from, and the board cost (emulated
Cortex-M4 instructions per sample, ``sysid.core.board``). This module reads it as stored and
recomputes nothing.
"""

from __future__ import annotations

import numpy as np

from .style import COLORS, new_figure

__all__ = ["has_order_curve", "order_curve_figure"]


def has_order_curve(model) -> bool:
    """True when the model's provenance holds an order/error/cost curve of at least two orders."""
    curve = (getattr(model, "identification", None) or {}).get("order_curve")
    return bool(curve) and len(curve.get("orders", [])) >= 2


def order_curve_figure(model, dpi: float = 100.0):
    """Validation rms over the noise floor against the model order (top), with the refined models and the chosen
    order marked; the Hankel singular values sigma_(n+1) / sigma_1 and the board cost against the same orders
    (bottom, two axes)."""
    info = model.identification
    curve = info["order_curve"]
    orders = np.asarray(curve["orders"], dtype=float)
    figure, axes = new_figure(2, 1, height=2.6, sharex=True, dpi=dpi)
    top, bottom = axes
    top.plot(orders, curve["ratio"], color=COLORS["smoothed"], marker=".", lw=1.0, label=curve["source"])
    if curve.get("refined_orders"):
        top.plot(curve["refined_orders"], curve["refined_ratio"], ls="none", marker="o", mfc="none",
                 color=COLORS["seed"], label="refined at that order")
    top.axhline(1.0, color=COLORS["noise_floor"], ls="--", lw=0.8, label="noise floor")
    chosen = curve.get("chosen")
    if chosen is not None:
        top.axvline(chosen, color=COLORS["model"], lw=0.8, label=f"chosen: {chosen} states")
        bottom.axvline(chosen, color=COLORS["model"], lw=0.8)
    capped = info.get("capped")
    if capped:
        top.axvline(capped["floor_order"], color=COLORS["bound"], ls=":", lw=0.8,
                    label=f"at the floor: {capped['floor_order']} states")
    top.set_xscale("log")
    top.set_yscale("log")
    top.set_ylabel("validation rms / noise floor")
    top.legend(loc="upper right", fontsize=7)
    top.grid(True, which="both", alpha=0.3)
    hsv = np.asarray(curve.get("hankel_singular_values", []), dtype=float)
    shown = [i for i, n in enumerate(curve["orders"]) if n < hsv.size and hsv[n] > 0]
    if shown:
        bottom.plot(orders[shown], hsv[[curve["orders"][i] for i in shown]], color=COLORS["measured"], marker=".",
                    lw=1.0, label="Hankel singular value s(n+1) / s(1)")
        bottom.set_yscale("log")
    bottom.set_ylabel("s(n+1) / s(1)")
    bottom.set_xlabel("model order (states)")
    bottom.grid(True, which="both", alpha=0.3)
    cost = bottom.twinx()
    cost.plot(orders, curve["q15_step"], color=COLORS["frequency"], lw=1.0, label="Cortex-M4 instructions / sample")
    cost.set_ylabel("M4 instructions / sample\n(Q15, one-sample step)", fontsize=8)
    lines = bottom.get_lines() + cost.get_lines()
    bottom.legend([ln for ln in lines if not ln.get_label().startswith("_")],
                  [ln.get_label() for ln in lines if not ln.get_label().startswith("_")], loc="upper center", fontsize=7)
    top.set_title("Order, error and board cost (from the model's provenance)", fontsize=9)
    return figure

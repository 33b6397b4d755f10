"""A simulated lab campaign: random helmets, each on several heads, written as a session folder tree.

Helmet h is ``sysid.random_plant.random_plant(seed + h, path)``; head k of it is
``riders.rider_variant`` of that plant (modes shifted, damping and leak varied). Each
session is ``sysid.simulate.simulate_session`` of the variant at the plant's sample rate
and sensor noise, written to ``root/H<h>/head<k>/<path>/`` with its truth.json (the
variant is the true plant). Used by the tests and the benchmark.
"""

from __future__ import annotations

from pathlib import Path

from sysid.core.model import Model
from sysid.random_plant import random_plant
from sysid.simulate import SessionSpec, simulate_session, write_session

from .riders import RiderSpread, rider_variant

__all__ = ["write_simulated_campaign"]


def write_simulated_campaign(root, helmets: int, heads: int, path: str = "fb", seed: int = 0,
                             spread: RiderSpread = RiderSpread(), latency: bool = True,
                             **spec_overrides) -> dict[str, Model]:
    """Write helmets x heads sessions under root; return {session folder (relative): true plant}.

    ``latency=False`` drops the drawn plants' pure delay; ``spec_overrides`` replace
    ``SessionSpec`` fields (e.g. ``noise_duration=6.0``).
    """
    root = Path(root)
    truths = {}
    for h in range(helmets):
        helmet = random_plant(seed + h, path)
        for k in range(heads):
            variant = rider_variant(helmet.model, seed=1000 * (seed + h) + k, spread=spread)
            if not latency:
                variant = Model.from_dict(dict(variant.to_dict(), delay=0))
            fields = {"path": path, "seed": 1000 * (seed + h) + k, "fs": helmet.fs, "output_noise": helmet.sensor_noise}
            fields.update(spec_overrides)
            session = simulate_session(SessionSpec(**fields), plant=variant)
            folder = Path(f"H{h}") / f"head{k}" / path
            write_session(session, root / folder)
            truths[str(folder)] = variant
    return truths

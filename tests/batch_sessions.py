"""Shared pieces of the batch tests: a small simulated campaign and fast identification options."""

from __future__ import annotations

from sysid.identify import IdentificationOptions

# A few seconds of audio per session and a coarse grid keep one identification near a second.
SHORT_SESSION = dict(noise_duration=6.0, sweep_duration=2.0, sweep_silence=0.2)
BATCH_OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 60)), orders=tuple(range(1, 13)), refine_seconds=3.0)

# Columns that depend on the clock or on the run, not on the data.
RUN_COLUMNS = ("seconds_load", "seconds_identify", "seconds_refine", "seconds_total", "seconds_cpu", "resumed")


def data_columns(row: dict) -> dict:
    return {k: v for k, v in row.items() if k not in RUN_COLUMNS}

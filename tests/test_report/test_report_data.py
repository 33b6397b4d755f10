"""report.data: the figures read the detectors' own context, never one of their own making."""

import dataclasses

import numpy as np

from report.data import prepare_report_data
from sysid.diagnose import diagnose
from sysid.io.corrections import corrected


def test_a_diagnosis_lends_its_context(sessions, identifications):
    session, result = sessions["ff"], identifications["ff"]
    diagnosis = diagnose(result.model, session.noise, session.sweeps)
    data = prepare_report_data(result.model, session.noise, session.sweeps, result, diagnosis)
    assert data.context is diagnosis.context and data.comparison is diagnosis.comparison
    # The shared values the detectors computed, there for the figures to read.
    assert {"segments", "session-lines", "delay-scan-data"} <= set(data.context.values)
    assert data.context.readable is None and data.context.readable_findings is None


def test_without_a_diagnosis_the_context_is_built_as_diagnose_builds_it(sessions, identifications):
    session, result = sessions["ff"], identifications["ff"]
    # A model with a clock correction: the figures see the recordings resampled as the detectors did.
    model = dataclasses.replace(result.model, clock_ratio=1.0 + 40e-6)
    findings = [f.to_dict() for f in diagnose(model, session.noise, session.sweeps)]
    data = prepare_report_data(model, session.noise, session.sweeps, result, findings)
    assert data.context.findings == [] and data.context.values == {}
    np.testing.assert_array_equal(data.context.noise.y, corrected(session.noise, model.clock_ratio).y)
    n = data.context.noise.y.size
    assert not np.array_equal(data.context.noise.y, session.noise.y[:n])

"""findings: the values detectors share are computed once by named providers, read only where declared."""

import inspect

import numpy as np
import pytest
from effect_units import true_session

from sysid import effects
from sysid.core.model import Model
from sysid.diagnose import diagnose
from sysid.effects import Effect
from sysid.findings import PROVIDERS, DiagnosisContext, data_quality, finding, uses
from sysid.io.lines import line_search
from sysid.validation.compare import compare

HUM = ("periodic-disturbance:50,3,1e-3",)


def _true_model(session) -> Model:
    return Model.from_dict(session.truth.get("base_plant", session.truth["plant"]))


def test_one_line_search_per_diagnosis_read_by_both_line_findings(monkeypatch):
    session = true_session("ff", 5, HUM)
    model = _true_model(session)
    calls, readers = [], set()
    # The provider registers on its module's import (the registry imports it lazily, on the first diagnosis).
    assert data_quality.clipping_finding.uses
    search = PROVIDERS["session-lines"]
    monkeypatch.setitem(PROVIDERS, "session-lines", lambda ctx: calls.append(ctx) or search(ctx))
    value = DiagnosisContext.value

    def reading(self, name):
        if name == "session-lines":
            readers.add(inspect.stack()[1].function)
        return value(self, name)

    monkeypatch.setattr(DiagnosisContext, "value", reading)
    findings = diagnose(model, session.noise, session.sweeps)
    assert len(calls) == 1
    assert {"clipping_finding", "disturbance_finding"} <= readers
    hum = next(f for f in findings if f.effect == "periodic-disturbance")
    assert hum.significant and hum.params["frequencies_hz"] == pytest.approx([50.0, 100.0, 150.0], abs=0.05)
    # The shared value is the direct search on the same recordings and predictions.
    ctx = calls[0]
    direct = line_search([ctx.noise, *ctx.sweeps],
                         [model.simulate(ctx.noise.u)] + [s["linear"] for s in ctx.comparison.per_sweep])
    assert value(ctx, "session-lines") == direct
    assert [round(line[0]) for line in direct.found[0]] == [50, 100, 150]
    assert list(direct.frequencies) == sorted(line[0] for lines in direct.found for line in lines)


def test_a_detector_reads_only_the_values_it_declares():
    session = true_session("ff", 5, ())
    model = _true_model(session)

    def undeclared(ctx):
        return finding("x-lines", False, 0.0, {"lines": len(ctx.value("session-lines").frequencies)}, "", "none")

    with effects.registered(Effect(name="x-lines", summary="x", kind="report", detect=uses()(undeclared))):
        with pytest.raises(KeyError, match="session-lines"):
            diagnose(model, session.noise, session.sweeps)
    with effects.registered(Effect(name="x-lines", summary="x", kind="report", detect=uses("session-lines")(undeclared))):
        found = next(f for f in diagnose(model, session.noise, session.sweeps) if f.effect == "x-lines")
    assert found.params == {"lines": 0}
    # Outside diagnose (a refinement's or a report's context) every value is readable, each computed once.
    ctx = DiagnosisContext(model, session.noise, session.sweeps, compare(model, session.sweeps))
    assert ctx.value("noise-prediction") is ctx.value("noise-prediction")
    np.testing.assert_array_equal(ctx.value("noise-prediction"), model.simulate(session.noise.u))
    with pytest.raises(KeyError, match="no provider"):
        ctx.value("nothing")


def test_a_detector_reads_only_the_findings_it_needs():
    session = true_session("ff", 5, ())
    model = _true_model(session)
    seen = {}

    def reader(name):
        def detect(ctx):
            seen[name] = [f.effect for f in ctx.findings_of("clipping", "delay")]
            return finding(name, False, 0.0, {"clipping": ctx.finding("clipping") is not None}, "", "none")
        return uses()(detect)

    declared = Effect(name="x-reads", summary="x", kind="report", detect=reader("x-reads"), needs=("clipping", "delay"))
    with effects.registered(declared):
        found = next(f for f in diagnose(model, session.noise, session.sweeps) if f.effect == "x-reads")
    assert found.params == {"clipping": True} and seen["x-reads"] == ["clipping", "delay"]
    # Declaring one of them is not enough to read the other, whichever ran first.
    partly = Effect(name="x-reads", summary="x", kind="report", detect=reader("x-reads"), needs=("clipping",))
    with effects.registered(partly), pytest.raises(KeyError, match="finding of 'delay'.*declares clipping"):
        diagnose(model, session.noise, session.sweeps)
    # Outside diagnose every finding is readable (none yet on a new context).
    ctx = DiagnosisContext(model, session.noise, session.sweeps, compare(model, session.sweeps))
    assert ctx.finding("delay") is None and ctx.findings_of("delay") == []


def test_every_detector_reads_what_its_effect_needs():
    # needs_all: every finding; a shared detector: what each of its effects needs.
    assert effects.findings_read_by(effects.get("under-modelled").detect) is None
    assert effects.findings_read_by(effects.get("resonance").detect) == ()
    assert effects.findings_read_by(effects.get("time-variation").detect) == ("clipping",)
    # Clipping too: harmonics of a clipped recording are the clipping's, not the driver's.
    assert effects.findings_read_by(effects.get("input-nonlinearity").detect) == ("resonance", "highpass", "lowpass",
                                                                                    "delay", "clipping")

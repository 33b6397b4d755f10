"""The controller JSON contract and its limits fields, the design's refusals and defaults, the design command.

Designs take minutes on this machine, so the default run checks what needs no design (the contract on a
small stored-style controller, refusals made before any design, the latency default, the command's
table and its one-line errors); the designs themselves are checked in ``test_design_closed_loop.py``
(slow).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg

from anc import CONTROLLER_FORMAT, Controller, DesignOptions, design
from anc.controller import BOARD_LATENCY_SAMPLES, StateSpaceFilter
from anc.design import WEAK_DRIVE_DB, _ff_reason, _margins, band_limits
from anc.limits import Limits
from anc.prediction import band_centres
from codegen.controller import PROCESSING_LATENCY_MIN
from control_cases import small_controller
from helmet_anc.cli import main
from helmet_anc.commands.design import margin_lines, table
from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model


def _limits_record() -> dict:
    n = len(band_centres())
    ff = Limits(band_centres(), [10.0] * n, [40.0] * n,
                ["the chin path is faster than the drive path by 3 samples (without that 30.0 dB)"] * (n - 1)
                + ["regularisation: the drive path 3 dB below its peak, the chin noise floor -60 dB"], 2,
                {"grid_points": 4096, "bad": float("nan")})

    class Bound:
        bands_hz = np.array([c for c in band_centres() if 50.0 <= c <= 1000.0])
        attenuation_db = np.full(bands_hz.size, 5.0)
        limits = ["the waterbed"] * bands_hz.size

    return band_limits(band_centres(), ff, Bound())


def test_the_design_latency_defaults_to_the_boards_control_path():
    """One figure: the design's default, the board's control path and codegen's check read the same constant."""
    assert DesignOptions().latency == BOARD_LATENCY_SAMPLES == PROCESSING_LATENCY_MIN == 2


def test_json_round_trip_keeps_the_contract_and_the_limits(tmp_path):
    controller = small_controller(limits=_limits_record())
    path = tmp_path / "c.json"
    controller.save(path)
    data = json.loads(path.read_text())  # strict JSON: no NaN
    for key in ("format", "fs", "internal_model", "ff", "fb", "latency_samples", "bands_hz", "predicted_attenuation_db"):
        assert key in data
    assert data["format"] == CONTROLLER_FORMAT
    assert data["limits"]["feedforward_details"]["bad"] is None
    again = Controller.load(path)
    n = len(band_centres())
    assert again.limits["causal_ff_db"] == [10.0] * n
    assert again.limits["feedback_db"][band_centres().index(50.1)] == 5.0
    assert again.limits["feedback_db"][0] is None  # 20 Hz: outside the feedback bound's bands
    assert again.limits["reasons"]["fb"][band_centres().index(1000.0)] == "the waterbed"
    f = np.array([100.0, 1000.0])
    np.testing.assert_allclose(again.fb.frequency_response(f, again.fs), controller.fb.frequency_response(f, again.fs))


def test_a_file_without_the_new_fields_loads():
    data = small_controller().to_dict()
    for key in ("limits", "feedback_bound", "margins", "notes", "provenance", "coherence_bound_db"):
        data.pop(key)
    controller = Controller.from_dict(data)
    assert controller.limits is None and controller.feedback_bound is None


def test_malformed_limits_are_refused():
    data = small_controller(limits=_limits_record()).to_dict()
    data["limits"]["causal_ff_db"] = [1.0]
    with pytest.raises(HelmetAncError, match="one value per band"):
        Controller.from_dict(data)


def test_unstable_filter_in_json_is_refused():
    data = small_controller().to_dict()
    data["fb"] = {"A": [[1.5]], "B": [[1.0]], "C": [[1.0]], "D": [[0.0]]}
    with pytest.raises(HelmetAncError, match="'fb' is unstable"):
        Controller.from_dict(data)


def test_an_unexplained_feedforward_limit_says_nothing_unless_the_drive_is_weak():
    """The limits' remainder ("regularisation: ...") names no cause; stored only where the drive path is weak."""
    assert _ff_reason("regularisation: the drive path 3 dB below its peak, the chin noise floor -60 dB") == ""
    weak = _ff_reason(f"regularisation: the drive path {WEAK_DRIVE_DB + 5:.0f} dB below its peak, the chin noise "
                      "floor -60 dB")
    assert weak == f"the drive path {WEAK_DRIVE_DB + 5:.0f} dB below its loudest band"
    named = "coherence: the ear noise not coherent with the chin (40.0 dB bound)"
    assert _ff_reason(named) == named


def test_no_crossover_has_no_phase_margin():
    """|Lg| < 1 everywhere: no phase margin (the old '180 deg'), said in words; with a crossover, a number."""
    f = np.geomspace(20.0, 2000.0, 50)
    small = _margins({"phase_margin_deg": 180.0}, np.full(f.size, -0.2 + 0j))
    assert small["phase_margin_deg"] is None and small["crossovers"] == 0
    base = {"gain_margin_db": None, "peak_amplification_db": 2.0, "peak_amplification_hz": 500.0,
            "robustness_factor": 1.5}
    assert "no crossover" in margin_lines({**base, **small})[0]
    loop = np.where(f < 300.0, -0.9 + 0j, -0.1 + 0j)  # |Lg| = 9 below 300 Hz, 0.11 above
    crossing = _margins({"phase_margin_deg": 60.0}, loop)
    assert crossing["crossovers"] == 1 and crossing["phase_margin_deg"] == 60.0
    assert "phase margin 60 deg" in margin_lines({**base, **crossing})[0]


def test_table_states_the_sign_convention_limits_and_reasons():
    text = table(small_controller(limits=_limits_record()))
    assert "positive = quieter at the ear" in text
    assert "causal ff" in text and "coherence" in text and "feedback" in text
    row_1k = next(line for line in text.splitlines() if line.lstrip().startswith("1000 "))
    assert "fb: the waterbed" in row_1k and "ff: chin path 3 samples ahead" in row_1k
    assert "no crossover" in text


def _ringing(s: Model, radius: float, hz: float) -> Model:
    w = 2 * np.pi * hz / s.fs
    ring = radius * np.array([[np.cos(w), -np.sin(w)], [np.sin(w), np.cos(w)]])
    A = scipy.linalg.block_diag(s.A, ring)
    B = np.vstack((s.B, [[1e-6], [0.0]]))
    C = np.hstack((s.C, [[1e-6, 0.0]]))
    return Model.from_dict({**s.to_dict(), "A": A.tolist(), "B": B.tolist(), "C": C.tolist()})


def test_fb_model_with_undamped_pole_is_refused():
    """A pole pair at radius 1 - 1e-9 near fs/2 (random helmet 9's identified FB model) is refused with why."""
    with pytest.raises(HelmetAncError, match="undamped pole at 22000 Hz"):
        design(_ringing(appendix_a_model("fb"), 1.0 - 1e-9, 22000.0))


def test_fb_model_with_unknown_error_is_refused():
    s = appendix_a_model("fb")
    bad = Model.from_dict({**s.to_dict(), "identification": {"rms": 1e-2, "noise_floor": 1e-4}})
    with pytest.raises(HelmetAncError, match="100.0x the noise floor"):
        design(bad)


@pytest.mark.parametrize("latency", [0, 1.5, True])
def test_a_bad_latency_is_refused(latency):
    with pytest.raises(HelmetAncError, match="latency"):
        design(appendix_a_model("fb"), options=DesignOptions(latency=latency))


def test_cli_design_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys):
    ff = tmp_path / "ff.json"
    appendix_a_model("ff").save(ff)
    out = tmp_path / "controller.json"
    assert main(["design", "--fb", str(ff), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "FB model" in err
    assert not out.exists()


@pytest.mark.parametrize("option, value, words", [("--latency", "0", ">= 1"), ("--latency", "two", "whole number"),
                                                   ("--latency", "-3", ">= 1"),
                                                   ("--max-amplification", "0", "at most 20"),
                                                   ("--max-amplification", "-1", "at most 20"),
                                                   ("--max-amplification", "21", "at most 20"),
                                                   ("--max-amplification", "six", "at most 20")])
def test_cli_design_bad_option_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, option, value, words):
    fb = tmp_path / "fb.json"
    appendix_a_model("fb").save(fb)
    out = tmp_path / "controller.json"
    with pytest.raises(SystemExit) as stop:
        main(["design", "--fb", str(fb), option, value, "-o", str(out)])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and option in err and words in err
    assert not out.exists()


@pytest.mark.parametrize("value", ["0", "2", "many", "8.5"])
def test_cli_design_bad_max_order_is_one_line_exit_2(tmp_path, capsys, value):
    fb = tmp_path / "fb.json"
    appendix_a_model("fb").save(fb)
    out = tmp_path / "controller.json"
    out.write_text("the user's own file")
    assert main(["design", "--fb", str(fb), "--max-order", value, "-o", str(out), "--force"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "max" in err and "order" in err and "Traceback" not in err
    assert out.read_text() == "the user's own file"


def test_cli_design_help_states_the_boards_latency(capsys):
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"default {BOARD_LATENCY_SAMPLES}: the board's control path" in text


def test_the_board_cost_counts_sections():
    """S order 7 and Q, W of order 22: 4 + 11 + 11 sections, as BENCHMARKS.md's measured control path
    (620 instructions for those orders; the estimate is within 5 % of it)."""
    from anc.design import BOARD_CYCLES_PER_SAMPLE, board_cost

    assert abs(board_cost(7, 22, 22) - 620) <= 0.05 * 620
    assert board_cost(7, 300, 300) > BOARD_CYCLES_PER_SAMPLE


def test_board_orders_fit_the_board_and_cut_only_what_does_not_fit():
    from anc.design import BOARD_CYCLES_PER_SAMPLE, board_cost, board_orders

    assert board_orders(7, 20, 30) == (20, 30)  # fits: nothing cut
    for s_order, q_order, w_order in [(7, 106, 322), (7, 157, 273), (24, 118, 0), (5, 0, 315), (300, 118, 273)]:
        q, w = board_orders(s_order, q_order, w_order)
        assert q <= q_order and w <= w_order
        assert (q == 0) == (q_order == 0) and (w == 0) == (w_order == 0)
        if s_order < 100:
            assert board_cost(s_order, q, w) <= BOARD_CYCLES_PER_SAMPLE


def test_the_drive_is_judged_against_the_fb_models_drive_limit():
    """A saturating driver (tanh, scale 0.01 FS) gives a drive limit; the drive's rms follows the filters
    linearly, so Q and W halved halve it, and the scale keeps the peaks at the limit."""
    import dataclasses

    from anc.controller import StateSpaceFilter
    from anc.design import DRIVE_CREST_FACTOR, drive_level
    from anc.disturbance import default_disturbance

    s_model = appendix_a_model("fb")
    q = StateSpaceFilter(np.array([[0.9]]), np.array([[1.0]]), np.array([[0.5]]), np.array([[0.2]]))
    disturbance = default_disturbance(s_model.fs, None)
    linear = drive_level(s_model, disturbance, q, None)
    assert linear["limit_fs"] is None and linear["scale"] == 1.0 and linear["rms_fs"] > 0
    half = StateSpaceFilter(q.A, q.B, 0.5 * q.C, 0.5 * q.D)
    assert drive_level(s_model, disturbance, half, None)["rms_fs"] == pytest.approx(0.5 * linear["rms_fs"], rel=1e-9)
    saturating = dataclasses.replace(s_model, input_nonlinearity_form={"kind": "tanh", "scale": 0.1 * linear["rms_fs"],
                                                                       "gain": 1.0, "offset": 0.0})
    judged = drive_level(saturating, disturbance, q, None)
    assert 0 < judged["limit_fs"] < judged["peak_fs"] == pytest.approx(DRIVE_CREST_FACTOR * linear["rms_fs"])
    assert judged["scale"] == pytest.approx(judged["limit_fs"] / judged["peak_fs"])


def test_a_saturating_driver_gets_q_scaled_to_its_drive_limit():
    """A tanh driver far below the drive the design asks: Q is scaled so the drive's peaks sit at the FB model's
    drive limit, the margins are those of the scaled loop, every band lies between the full filter's attenuation
    and none, and the note says so."""
    import dataclasses

    from anc.design import DesignOptions, drive_level, predict, scaled_filter
    from anc.disturbance import default_disturbance

    s_model = appendix_a_model("fb")
    saturating = dataclasses.replace(s_model, input_nonlinearity_form={"kind": "tanh", "scale": 1e-5, "gain": 1.0,
                                                                       "offset": 0.0})
    disturbance = default_disturbance(s_model.fs, None)
    options = DesignOptions(feedforward=False, max_order=6)
    limited = design(saturating, None, disturbance, options)
    drive = limited.provenance["drive"]
    assert 0 < drive["applied_scale"] < 0.5
    assert drive["peak_fs"] == pytest.approx(drive["limit_fs"], rel=1e-6)
    full = scaled_filter(limited.fb, 1.0 / drive["applied_scale"])
    assert drive_level(saturating, disturbance, full, None)["scale"] == pytest.approx(drive["applied_scale"], rel=1e-6)
    full_db = np.array(predict(s_model, disturbance, options.latency, full, None)[0]["fb"])
    limited_db = np.array(limited.predicted_attenuation_db["fb"])
    assert np.all(limited_db >= np.minimum(full_db, 0.0) - 1e-6)
    assert np.all(limited_db <= np.maximum(full_db, 0.0) + 1e-6)
    # The uncertainty disc r95 |G Q| <= 0.5 shrinks with the scale: the design's factor (at least about 1) over it.
    assert limited.margins["robustness_factor"] >= 0.95 / drive["applied_scale"]
    assert any(n.startswith("drive:") and "scaled by" in n and "--ignore-drive-limit" in n for n in limited.notes)


@pytest.mark.parametrize("limit", [0.0, -3.0, 25.0, float("nan"), True])
def test_a_bad_amplification_limit_is_refused(limit):
    with pytest.raises(HelmetAncError, match="max_amplification_db"):
        design(appendix_a_model("fb"), options=DesignOptions(max_amplification_db=limit))

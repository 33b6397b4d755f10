"""C of a controller (codegen.controller), its worst-case headroom, the sample-by-sample
twins of the generated filters (codegen.control_loop) and ``generate-firmware --controller``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from control_cases import board_controller

from anc.controller import Controller
from codegen.api import generate_controller_firmware
from codegen.build import build_host
from codegen.control_loop import FixedStepper, Float32Stepper
from codegen.controller import FILTER_NAMES, plan_controller
from codegen.errors import CodegenError
from codegen.reference import fixed_reference, float32_reference, to_q15
from helmet_anc.firmware_cli import main as firmware_main
from sysid.core import lti
from sysid.core.plants import appendix_a_model


@pytest.fixture(scope="module")
def controller():
    """A controller of the board's kind on the seed plants for the per-sample path (latency 2; made without a
    design, which takes minutes: ``control_cases.board_controller``)."""
    return board_controller(appendix_a_model("fb"), appendix_a_model("ff"), 2)


@pytest.fixture(scope="module")
def plan(controller):
    return plan_controller(controller)


@pytest.fixture(scope="module")
def generated(controller, tmp_path_factory):
    folder = tmp_path_factory.mktemp("ctl") / "out"
    return generate_controller_firmware(controller, folder)


def _edited(controller, **changes) -> Controller:
    data = controller.to_dict()
    data.update(changes)
    return Controller.from_dict(data)


@pytest.mark.parametrize("part", ["model", "fb", "ff"])
def test_steppers_equal_whole_signal_references(plan, part):
    """Block by block with the state carried over equals the references over the whole signal."""
    rng = np.random.default_rng(7)
    u = to_q15(rng.uniform(-0.6, 0.6, 1500))
    stepper = FixedStepper(plan.fixed(part))
    out = np.array(stepper.process(u[:700].tolist()) + stepper.process(u[700:].tolist()))
    np.testing.assert_array_equal(out, fixed_reference(plan.fixed(part), u))
    uf = u.astype(np.float32) / np.float32(32768.0)
    floating = Float32Stepper(plan.floating(part))
    out_f = np.array(floating.process(list(uf[:700])) + floating.process(list(uf[700:])), dtype=np.float32)
    np.testing.assert_array_equal(out_f.view(np.uint32), float32_reference(plan.floating(part), uf).view(np.uint32))


def test_generated_folder(generated, controller):
    names = set(generated.data["files"])
    assert names == {f"{name}_filter.{ext}" for name in FILTER_NAMES.values() for ext in "ch"} | {"controller_config.h"}
    config = (generated.outdir / "controller_config.h").read_text()
    assert "#define CTL_LATENCY_SAMPLES 2\n" in config
    assert "#define CTL_HAS_Q 1\n" in config and "#define CTL_HAS_W 1\n" in config
    manifest = json.loads((generated.outdir / "manifest.json").read_text())
    assert manifest["kind"] == "controller" and manifest["controller"]["latency_samples"] == 2
    assert manifest["controller"]["largest_control_block"] == 1
    assert set(manifest["filters"]) == set(FILTER_NAMES.values())
    # Regeneration into our own folder is allowed and gives the same files.
    again = generate_controller_firmware(controller, generated.outdir)
    assert again.data["files"] == generated.data["files"]


def test_feedback_only_controller(controller, tmp_path):
    manifest = generate_controller_firmware(_edited(controller, ff=None), tmp_path / "fb_only")
    assert "ctl_w_filter.c" not in manifest.data["files"]
    assert "#define CTL_HAS_W 0\n" in (tmp_path / "fb_only" / "controller_config.h").read_text()


def test_headroom_is_the_l1_norm(plan):
    """The worst-case gains of Q and W are sum |h| of the realised filters (the exact worst case;
    their clustered poles decay within 30000 samples), and the drive's is the sum of the two."""
    impulse = np.zeros(30000)
    impulse[0] = 1.0
    for part in ("fb", "ff"):
        r = plan.plans[part].realisation
        h = lti.simulate(r.A, r.B, r.C, r.D, impulse)
        assert plan.headroom[part]["l1_gain"] == pytest.approx(np.sum(np.abs(h)), rel=1e-6)
    drive = plan.headroom["drive"]
    assert drive["worst_case_peak"] == pytest.approx(plan.headroom["fb"]["l1_gain"] + plan.headroom["ff"]["l1_gain"])
    assert drive["saturates"] == (drive["worst_case_peak"] > 1.0)


def _host_and_worst_case(generated, plan, part: str, length: int):
    """(the part's generated filter built on the host, its impulse response over ``length`` samples, the
    full-scale Q15 input that attains its L1 gain at the last sample: the reversed impulse response's signs)."""
    name = FILTER_NAMES[part]
    folder = generated.outdir
    host = build_host(name, (folder / f"{name}_filter.h").read_text(), (folder / f"{name}_filter.c").read_text())
    r = plan.plans[part].realisation
    impulse = np.zeros(length)
    impulse[0] = 1.0
    h = lti.simulate(r.A, r.B, r.C, r.D, impulse)
    return host, h, np.where(h[::-1] >= 0, 32767, -32768).astype(np.int16)


@pytest.mark.parametrize("part", ["model", "fb", "ff"])
def test_worst_case_input_saturates_never_wraps(generated, plan, part):
    """The full-scale input that attains the L1 bound (the reversed signs of the impulse response),
    its negation and itself again: the generated C equals the saturating reference word for word
    (a wrap would differ by 65536); where no section can saturate it attains the linear bound, and
    the internal model (L1 gain 754) reaches the positive rail."""
    host, h, worst = _host_and_worst_case(generated, plan, part, 4000)
    worst = np.concatenate((worst, (-worst.astype(np.int32)).clip(-32768, 32767).astype(np.int16), worst))
    out = host.process_q15(worst)
    np.testing.assert_array_equal(out, fixed_reference(plan.fixed(part), worst))
    if plan.headroom[part]["safe_input_peak_dbfs"] >= 0.0:
        # No section can saturate: the output attains the linear bound.
        bound = 32768 * np.sum(np.abs(h))
        assert abs(int(out[h.size - 1]) - min(bound, 32767)) <= 0.01 * bound + 4
    elif part == "model":
        assert out[h.size - 1] == 32767


@pytest.mark.parametrize("part", ["model", "fb", "ff"])
def test_step_kernel_bit_exact_on_worst_case_inputs(generated, plan, part):
    """NAME_q15_step (the per-sample path's kernel) on the L1-attaining full-scale input, its
    negation and a full-scale square wave, alternating with process() blocks of 1, 4 and 37 samples
    on the same state (the two paths share it: section k's input history is section k - 1's
    output history): word for word the saturating reference."""
    host, h, worst = _host_and_worst_case(generated, plan, part, 3000)
    square = np.where((np.arange(3000) // 40) % 2 == 0, 32767, -32768).astype(np.int16)
    x = np.concatenate((worst, (-worst.astype(np.int32)).clip(-32768, 32767).astype(np.int16), square))
    pieces, start, k = [], 0, 0
    while start < x.size:
        stop = min(x.size, start + (300, 1, 300, 4, 300, 37)[k % 6])
        run = host.step_q15 if k % 2 == 0 else host.process_q15
        pieces.append(run(x[start:stop]))
        start, k = stop, k + 1
    out = np.concatenate(pieces)
    expected = fixed_reference(plan.fixed(part), x)
    np.testing.assert_array_equal(out, expected)
    if part == "model":
        assert expected.max() == 32767  # the internal model's output saturates on this input


def test_refusals(controller, tmp_path):
    with pytest.raises(CodegenError, match="latency_samples 1 is below the board's 2-sample control path"):
        plan_controller(_edited(controller, latency_samples=1))
    with pytest.raises(CodegenError, match="neither a feedback"):
        plan_controller(_edited(controller, ff=None, fb=None))
    with pytest.raises(CodegenError, match="variant refused: predicted SNR"):
        plan_controller(controller, min_snr=200.0)  # above float32's reach for any filter
    assert not (tmp_path / "refused").exists()


def test_cli(controller, tmp_path, capsys):
    path = tmp_path / "controller.json"
    controller.save(path)
    assert firmware_main(["--controller", str(path), "-o", str(tmp_path / "out"), "-q"]) == 0
    out = capsys.readouterr().out
    assert "worst-case headroom (latency 2 samples)" in out and "ctl_q (controller Q)" in out
    assert (tmp_path / "out" / "controller_config.h").is_file()
    assert firmware_main([str(path), "--controller", str(path), "-o", str(tmp_path / "two"), "-q"]) == 2
    assert "exactly one" in capsys.readouterr().err
    assert firmware_main(["--controller", str(path), "--fs", "48000", "-o", str(tmp_path / "fs"), "-q"]) == 2
    assert "--fs not used with --controller" in capsys.readouterr().err
    bad = tmp_path / "model.json"
    appendix_a_model("fb").save(bad)
    assert firmware_main(["--controller", str(bad), "-o", str(tmp_path / "bad"), "-q"]) == 2
    assert "not a controller file" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists() and not (tmp_path / "two").exists()

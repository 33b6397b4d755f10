"""The manifest states a model's saturation form as outside the generated linear filter."""

from dataclasses import replace

from codegen.plan import plan_firmware
from sysid.core.plants import appendix_a_model


def test_a_saturation_form_is_stated_as_not_generated():
    model = replace(appendix_a_model("ff"), input_nonlinearity_form={"kind": "tanh", "scale": 0.4})
    record = plan_firmware(model, variant="float", min_snr=0.0).record()["model"]
    assert record["input_nonlinearity_form"]["scale"] == 0.4
    assert record["input_nonlinearity_form"]["generated"].startswith("no")


def test_a_model_without_one_has_no_such_field():
    record = plan_firmware(appendix_a_model("ff"), variant="float", min_snr=0.0).record()["model"]
    assert "input_nonlinearity_form" not in record

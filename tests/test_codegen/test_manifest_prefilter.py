"""The manifest states a Wiener-Hammerstein model's pre-filter with its form, outside the generated linear filter."""

from dataclasses import replace

from codegen.plan import plan_firmware
from sysid.core.plants import appendix_a_model


def test_the_prefilter_is_stated_with_the_form():
    prefilter = {"kind": "highpass", "order": 1, "corner_hz": 2.0}
    model = replace(appendix_a_model("ff"), input_nonlinearity=[1.0, 0.3],
                    input_nonlinearity_form={"kind": "identity", "prefilter": prefilter})
    record = plan_firmware(model, variant="float", min_snr=0.0).record()["model"]
    assert record["input_nonlinearity_form"]["prefilter"] == prefilter
    assert record["input_nonlinearity_form"]["generated"].startswith("no")
    assert record["input_nonlinearity"] == [1.0, 0.3]

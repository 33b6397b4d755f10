"""The harmonics figure: the error spectrogram, and the measured harmonic levels against the model's."""

from dataclasses import replace

from effect_units import true_context

from report.diagnosis_figures import finding_figure
from sysid.estimation.spectra import estimate_spectra
from sysid.findings.nonlinearity import nonlinearity_finding


def test_the_measured_harmonics_are_drawn_against_the_models():
    ctx = true_context("ff", 5, ("input-nonlinearity:h3_db=-22,h2_db=-120,tanh=1",))
    found = nonlinearity_finding(ctx)
    figure = finding_figure(found, ctx, estimate_spectra(ctx.body, "h1"))
    assert len(figure.axes) == 2
    labels = [line.get_label() for line in figure.axes[1].get_lines()]
    assert any(label.startswith("H3 measured") for label in labels)
    assert any(label.startswith("H3 of the model") for label in labels)


def test_without_measured_harmonics_only_the_spectrogram():
    ctx = true_context("ff", 5, ("input-nonlinearity:h3_db=-22,h2_db=-120,tanh=1",))
    found = nonlinearity_finding(ctx)
    found = replace(found, evidence={})  # a finding of a linear sweep: Farina's separation does not apply
    figure = finding_figure(found, ctx, estimate_spectra(ctx.body, "h1"))
    assert len(figure.axes) == 1

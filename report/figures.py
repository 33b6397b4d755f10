"""Every figure of the report, one function each, for notebooks and scripts.

Each function returns a ``matplotlib.figure.Figure`` (created without pyplot, so it
never opens a window; display it in a notebook or save it with ``savefig``)::

    from report.figures import model_bode_figure, pole_zero_figure
    model_bode_figure(result.model, result.spectra, result.grid.chosen.gamma).savefig("bode.png")

Identification (seed chapter 3, appendices B and C): ``averaged_spectra_figure``,
``smoothed_estimates_figure``, ``singular_values_figure`` (with
``order_singular_values`` when no grid was run), ``rms_heatmap_figure``.
Model (seed chapter 4): ``model_bode_figure``, ``pole_zero_figure``,
``impulse_response_figure``. Validation (``sysid.validation.compare.Comparison``):
``sweep_prediction_figure``, ``error_bands_figure``, ``residual_correlation_figure``,
``coherence_figure``. Diagnosis: ``finding_figure``, ``refinement_figure``.
"""

from .diagnosis_figures import finding_figure, refinement_figure
from .identification_figures import (averaged_spectra_figure, order_singular_values, rms_heatmap_figure,
                                     singular_values_figure, smoothed_estimates_figure)
from .model_figures import impulse_response_figure, model_bode_figure, pole_zero_figure, transient_decay_db
from .validation_figures import (coherence_figure, error_bands_figure, residual_correlation_figure,
                                 sweep_prediction_figure)

__all__ = [
                                     "averaged_spectra_figure",
                                     "coherence_figure",
                                     "error_bands_figure",
                                     "finding_figure",
                                     "impulse_response_figure",
                                     "model_bode_figure",
                                     "order_singular_values",
                                     "pole_zero_figure",
                                     "refinement_figure",
                                     "residual_correlation_figure",
                                     "rms_heatmap_figure",
                                     "singular_values_figure",
                                     "smoothed_estimates_figure",
                                     "sweep_prediction_figure",
                                     "transient_decay_db",
]

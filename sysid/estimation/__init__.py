"""From recordings to a stable model: the estimators of identification, in pipeline order.

Non-parametric spectra (``spectra``), the pure delay (``delay``: the one place it is
decided), the frequency-domain subspace fit (``subspace``) and the seed's grid
(``grid``), output-error refinement on raw data (``output_error``,
``masked_output_error``), the order search (``order_search``), removal of degenerate
states (``reduction``) and the model's 95 % band (``uncertainty``). ``sysid.identify``
runs them in this order.
"""

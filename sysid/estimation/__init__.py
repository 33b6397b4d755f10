"""From recordings to a stable model: the estimators of identification, in pipeline order.

Non-parametric spectra (``spectra``), the pure delay (``delay/``: the one place it is
decided), the frequency-domain subspace fit (``subspace``) and the seed's grid
(``grid``), output-error refinement on raw data (``output_error`` with its data
``output_error_data``, its parametrisation ``modal_parametrisation`` and its solvers
``least_squares``; ``masked_output_error`` over recordings with gaps), the order
search (``order_search``), removal of degenerate states (``reduction``), the model's
95 % band (``uncertainty``), long responses (``long_response``: a least-squares FIR
and its frequency-limited balanced truncation) and the input polynomial of a
Hammerstein model (``input_polynomial``). ``sysid.identify`` runs them.
"""

"""The foundations every step of identification stands on.

Errors (``errors``), the one place files are written (``files``), every tunable
(``thresholds``), state-space numerics and all balancing (``lti``), frequency
responses and simulation (``response``), the model of a path and its JSON contract
(``model``), the structures effects add (``structures``), second-order sections
(``sections``), effect specifications (``effect_spec``), the seed's appendix-A plants
(``plants``) and measured responses as plants (``measured``, data in ``data/``).
Nothing here imports another folder of sysid.
"""

"""The foundations every step of identification stands on.

Errors (``errors``), the one place files are written (``files``), every tunable
(``thresholds``), state-space numerics and all balancing (``lti``), the model of a
path and its JSON contract (``model``), the structures effects add (``structures``),
second-order sections (``sections``), effect specifications (``effect_spec``) and the
seed's appendix-A plants (``plants``). Nothing here imports another folder of sysid.
"""

"""Firmware generation: identified helmet-anc models -> verified C filter code.

The steps flow one way, each importing only those before it (as acados' template
code generation): plan -> context (plain data) -> render -> build -> verify ->
manifest; ``api`` alone joins them. Below the steps (design reference, "Firmware
generation"):

``errors``      the exceptions; ``c_syntax`` identifiers, comment text and C literals;
``realise``     balanced realisation (``sysid.core.lti``), truncation, re-discretisation
                to the board rate;
``sections``    second-order sections: pairing, ordering, relative degree, scaling;
``fixedpoint``  Q15/Q31 design with per-section exponents; ``float32`` its float twin;
``reference``   bit-exact fixed-point, float32 and float64 Python references;
``cmsis``       tables and Python models of CMSIS-DSP's biquad kernels;
``noise``       predicted round-off noise, coefficient error and overflow margins;
``targets``     the kinds of generated code (generic Q15/float32, cmsis): one Target each,
                with what it needs (designs, references, templates, host runner, formats).

The steps:

``plan``        all of the above for one model, with the refusals (and the sections whose
                round-off dominates moved to the end where that halves it); ``controller`` the
                plans of a controller's S, Q and W (reads ``anc.controller``);
``context``     the plan as the plain dictionary the templates render;
``render``      the jinja2 templates (``codegen.templates``);
``build``       cffi host builds cached by source hash, and the cmsisdsp package's kernels;
``verify``      the C on the host against the references, on sweeps (the one reader of WAVs);
``manifest``    the manifest beside the code and the output folder it vouches for;
``api``         the entry points (``generate_firmware``, ``generate_controller_firmware``)
                of both command lines (``helmet_anc``).

Beside them: ``qemu_cost`` counts instructions per sample of the real Cortex-M4 ELF on
QEMU; ``control_loop`` is the control path's sample-by-sample Python twin (fixed point
and float32).
"""

__all__ = ["__version__"]

__version__ = "0.1.0"

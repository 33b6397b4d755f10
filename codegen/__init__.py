"""Firmware generation: identified helmet-anc models -> verified C filter code.

The pipeline (design reference, "Firmware generation"):

``realise``     balanced realisation, truncation, re-discretisation to the board rate;
``sections``    second-order sections: pairing, ordering, relative degree, scaling;
``fixedpoint``  Q15/Q31 design with per-section exponents; ``float32`` its float twin;
``cmsis``       tables and Python models of CMSIS-DSP's biquad kernels;
``noise``       predicted round-off noise, coefficient error and overflow margins;
``targets``     the registry of kinds of generated code (generic Q15/float32, cmsis) and
                what each needs: designs, references, templates, host runner, manifest;
``plan``        all of the above for one model, with the refusals;
``reference``   bit-exact fixed-point, float32 and float64 Python references;
``render``      jinja2 templates (``codegen.templates``) and atomic output directories;
``build``       cffi host builds cached by source hash; ``verify`` the C against the references;
``qemu_cost``   instructions per sample of the real Cortex-M4 ELF, counted on QEMU;
``controller``  a controller JSON (``anc``) -> C of its S, Q and W for the board's control path;
``control_loop`` the control path's sample-by-sample Python twin (fixed point and float32);
``api`` the Python front end (``generate_firmware``); the command line is ``helmet_anc``.
"""

__all__ = ["__version__"]

__version__ = "0.1.0"

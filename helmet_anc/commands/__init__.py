"""Subcommands of ``helmet-anc``, one module each.

Every module defines ``register(commands)``, which adds its subparser to the
argparse sub-parsers object and sets ``handler`` (args -> exit status), and an
``ORDER`` number that places it in the help listing.
"""

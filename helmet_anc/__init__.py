"""The command-line front end: ``helmet-anc`` and ``generate-firmware``.

It joins the packages (``sysid`` identification, ``codegen`` firmware generation)
and belongs to none of them: each subcommand is one module of ``helmet_anc.commands``.
"""

"""jinja2 templates of the generated C code (package data of ``codegen.templates``)."""

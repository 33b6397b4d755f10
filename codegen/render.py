"""Render the generated C from the prepared plain data with the jinja2 templates.

Third step of firmware generation (plan -> context -> render -> build -> verify ->
manifest): the templates in ``codegen.templates`` only lay out what
:mod:`codegen.context` prepared. Rendering runs in-process with ``StrictUndefined``
so a missing value fails instead of printing nothing. It reads the template names
of a target from :mod:`codegen.targets` and imports nothing of the other steps.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import jinja2

from .targets import get_target

__all__ = ["environment", "render_files", "render_template", "template_folder"]


def template_folder():
    """Where the .j2 templates are: the installed ``codegen.templates`` package, or, when
    ``codegen`` is imported from a source checkout (the distribution maps the top-level
    ``templates/`` folder onto that package), the checkout's ``templates/`` folder."""
    try:
        return resources.files("codegen.templates")
    except ModuleNotFoundError:
        return Path(__file__).resolve().parent.parent / "templates"


def environment() -> jinja2.Environment:
    """The jinja2 environment of the templates: strict about undefined values, no escaping, the
    templates' trailing newlines kept."""
    folder = template_folder()
    loader = jinja2.FunctionLoader(lambda template: folder.joinpath(template).read_text(encoding="utf-8"))
    return jinja2.Environment(loader=loader, undefined=jinja2.StrictUndefined, keep_trailing_newline=True,
                              autoescape=False)


def render_files(context: dict, target: str = "generic") -> dict[str, str]:
    """{file name: text} of NAME_filter.h and NAME_filter.c for the target's templates."""
    header, source = get_target(target).templates
    env = environment()
    name = context["name"]
    return {
        f"{name}_filter.h": env.get_template(header).render(context),
        f"{name}_filter.c": env.get_template(source).render(context),
    }


def render_template(template: str, context: dict) -> str:
    """The text of one template (e.g. ``controller_config.h.j2``) rendered with ``context``."""
    return environment().get_template(template).render(context)

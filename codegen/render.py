"""Render the generated C from prepared data, and write output directories atomically.

Python prepares every number and every C expression fragment (:func:`build_context`);
the jinja2 templates in ``codegen.templates`` only lay them out. Rendering runs
in-process with ``StrictUndefined`` so a missing value fails instead of printing
nothing. Identifiers are validated before they reach a template.
"""

from __future__ import annotations

import math
import os
import re
from importlib import resources
from pathlib import Path

import jinja2
import numpy as np

from sysid.core.files import OutputRefused, write_output_directory

from . import __version__
from .errors import InvalidNameError, OutputError
from .fixedpoint import FixedDesign
from .float32 import FloatDesign
from .targets import get_target

__all__ = [
    "C_KEYWORDS",
    "C_LIBRARY_NAMES",
    "build_context",
    "comment_text",
    "float_literal",
    "int_literal",
    "render_files",
    "validate_name",
    "write_directory",
]

# C99 and C11 keywords plus names the generated code or its headers already use.
C_KEYWORDS = frozenset(
    ["auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else", "enum", "extern", "float", "for", "goto", "if", "inline", "int", "long", "register", "restrict", "return", "short", "signed", "sizeof", "static", "struct", "switch", "typedef", "union", "unsigned", "void", "volatile", "while", "_Bool", "_Complex", "_Imaginary", "_Alignas", "_Alignof", "_Atomic", "_Generic", "_Noreturn", "_Static_assert", "_Thread_local", "asm", "typeof", "main", "NULL", "errno", "assert", "bool", "true", "false"]
)
# Names of the C standard library (C99 clause 7) a prefix must not take: the generated
# identifiers and macros start with it, and a user's translation unit includes these headers.
C_LIBRARY_NAMES = frozenset(
    "abort abs acos asctime asin atan atan2 atexit atof atoi atol atoll bsearch calloc ceil clearerr clock "
    "cos cosh ctime difftime div exit exp fabs fclose feof ferror fflush fgetc fgetpos fgets floor fmod fopen "
    "fprintf fputc fputs fread free freopen frexp fscanf fseek fsetpos ftell fwrite getc getchar getenv gets "
    "gmtime isalnum isalpha isblank iscntrl isdigit isgraph islower isprint ispunct isspace isupper isxdigit "
    "labs ldexp ldiv llabs lldiv localeconv localtime log log10 longjmp lrint lround malloc mblen mbstowcs "
    "mbtowc memchr memcmp memcpy memmove memset mktime modf offsetof perror pow printf putc putchar puts qsort "
    "raise rand realloc remove rename rewind round scanf setbuf setjmp setlocale setvbuf signal sin sinh "
    "snprintf sprintf sqrt srand sscanf strcat strchr strcmp strcoll strcpy strcspn strerror strftime strlen "
    "strncat strncmp strncpy strpbrk strrchr strspn strstr strtod strtof strtok strtol strtold strtoll strtoul "
    "strtoull strxfrm system tan tanh time tmpfile tmpnam tolower toupper ungetc va_arg va_copy va_end "
    "va_start vfprintf vprintf vsnprintf vsprintf wcstombs wctomb stdin stdout stderr size_t ptrdiff_t "
    "wchar_t FILE EOF BUFSIZ CHAR_BIT INT_MAX INT_MIN SIZE_MAX".split()
)
# C99 7.26 future library directions: reserved prefixes (is*, to*, str*, mem*, wcs*, E<digit or capital>,
# SIG*, LC_*, int*_t / uint*_t).
_RESERVED = re.compile(r"(is|to|str|mem|wcs)[a-z]|E[0-9A-Z]|SIG[A-Z_]|LC_[A-Z]|u?int.*_t\Z")
_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}\Z")
# Characters model text may keep in a C comment: no backslash (line splicing), no '?' (trigraphs),
# no '*' or '/' pairs (comment delimiters), no newline.
_COMMENT_UNSAFE = re.compile(r"[^A-Za-z0-9 .,:=+_()\[\]-]")


def comment_text(value) -> str:
    """``value`` as text safe inside a C comment: every character outside a small whitelist
    (letters, digits, space and ``.,:=+_-()[]``) becomes ``_``, so model text cannot end the
    comment, splice lines (backslash-newline) or form trigraphs."""
    return _COMMENT_UNSAFE.sub("_", str(value))[:200]


def validate_name(name: str) -> str:
    """Return ``name`` if it is a safe prefix for C identifiers, else raise InvalidNameError.

    Accepted: a lower-case letter then up to 31 lower-case letters, digits or
    underscores (C99 keeps 31 significant characters of external names; macros
    use the name in capitals, so only lower case keeps them unique per name), not
    a C keyword, a standard-library name or a prefix C99 7.26 reserves. A leading
    underscore is refused because such names are reserved to the implementation.
    """
    if not isinstance(name, str) or not _NAME.match(name):
        shown = repr(comment_text(name)) if isinstance(name, str) and len(name) < 60 else "given name"
        raise InvalidNameError(
            f"--name must be a lower-case C identifier (a letter, then up to 31 lower-case letters, digits or "
            f"underscores; the macros use it in capitals, so 'ff' and 'FF' would collide); found {shown}"
        )
    if name in C_KEYWORDS or name in C_LIBRARY_NAMES or _RESERVED.match(name):
        raise InvalidNameError(f"--name must not be a C keyword, a C library name or a reserved prefix "
                               f"(is*, to*, str*, mem*, wcs*, int*_t); found {name!r}")
    return name


def float_literal(value: float) -> str:
    """float32 literal that reads back to the same float32 ('%.9g' round-trips single precision)."""
    text = format(float(value), ".9g")
    if not any(ch in text for ch in ".en"):
        text += ".0"
    return text + "f"


def int_literal(value: int, ctype: str = "INT64_C") -> str:
    """Exact integer literal; the int64 macro keeps the constant's type explicit under -Wconversion."""
    return f"{ctype}({int(value)})"


def _product(state: str, coefficient: int, table: list | None = None) -> str:
    """A 32 x 32 -> 64-bit product the compiler maps to SMULL/SMLAL: with the coefficient as a
    literal, or, given ``table``, appended to it and read as ``c[index]``."""
    if table is None:
        return f"(int64_t){state} * {int_literal(coefficient, 'INT32_C')}"
    table.append(int(coefficient))
    return f"(int64_t){state} * c[{len(table) - 1}]"


def _fixed_step(section, quantiser: str, x: tuple[str, str, str], y: tuple[str, str], out: str,
                table: list | None = None) -> dict:
    """One sample of a section with the state variables in the given roles: x = (x[n], x[n-1],
    x[n-2]), y = (y[n-1], y[n-2]); the output goes to ``out``. With ``table`` the coefficients
    are read from the table (see :func:`_product`)."""
    # Feedback first: the table then holds the coefficients in the order of the products below.
    feedback = [_product(state, a, table) for state, a in zip(y, section.a) if a]
    forward = [_product(state, b, table) for state, b in zip(x, section.b) if b]
    if section.feedback_shift and feedback:
        # The feedback's extra d fractional bits: its product sum is shifted down on its own.
        return {"start": f"(({' + '.join(feedback)}) >> {section.feedback_shift}) + {quantiser}", "terms": forward,
                "input": x[0], "out": out}
    return {"start": quantiser, "terms": feedback + forward, "input": x[0], "out": out}


def _fixed_sections(design: FixedDesign) -> list[dict]:
    """Per section: the four unrolled steps and the single step of its sample loop, and the clamp.

    The single steps (the per-sample kernel, all sections in one function) read their
    coefficients from one table (``single.coefficients`` are each section's entries, in table
    order): loaded through one pointer they cost the same loads as literals but leave gcc the
    registers a literal pool's addressing takes (emulated Cortex-M4, seed plants' control path: 676 -> 620
    instructions per sample).

    The loop takes four samples per pass (as CMSIS-DSP's DF1 kernels do); each new input is
    read into the variable of the oldest input and each output replaces the older output, so
    the states change roles instead of being copied (after four samples the outputs are back
    in their roles and the inputs need x2 = x1, x1 = x0, fixed in the template).
    """
    rows = []
    quantiser = "(int64_t)e" if design.quantiser == "efb" else "INT64_C(2147483648)"
    roles = [(("x0", "x1", "x2"), ("y1", "y2"), "y2"), (("x2", "x0", "x1"), ("y2", "y1"), "y1"),
             (("x1", "x2", "x0"), ("y1", "y2"), "y2"), (("x0", "x1", "x2"), ("y2", "y1"), "y1")]
    table = []
    for k, section in enumerate(design.sections):
        first = len(table)
        single = _fixed_step(section, f"(int64_t)s->e[{k}]" if design.quantiser == "efb" else quantiser,
                             ("v", "x1", "x2"), ("y1", "y2"), "out", table)
        single["coefficients"] = [int_literal(c, "INT32_C") for c in table[first:]]
        rows.append({
            "index": k,
            "order": section.order,
            "guard": section.guard,
            "feedback_shift": section.feedback_shift,
            "quad": [{**_fixed_step(section, quantiser, x, y, out), "offset": offset}
                     for offset, (x, y, out) in enumerate(roles)],
            "tail": _fixed_step(section, quantiser, ("x0", "x1", "x2"), ("y1", "y2"), "y0"),
            # The short-block and per-sample path: one sample through every section; the input history x1, x2
            # is the previous section's output history (the template keeps it in registers).
            "single": single,
            "bits": 32 - section.guard,
            "unit": str(1 << section.guard),
        })
    return rows


def _float_sections(design: FloatDesign) -> list[dict]:
    rows = []
    for k, section in enumerate(design.sections):
        terms = [f"{float_literal(b)} * " + (f"h{k}_{lag}" if lag else f"v{k}") for lag, b in enumerate(section.b) if b]
        feedback = [f"{float_literal(c)} * h{k + 1}_{lag + 1}" for lag, c in enumerate(section.c) if c]
        rows.append({"index": k, "order": section.order, "forward": " + ".join(terms) if terms else "0.0f",
                     "feedback": feedback})
    return rows


def _dc_gain(cascade) -> float:
    """Gain of the cascade at z = 1: prod_k sum(b_k) / sum(a_k) (poles at z = 1 are refused earlier)."""
    return float(np.prod([sum(s.b) / sum(s.a) for s in cascade.sections]))


def _dc_headroom_lsb(dc_gain: float) -> int:
    """Largest constant Q15 input (LSB) whose output magnitude stays at most 32767."""
    return 32767 if abs(dc_gain) <= 1.0 else int(32767 // abs(dc_gain))


def build_context(*, name: str, provenance: dict, fs: float, cascade, variants, fixed: FixedDesign | None,
                  floating: FloatDesign | None, cmsis=None, target: str = "generic") -> dict:
    """The plain dictionary the templates render: names, literals, sizes, flags.

    ``variants`` lists the variants to emit ('q15', 'float'); ``fixed``/``floating``
    carry the generic target's designs, ``cmsis`` the cmsis target's tables; the
    target (:mod:`codegen.targets`) adds the fields only its templates use.
    """
    validate_name(name)
    # Model text reaches the C only through comment_text (a whitelist).
    hash_text = comment_text(provenance.get("hash", "unknown"))
    banner = (f"Generated by helmet-anc codegen {__version__} from model {hash_text}; do not edit.")
    gamma = provenance.get("gamma")
    described = comment_text(f"path {provenance.get('path')}, file {provenance.get('file') or '(in memory)'}, "
                             f"sha256 {hash_text}, gamma {gamma if gamma is not None else 'n/a'}, "
                             f"order {provenance.get('order')}")
    poly_fixed = list(fixed.polynomial) if fixed is not None and fixed.polynomial else []
    poly_float = list(floating.polynomial) if floating is not None and floating.polynomial else []
    delay = (fixed or floating or cmsis).delay
    fixed_rows = _fixed_sections(fixed) if fixed is not None else []
    context = {
        "banner": banner,
        "provenance": described,
        "name": name,
        "NAME": name.upper(),
        "guard": f"HELMET_ANC_{name.upper()}_FILTER_H",
        "path_label": comment_text(provenance.get("path", "unknown")).upper(),
        "fs_text": format(fs, ".6g"),
        "fs_int": round(fs),
        "sections": [{"order": s.order} for s in cascade.sections],
        "nodes": list(range(len(cascade.sections) + 1)),
        "delay": delay,
        "scaling": cascade.scaling,
        "output_peak_gain": format(cascade.node_gains[-1], ".4g"),
        "dc_gain": float_literal(_dc_gain(cascade)),
        "dc_headroom_lsb": _dc_headroom_lsb(_dc_gain(cascade)),
        "output_margin_db": format(-20 * math.log10(cascade.node_gains[-1]), ".1f"),
        "headroom_db": format(cascade.headroom_db, "g"),
        "has_float": "float" in variants,
        "has_fixed": "q15" in variants,
        "efb": fixed is not None and fixed.quantiser == "efb",
        "quantiser_text": ("the previous sample's residue e = acc mod 2^32 (first-order error feedback of the "
                           "truncation residue)" if fixed is not None and fixed.quantiser == "efb"
                           else "2^31 (rounding to nearest)"),
        "polynomial": bool(poly_fixed or poly_float),
        "fixed_poly": [int_literal(p) for p in poly_fixed],
        "fixed_poly_rest": [int_literal(p) for p in poly_fixed[-2::-1]],
        "poly_exponent": fixed.polynomial_exponent if fixed is not None else 0,
        "float_poly": [float_literal(a) for a in poly_float],
        "float_poly_rest": [float_literal(a) for a in poly_float[-2::-1]],
        "fixed_sections": fixed_rows,
        # The per-sample kernel's coefficient table (none when every coefficient is zero).
        "single_coefficients": any(row["single"]["coefficients"] for row in fixed_rows),
        # One saturation function per output width the sections use (SSAT takes the width as an immediate).
        "saturations": [{"bits": bits, "top": str(2 ** (bits - 1) - 1)}
                        for bits in sorted({32 - s.guard for s in fixed.sections if s.guard})] if fixed is not None else [],
        "float_sections": _float_sections(floating) if floating is not None else [],
    }
    context.update(get_target(target).context({"fixed": fixed, "floating": floating, "cmsis": cmsis}))
    return context


def template_folder():
    """Where the .j2 templates are: the installed ``codegen.templates`` package, or, when
    ``codegen`` is imported from a source checkout (the distribution maps the top-level
    ``templates/`` folder onto that package), the checkout's ``templates/`` folder."""
    try:
        return resources.files("codegen.templates")
    except ModuleNotFoundError:
        return Path(__file__).resolve().parent.parent / "templates"


def _environment() -> jinja2.Environment:
    folder = template_folder()
    loader = jinja2.FunctionLoader(lambda template: folder.joinpath(template).read_text(encoding="utf-8"))
    return jinja2.Environment(loader=loader, undefined=jinja2.StrictUndefined, keep_trailing_newline=True,
                              autoescape=False)


def render_files(context: dict, target: str = "generic") -> dict[str, str]:
    """{file name: text} of NAME_filter.h and NAME_filter.c for the target's templates."""
    header, source = get_target(target).templates
    env = _environment()
    name = context["name"]
    return {
        f"{name}_filter.h": env.get_template(header).render(context),
        f"{name}_filter.c": env.get_template(source).render(context),
    }


def write_directory(outdir: str | os.PathLike, files: dict[str, str | bytes], force: bool = False) -> Path:
    """Write ``files`` (``manifest.json`` among them) as the generated-code folder ``outdir``.

    The rules are those of every helmet-anc output folder (:mod:`sysid.core.files`): a
    new folder appears complete or not at all; an existing one is written only when
    it holds nothing but a previous output our manifest proves, or with ``force``,
    and only files a manifest of ours lists are ever removed.
    """
    from .api import MANIFEST_FORMAT

    try:
        return write_output_directory(outdir, files, "manifest.json", MANIFEST_FORMAT, force=force)
    except OutputRefused as exc:
        raise OutputError(str(exc)) from None

"""C syntax of the generated code: safe identifiers, comment text and exact literals.

A leaf of firmware generation: it imports nothing of ``codegen`` but its errors. The
context (:mod:`codegen.context`) and the target descriptions (:mod:`codegen.targets`)
write every name and number of the C through these functions, so a model's text or
a user's ``--name`` cannot change the code's meaning.
"""

from __future__ import annotations

import re

from .errors import InvalidNameError

__all__ = ["C_KEYWORDS", "C_LIBRARY_NAMES", "comment_text", "float_literal", "int_literal", "validate_name"]

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

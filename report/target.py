"""Where a report is written: the file a ``--report``/``write_report`` path names.

A path naming an existing folder, or ending with a path separator, is a folder: the report is
``<folder>/<fb|ff>-report.html`` in it, and a folder that does not exist is refused (never a file
written under the folder's name: ``--report reps/`` once wrote a file ``reps``). Any other path
is the report file itself.
"""

from __future__ import annotations

import os
from pathlib import Path

from sysid.core.errors import HelmetAncError

__all__ = ["report_file"]


def report_file(path, kind: str) -> Path:
    """The report file ``path`` names for a model of path ``kind`` (fb or ff); HelmetAncError for a
    folder (trailing separator) that does not exist."""
    text = os.fspath(path)
    target = Path(text)
    if target.is_dir():
        return target / f"{kind}-report.html"
    if text.endswith(("/", os.sep)):
        raise HelmetAncError(f"{text}: folder {target} does not exist; create it first, or give a file name "
                             f"(e.g. {target}.html)")
    return target

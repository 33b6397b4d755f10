"""The repository's root folder, for tests that read its files (README, firmware, docs)."""

from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

"""Wording shared by every message acslam prints."""

from __future__ import annotations


def plural(count: int, noun: str, plural_form: str | None = None) -> str:
    """``count`` and ``noun``, the noun in the plural unless the count is one: "1 robot",
    "3 robots", "2 start poses"; nouns that do not just add an s give ``plural_form``."""
    return f"{count} {noun if count == 1 else plural_form or noun + 's'}"

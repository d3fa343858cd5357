"""Periodic yarn patterns: the data model, weave drafts, knits and the ``.pyp`` format."""

from .base import FAMILIES, PatternError, Yarn, YarnPattern
from .knit import STITCHES, knit
from .pyp import format_pyp, parse_pyp, read_pyp, write_pyp
from .weave import DRAFTS, weave

__all__ = [
    "DRAFTS",
    "FAMILIES",
    "PatternError",
    "STITCHES",
    "Yarn",
    "YarnPattern",
    "format_pyp",
    "knit",
    "parse_pyp",
    "read_pyp",
    "weave",
    "write_pyp",
]

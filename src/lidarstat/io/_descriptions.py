"""Short descriptions of per-point fields, written with LAS extra bytes.

A LAS extra-bytes record has a 32-byte description beside the field's name. The modules
that compute fields register their documented meanings here (``name -> (dtype,
description)`` tables); the LAS writer asks :func:`field_description` for every extra-bytes
field it adds, and a field nobody registered gets a generic description.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

#: Bytes of the description field of a LAS extra-bytes record.
DESCRIPTION_BYTES = 32

_REGISTERED: dict[str, str] = {}
# Words (besides bare numbers) a shortened description should not end on.
_DANGLING = {"a", "along", "an", "and", "at", "between", "by", "for", "in", "of", "on", "or",
             "the", "to", "with"}
_ARTICLES = {"a", "an", "the"}


def register_field_descriptions(table: Mapping[str, object]) -> None:
    """Record the documented meaning of per-point fields.

    Parameters
    ----------
    table : mapping of str to str or tuple
        Field name -> description, or -> ``(dtype, description)`` as in the ``FIELDS``
        tables of :mod:`lidarstat.features`. A name already registered keeps its first
        description (methods that share a field, such as ``neighbors`` or ``NormalX``,
        describe it alike).
    """
    for name, entry in table.items():
        text = entry[-1] if isinstance(entry, tuple) else entry
        _REGISTERED.setdefault(str(name), str(text))


def shorten(text: str, limit: int = DESCRIPTION_BYTES) -> str:
    """`text` as ASCII of at most `limit` bytes.

    Parenthesised asides go first, then articles, then whole words from the end (never
    ending on a preposition or a bare number); a single word longer than `limit` is cut.
    """
    text = " ".join(text.encode("ascii", "replace").decode("ascii").split())
    if len(text) <= limit:
        return text
    text = " ".join(re.sub(r"\s+\([^)]*\)", "", text).split())
    if len(text) > limit:
        text = " ".join(w for w in text.split() if w.lower() not in _ARTICLES)
    while len(text) > limit and re.search(r"[ ,]", text):
        text = re.sub(r"[ ,][^ ,]*$", "", text)
        while re.search(r"[ ,]", text) and (_last(text) in _DANGLING or _last(text).isdigit()):
            text = re.sub(r"[ ,][^ ,]*$", "", text)
        text = text.rstrip(",;: ")
    return text[:limit]


def _last(text: str) -> str:
    return re.split(r"[ ,]", text)[-1]


def field_description(name: str) -> str:
    """Description of the field `name`, at most 32 ASCII bytes.

    The registered (documented) meaning when there is one, else ``"lidarstat field
    <name>"`` (``"lidarstat <name>"`` or the name itself when that is too long).
    """
    text = _REGISTERED.get(name)
    if text:
        return shorten(text)
    generic = [f"lidarstat field {name}", f"lidarstat {name}"]
    return next((g for g in generic if len(g) <= DESCRIPTION_BYTES), shorten(name))

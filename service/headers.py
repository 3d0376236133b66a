"""HTTP headers the service and its client share (no dependency: both import it).

A file answer (``POST /v1/enhance``, ``POST /v1/render``) carries what the command line prints as
``depict: warning: ...`` (NaN pixels read as holes, a render that shows nothing, triangles left
out) as one :data:`WARNING` header per warning. Header values are ASCII: each warning is
percent-encoded (RFC 3986) except for printable ASCII, so it reads as it is in ``curl -i`` and
:func:`warning_text` gives it back exactly (``urllib.parse.unquote``).
"""

from __future__ import annotations

from urllib.parse import quote, unquote

#: One header per warning of a file answer.
WARNING = "Depict-Warning"

#: Printable ASCII but ``%``: kept as it is in a header value.
_KEPT = "".join(chr(c) for c in range(0x20, 0x7F) if chr(c) not in "%")


def warning_value(text: str) -> str:
    """``text`` as a :data:`WARNING` header value."""
    return quote(text, safe=_KEPT)


def warning_text(value: str) -> str:
    """The warning a :data:`WARNING` header value holds."""
    return unquote(value)

"""The one error a capture raises: the file, the field, what is wrong."""

from __future__ import annotations

import pydantic

from .._rules import one_line, shorten

__all__ = ["CAPTURE_FILE", "CaptureError", "pydantic_error"]

CAPTURE_FILE = "capture.toml"


class CaptureError(ValueError):
    """A capture that cannot be used: one line naming the file and the field or value.

    Attributes
    ----------
    file
        The file at fault (``capture.toml`` or an image), relative to the capture folder.
    field
        The field (``camera.focal_px``) or ``None``.
    """

    def __init__(self, file: str, field: str | None, message: str):
        # Names read from the input (a TOML key, an image path) may hold line breaks: shown escaped, on one line.
        self.file = one_line(file)
        self.field = None if field is None else one_line(field)
        self.message = shorten(one_line(message))
        where = f"{self.file}: {self.field}: " if field else f"{self.file}: "
        super().__init__(where + self.message)


def _fmt_loc(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def pydantic_error(err: pydantic.ValidationError, file: str) -> CaptureError:
    first = err.errors()[0]
    loc = [p for p in first["loc"] if not (isinstance(p, str) and ("[" in p or "-" in p))]
    field = _fmt_loc(loc)
    msg = first["msg"]
    if first["type"] == "missing":
        return CaptureError(file, field, "required field is missing")
    if first["type"] == "extra_forbidden":
        return CaptureError(file, field, "unknown field (check its spelling and section)")
    # pydantic prefixes the messages of custom validators with "Value error, " / "Assertion failed, ".
    for prefix in ("Value error, ", "Assertion failed, "):
        msg = msg.removeprefix(prefix)
    got = first.get("input")
    if first["type"] in ("float_type", "int_type") and isinstance(got, bool):
        return CaptureError(file, field, f"expected a number, not the boolean {str(got).lower()}")
    more = len(err.errors()) - 1
    tail = f" (and {more} more problem{'s' if more > 1 else ''})" if more else ""
    # A whole section as the input (a check across its fields) says nothing the message does not.
    shown = "" if isinstance(got, dict) else f", got {got!r}"
    return CaptureError(file, field, f"{msg}{shown}{tail}")

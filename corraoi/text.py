"""Names are data: text from files made safe for the terminal and for file names.

An instance, policy or plug-in name comes from a file someone else wrote. Before it is
printed it goes through :func:`safe_text` (control codes and invisible format characters
shown as escapes, so an ANSI sequence in a name cannot recolour, move or clear the
terminal); before it becomes part of a file name it goes through :func:`safe_name` (a
small alphabet without path separators, so ``../../x`` cannot leave the output folder).
"""

from __future__ import annotations

import re
import unicodedata

#: Characters a name derived from data may keep in a file name.
NAME_ALPHABET = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789._+-"
#: The longest file-name component made from a name (most file systems allow 255 bytes).
MAX_NAME = 120
_UNSAFE_NAME = re.compile(r"[^A-Za-z0-9._+\-]+")


def safe_text(text: object, *, newlines: bool = False) -> str:
    """``text`` with every control or format character written as an escape (``\\x1b``).

    Printable text is returned unchanged. ``newlines`` keeps ``\\n`` (for multi-line
    output built by the program itself); by default a newline is escaped too, so that a
    message stays on one line.
    """
    s = str(text)
    if s.isprintable():
        return s
    out = []
    for ch in s:
        if ch == "\n" and newlines:
            out.append(ch)
        elif ch == " " or ch.isprintable():
            out.append(ch)
        elif unicodedata.category(ch) in ("Zs",):
            out.append(" ")
        else:
            code = ord(ch)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000
                       else f"\\U{code:08x}")  # fmt: skip
    return "".join(out)


def safe_name(name: object, *, default: str = "_") -> str:
    """A file-name component made from ``name``: only :data:`NAME_ALPHABET`, no leading dot,
    at most :data:`MAX_NAME` characters. Runs of other characters become one ``_``.

    ``safe_name("../../x") == "__.._x"``; ``safe_name("cucb") == "cucb"``.
    """
    s = _UNSAFE_NAME.sub("_", str(name))
    if s.startswith("."):
        s = "_" + s.lstrip(".")
    s = s[:MAX_NAME]
    return s or default


__all__ = ["MAX_NAME", "NAME_ALPHABET", "safe_name", "safe_text"]

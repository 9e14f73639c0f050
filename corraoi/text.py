"""Names are data: text from files made safe for the terminal and for file names.

An instance, policy or plug-in name comes from a file someone else wrote. Before it is
printed it goes through :func:`safe_text` (control codes and invisible format characters
shown as escapes, so an ANSI sequence in a name cannot recolour, move or clear the
terminal); before it becomes part of a file name it goes through :func:`safe_name` (letters,
digits and a little punctuation, no path separators, so ``../../x`` cannot leave the output
folder; a short hash of the name where that loses information, so that two names never
share a file).
"""

from __future__ import annotations

import hashlib
import re
import unicodedata
from collections.abc import Iterable
from itertools import groupby

#: Characters besides Unicode letters, marks and digits that a name may keep in a file name.
NAME_PUNCTUATION = "._+-"
#: The longest file-name component made from a name, in UTF-8 bytes (file systems allow 255
#: bytes; this leaves room for the suffixes and the other parts of a file name).
MAX_NAME = 120
#: Hex digits of the hash appended to a name that lost information on its way to a file name.
HASH_DIGITS = 8
_EXTENSION = r"\.[A-Za-z0-9]{1,8}$"
#: What a hashed name ends with: a name that already ends like that is hashed too.
_HASHED = re.compile(rf"-[0-9a-f]{{{HASH_DIGITS}}}(?:{_EXTENSION[:-1]})?$")


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
    """A file-name component made from ``name``, NFC-normalised: Unicode letters, marks and
    digits kept as they are, with :data:`NAME_PUNCTUATION`; every run of other characters
    (``/``, spaces, control codes, NUL, ...) becomes one ``_``, a leading dot ``_``, and the
    result is at most :data:`MAX_NAME` bytes in UTF-8.

    Where that loses information (a character replaced, the name cut, an empty name), the
    first :data:`HASH_DIGITS` hex digits of the name's sha256 are added (``-1a2b3c4d``, before
    an extension such as ``.py``), as they are to a name that already ends like that: two
    different names never give one file name (short of a hash collision), and a name that is
    safe as it is stays unchanged.

    ``safe_name("cucb-I1-s0") == "cucb-I1-s0"``; ``safe_name("東京") == "東京"``;
    ``safe_name("../../x")`` is ``"__.._x-"`` and a hash.
    """
    text = unicodedata.normalize("NFC", str(name))
    s = "".join("".join(run) if keep else "_" for keep, run in groupby(text, _keeps))
    if s.startswith("."):
        s = "_" + s.lstrip(".")
    if s != text or not s or _HASHED.search(s) or len(s.encode()) > MAX_NAME:
        digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()
        ext = re.search(_EXTENSION, s)  # kept last: a plug-in's copy stays a .py file
        stem, suffix = (s[: ext.start()], ext.group()) if ext and ext.start() > 0 else (s, "")
        tail = f"-{digest[:HASH_DIGITS]}{suffix}"
        s = _cut(stem or default, MAX_NAME - len(tail)) + tail
    return s


def _keeps(ch: str) -> bool:
    return ch in NAME_PUNCTUATION or unicodedata.category(ch)[0] in "LMN"


def _cut(s: str, limit: int) -> str:
    """``s`` cut to at most ``limit`` UTF-8 bytes, on a character boundary."""
    return s.encode()[:limit].decode(errors="ignore")


def split_list(values: Iterable[str]) -> list[str]:
    """Comma lists and repeated options (``-i I1,I2 -i I3``), in order, without repeats or
    empty items."""
    out: list[str] = []
    for value in values:
        for part in str(value).split(","):
            item = part.strip()
            if item and item not in out:
                out.append(item)
    return out


__all__ = ["HASH_DIGITS", "MAX_NAME", "NAME_PUNCTUATION", "safe_name", "safe_text", "split_list"]

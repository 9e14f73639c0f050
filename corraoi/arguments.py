"""Arguments checked at the door: the one set of checks every Python call of corraoi runs on
what it is given (the face's ``record``, ``sweep``, ``load``, ``compare``, ``diff``, ``show``,
the ``Run`` and ``Sweep`` methods; a ``Param``, a policy class's declarations; the testing
helpers), before any work.

Each check returns the value as the call uses it (an ``int`` for an integer, a tuple of
names, ...) or raises the error of the argument's ``kind`` -- ``PolicyError``,
``InstanceError``, ``ConfigError``, ``OutputError`` or ``UsageError`` -- in its variant that
is also a ``TypeError`` (a wrong type) or a ``ValueError`` (a value not accepted): see
:func:`wrong_type` and :func:`wrong_value`. Each message is one line that names the argument,
the value given and what is accepted.

The rules, once: an integer is an ``int`` (or a numpy integer, or a float with an integral
value such as ``1e4``), never a ``bool`` and never a float truncated (``2.5`` is refused); a
number is an ``int`` or ``float`` (numpy's too), never a ``bool``; a flag is ``True`` or
``False``; a ``str`` where names are expected is one name, never its letters.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

from .errors import (
    ArgumentTypeError,
    ArgumentValueError,
    ConfigError,
    ConfigTypeError,
    ConfigValueError,
    InstanceError,
    InstanceTypeError,
    InstanceValueError,
    OutputError,
    OutputTypeError,
    OutputValueError,
    PolicyError,
    PolicyTypeError,
    PolicyValueError,
    UsageError,
)

#: The kinds of a wrong argument, each with its TypeError and ValueError variants.
KINDS: Mapping[type[UsageError], tuple[type[UsageError], type[UsageError]]] = {
    UsageError: (ArgumentTypeError, ArgumentValueError),
    PolicyError: (PolicyTypeError, PolicyValueError),
    InstanceError: (InstanceTypeError, InstanceValueError),
    ConfigError: (ConfigTypeError, ConfigValueError),
    OutputError: (OutputTypeError, OutputValueError),
}
#: The longest shown form of a value given (a long list or array is cut).
SHOWN = 60

T = TypeVar("T")


def shown(value: object) -> str:
    """``repr(value)`` on one line, cut to :data:`SHOWN` characters."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a caller's object whose repr fails is still named
        text = f"<{_typename(value)} object>"
    if not text.isprintable():
        text = text.encode("unicode_escape").decode("ascii")
    return text if len(text) <= SHOWN else f"{text[: SHOWN - 3]}..."


def _typename(value: object) -> str:
    return type(value).__name__


def wrong_type(kind: type[UsageError], name: str, value: object, expected: str) -> UsageError:
    """The error of ``kind`` (its TypeError variant): ``name`` was given ``value``, of a type
    that is not ``expected``."""
    return KINDS[kind][0](f"{name} {shown(value)}: expected {expected}, got {_typename(value)}")


def wrong_value(kind: type[UsageError], name: str, value: object, expected: str,
                problem: str = "") -> UsageError:  # fmt: skip
    """The error of ``kind`` (its ValueError variant): ``name`` was given ``value``, which
    is not ``expected`` (``problem`` says why, when it helps)."""
    what = f"{problem}, expected" if problem else "expected"
    return KINDS[kind][1](f"{name} {shown(value)}: {what} {expected}")


def _bounds(lo: float | None, hi: float | None) -> str:
    if lo is not None and hi is not None:
        return f"{lo}..{hi}"
    if lo is not None:
        return f">= {lo}"
    if hi is not None:
        return f"<= {hi}"
    return ""


def integer(value: object, *, name: str, lo: int | None = None, hi: int | None = None,
            kind: type[UsageError] = UsageError, why: str = "",
            floats: bool = True) -> int:  # fmt: skip
    """``value`` as an ``int`` in ``lo..hi``: an ``int``, a numpy integer or (with
    ``floats``) a float of integral value; a ``bool``, ``2.5`` or ``"3"`` are refused."""
    expected = (_bounds(lo, hi) or "an integer") + (f" ({why})" if why else "")
    number: int | None = None
    problem = "not an integer"
    if isinstance(value, int) and not isinstance(value, bool):
        number = int(value)
    elif not isinstance(value, bool):
        import numpy as np  # a dependency; already imported by whoever hands numpy values

        if isinstance(value, np.integer):
            number = int(value)
        elif floats and isinstance(value, (float, np.floating)) and math.isfinite(value):
            if float(value).is_integer():
                number = int(value)
            else:
                problem = "not an integer (a float is never rounded)"
    if number is None:
        raise KINDS[kind][0](f"{name} {shown(value)}: {problem}, expected {expected}")
    if (lo is not None and number < lo) or (hi is not None and number > hi):
        raise KINDS[kind][1](f"{name} {number}: out of range, expected {expected}")
    return number


def number(value: object, *, name: str, lo: float | None = None, hi: float | None = None,
           kind: type[UsageError] = UsageError, finite: bool = True,
           expected: str = "") -> float:  # fmt: skip
    """``value`` as a ``float`` in ``lo..hi`` (an ``int`` or ``float``, numpy's too; never a
    ``bool``); NaN and the infinities are refused with ``finite``. ``expected`` says in words
    what is accepted (default: a number in the bounds)."""
    import numpy as np

    said = expected or f"a {'finite ' if finite else ''}number {_bounds(lo, hi)}".rstrip()
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise wrong_type(kind, name, value, said)
    x = float(value)
    if finite and not math.isfinite(x):
        raise wrong_value(kind, name, value, said, "not finite")
    if (lo is not None and x < lo) or (hi is not None and x > hi):
        raise wrong_value(kind, name, value, said, "out of range")
    return x


def flag(value: object, *, name: str, kind: type[UsageError] = UsageError) -> bool:
    """``value`` as a ``bool``: ``True`` or ``False`` (numpy's too), nothing else (a
    ``"no"`` is true to Python, so it is refused rather than guessed)."""
    import numpy as np

    if not isinstance(value, (bool, np.bool_)):
        raise wrong_type(kind, name, value, "True or False")
    return bool(value)


def text(value: object, *, name: str, kind: type[UsageError] = UsageError,
         choices: Sequence[str] = (), empty: bool = False,
         expected: str = "") -> str:  # fmt: skip
    """``value``, a ``str``: one of ``choices`` when given, not blank unless ``empty``.
    ``expected`` says in words what is accepted (default: the choices, or text)."""
    said = expected or (", ".join(choices[:-1]) + f" or {choices[-1]}" if len(choices) > 1
                        else choices[0] if choices else "text")  # fmt: skip
    if not isinstance(value, str):
        raise wrong_type(kind, name, value, said)
    if "\x00" in value:
        raise wrong_value(kind, name, value, said, "a NUL character")
    if not empty and not value.strip():
        raise wrong_value(kind, name, value, said, "empty")
    if choices and value not in choices:
        raise wrong_value(kind, name, value, said)
    return value


def path(value: object, *, name: str, kind: type[UsageError] = OutputError,
         what: str = "a path (a str or a pathlib.Path)") -> str | os.PathLike[str]:  # fmt: skip
    """``value``, a path: a ``str`` or an ``os.PathLike`` of text (a ``pathlib.Path``, a
    ``corraoi.Run``), neither empty nor holding a NUL byte; ``what`` says what it names."""
    expected = what
    if not isinstance(value, (str, os.PathLike)):
        raise wrong_type(kind, name, value, expected)
    try:
        fs = os.fspath(value)
    except TypeError:
        raise wrong_type(kind, name, value, expected) from None
    if not isinstance(fs, str):
        raise wrong_type(kind, name, value, expected)
    if not fs.strip():
        raise wrong_value(kind, name, value, expected, "empty")
    if "\x00" in fs:
        raise wrong_value(kind, name, value, expected, "a NUL character")
    return value


def names(value: object, *, name: str, kind: type[UsageError] = UsageError,
          empty: bool = False, what: str = "names") -> tuple[str, ...]:  # fmt: skip
    """``value`` as a tuple of non-blank ``str``: one ``str`` is one name (never its
    letters), else a list or tuple of them; an empty one only with ``empty``."""
    expected = f"one of the {what} or a list of them"
    if isinstance(value, str):
        return (text(value, name=name, kind=kind, expected=expected),)
    if not isinstance(value, Sequence) or isinstance(value, (bytes, bytearray)):
        raise wrong_type(kind, name, value, expected)
    out = tuple(text(v, name=f"{name}[{i}]", kind=kind, expected=f"one of the {what}")
                for i, v in enumerate(value))  # fmt: skip
    if not out and not empty:
        raise wrong_value(kind, name, value, f"at least one of the {what}", "empty")
    return out


def callback(value: object, *, name: str, kind: type[UsageError] = UsageError) -> Any:
    """``value``, a callable (a function, a method, a lambda)."""
    if not callable(value):
        raise wrong_type(kind, name, value, "a function")
    return value


def optional(check: Callable[..., T], value: object, **options: Any) -> T | None:
    """None when ``value`` is None, else ``check(value, **options)``."""
    return None if value is None else check(value, **options)


def path_or_flag(value: object, *, name: str, kind: type[UsageError] = OutputError,
                 what: str = "a path") -> str | os.PathLike[str] | bool | None:  # fmt: skip
    """``value``: None (the default place), ``True`` (the same), ``False`` (none) or a path
    (:func:`path`), as ``rrd=`` takes."""
    if value is None or isinstance(value, bool):
        return value
    if not isinstance(value, (str, os.PathLike)):
        raise wrong_type(kind, name, value, f"{what}, None, True or False")
    return path(value, name=name, kind=kind, what=what)


def index_or_word(value: object, *, name: str, words: Sequence[str],
                  kind: type[UsageError] = UsageError) -> int | str:  # fmt: skip
    """``value``: an index (an integer >= 0, :func:`integer`) or one of ``words`` (any
    case); a ``str`` of an integer (what a command line gives) is that integer, its range
    left to the caller, which knows how many there are."""
    said = f"an index (0, 1, ...) or one of {', '.join(words)}"
    if isinstance(value, str):
        word = value.strip().lower()
        if word in words:
            return word
        if word.removeprefix("-").isascii() and word.removeprefix("-").isdigit():
            return int(word)
        raise wrong_value(kind, name, value, said)
    if isinstance(value, bool) or value is None or isinstance(value, (bytes, Sequence, Mapping)):
        raise wrong_type(kind, name, value, said)
    return integer(value, name=name, lo=0, kind=kind)


def objects(value: object, *, name: str, has: Sequence[str], what: str,
            kind: type[UsageError] = UsageError) -> tuple[Any, ...]:  # fmt: skip
    """``value``: a list or tuple of objects that each have the attributes ``has`` (``what``
    says what they are); a ``str`` is refused."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise wrong_type(kind, name, value, f"a list or tuple, each {what}")
    for i, item in enumerate(value):
        if not all(hasattr(item, a) for a in has):
            raise wrong_type(kind, f"{name}[{i}]", item, what)
    return tuple(value)


def window(value: object, *, name: str = "slots") -> tuple[int, int]:
    """``(first, last)``: two slot numbers, 1 <= first <= last."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise wrong_type(UsageError, name, value, "a pair (first, last) of slot numbers")
    first = integer(value[0], name=f"{name}[0]", lo=1)
    last = integer(value[1], name=f"{name}[1]", lo=first)
    return first, last


__all__ = [
    "KINDS",
    "callback",
    "flag",
    "integer",
    "index_or_word",
    "names",
    "number",
    "objects",
    "optional",
    "path",
    "path_or_flag",
    "shown",
    "text",
    "window",
    "wrong_type",
    "wrong_value",
]

"""Reading a user's description file (a machine, a design): one-line refusals that name the
file, the line of the key at fault and the rule."""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - the project's dependency on Python 3.10
    import tomli as tomllib

T = TypeVar("T")


class UserFileError(ValueError):
    """A description (file or dict) that breaks one of its rules.

    ``key``: the key at fault, when there is one (a file reader turns it into a line
    number); ``occurrence``: which appearance of the key in the file (2 for the second of
    two duplicate keys).
    """

    def __init__(self, message: str, key: str | None = None, occurrence: int = 1) -> None:
        super().__init__(message)
        self.key = key
        self.occurrence = occurrence


def read_user_file(path: Path, kind: str, error: type[ValueError]) -> str:
    """A user's text file, or ``error`` with a one-line message naming the file."""
    try:
        return path.read_text()
    except FileNotFoundError:
        raise error(f"{kind} not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise error(f"cannot read {kind} {path}: {reason}") from None


def load_user_file(path: str | Path, kind: str, error: type[UserFileError],
                   build: Callable[[Any], T], *, toml: bool = False) -> T:
    """``build`` of the document in the user's ``kind`` file ``path``: JSON (a key given
    twice is an error), or TOML when ``toml``.  Every refusal is ``error`` naming the file,
    and the line of the key at fault when there is one."""
    path = Path(path)
    text = read_user_file(path, f"{kind} file", error)
    try:
        if toml:
            data = tomllib.loads(text)
        else:
            data = json.loads(text, object_pairs_hook=partial(unique_keys, kind=kind,
                                                              error=error))
        return build(data)
    except json.JSONDecodeError as exc:
        raise error(f"{path}:{exc.lineno}: not valid JSON (column {exc.colno}: "
                    f"{exc.msg})") from None
    except tomllib.TOMLDecodeError as exc:
        found = re.search(r"\(at line (\d+), column (\d+)\)", str(exc))
        where = f":{found[1]}" if found else ""
        raise error(f"{path}{where}: not valid TOML "
                    f"({str(exc).split(' (at line')[0]})") from None
    except error as exc:
        line = line_of_key(text, exc.key, exc.occurrence, toml=toml)
        raise error(f"{path}{'' if line is None else f':{line}'}: {exc}",
                    key=exc.key) from None
    except (ValueError, RecursionError) as exc:
        # The JSON reader's own limits: integers of thousands of digits, deep nesting.
        reason = str(exc).split(";")[0].splitlines()[0]
        raise error(f"{path}: not a {kind} file ({reason})") from None


def short_repr(value: Any) -> str:
    """A value's repr for a one-line message, cut short."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def unique_keys(pairs: list[tuple[str, Any]], kind: str, error: type[UserFileError]
                ) -> dict[str, Any]:
    """A JSON object's pairs as a dict, refusing a key given twice (``json`` would keep
    the last one silently) with ``error`` naming the ``kind`` of key."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise error(f"{kind} key '{key}' is given twice", key=key, occurrence=2)
        out[key] = value
    return out


def line_of_key(text: str, key: str | None, occurrence: int = 1, *, toml: bool = False
                ) -> int | None:
    """Line (1-based) of the ``occurrence``-th ``"key":`` in a JSON text (``key =`` or the
    table header ``[key]`` at the start of a line in a TOML text), if found."""
    if key is None:
        return None
    name = rf'"?{re.escape(key)}"?'
    pattern = (rf'^[ \t]*(\[[ \t]*{name}[ \t]*\]|{name}[ \t]*=)' if toml
               else rf'"{re.escape(key)}"\s*:')
    matches = list(re.finditer(pattern, text, flags=re.MULTILINE))
    if len(matches) < occurrence:
        return None
    return text.count("\n", 0, matches[occurrence - 1].start()) + 1

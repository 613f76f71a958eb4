"""Whether a PyBullet GUI window can open here, asked before PyBullet is.

PyBullet's GUI connection ends the whole Python process (exit status 1, one line from C
on stderr) when it finds no X server, so a missing display must be found first and
reported as an ordinary error.  On Linux and the other X11 platforms that means a
``DISPLAY`` variable and an X server that accepts a connection there; macOS and Windows
always have a window system.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
import sys

#: PyBullet's GUI loads this library itself (dlopen) to talk to the X server.
X11_LIBRARY = "X11"


def display_problem() -> str | None:
    """Why no GUI window can open, or None when one can."""
    if sys.platform in ("darwin", "win32"):
        return None
    name = os.environ.get("DISPLAY", "")
    if not name:
        return "no display (the DISPLAY environment variable is not set)"
    return _x_server_problem(name)


@functools.lru_cache(maxsize=8)
def _x_server_problem(name: str) -> str | None:
    """Open and close one connection to the X server ``name`` (cached per name)."""
    path = ctypes.util.find_library(X11_LIBRARY)
    if path is None:
        return "no X11 client library (libX11) is installed"
    xlib = ctypes.CDLL(path)
    xlib.XOpenDisplay.restype = ctypes.c_void_p
    xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
    xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
    handle = xlib.XOpenDisplay(name.encode())
    if not handle:
        return f"cannot connect to the X server at DISPLAY={name}"
    xlib.XCloseDisplay(handle)
    return None


def require_display(what: str, instead: str) -> None:
    """Raise ``ValueError`` naming the setting ``what`` that asked for a window, why none
    can open, and the setting to use ``instead``."""
    problem = display_problem()
    if problem is not None:
        raise ValueError(f"{what} needs a display: {problem}; use {instead} instead")

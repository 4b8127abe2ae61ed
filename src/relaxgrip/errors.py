"""Exceptions shared by every layer."""

from __future__ import annotations


class InputError(ValueError):
    """Bad input from outside: a file, a flag, a frame, a byte.

    The message is one line that names the problem; the command line turns it
    into ``error: <message>`` and exit code 2, with no traceback.
    """

"""Strings from outside made safe for a terminal or a log.

A recording's topic names, message type names and frame ids, a file's name or contents, a topic's
frame ids: any of them can hold characters that a terminal obeys rather than shows (ESC starts a
control sequence that can clear the screen or retitle the window, BEL rings, CR overwrites the line,
U+202E reverses what follows) or that an encoder refuses (the lone surrogates of a file name that
is not UTF-8). Every such string is passed through :func:`printable` before it is written to a
terminal or a log; what a command prints or logs as a whole goes through :func:`printable_lines`
as the last step (``hac``'s output and its log lines, ``hac batch``'s job logs).

A character that is not printable (``str.isprintable``: the control characters, format characters
such as U+202E, separators other than the space, surrogates, unassigned code points) is written
as Python writes it in a repr (``\\x1b``, ``\\t``, ``\\u202e``, ``\\udcff``); everything else, the
letters of every script included, is left as it is.
"""
from __future__ import annotations

_NAMED = {'\t': '\\t', '\n': '\\n', '\r': '\\r'}


def printable(text: object) -> str:
    """``str(text)`` with every character that is not printable escaped (module docstring):
    one line, whatever it held."""
    s = str(text)
    if s.isprintable():
        return s
    return ''.join(c if c.isprintable() else _escaped(c) for c in s)


def printable_lines(text: object) -> str:
    """As :func:`printable`, line by line: the line breaks of ``text`` are kept (a summary, a
    message of several lines), every other character that is not printable is escaped."""
    s = str(text)
    return '\n'.join(printable(line) for line in s.split('\n'))


def first_line(exc: BaseException) -> str:
    """The first line of an exception's text, escaped (a library's messages, rosbags' among
    them, can run to many lines); its type's name when it has no text."""
    text = str(exc).strip() or type(exc).__name__
    return printable(text.splitlines()[0])


def _escaped(char: str) -> str:
    if char in _NAMED:
        return _NAMED[char]
    code = ord(char)
    if code < 0x100:
        return f'\\x{code:02x}'
    return f'\\u{code:04x}' if code < 0x10000 else f'\\U{code:08x}'


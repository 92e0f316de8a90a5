"""Exception types of the core. Catch :class:`HacError` for anything the package raises on
purpose."""
from __future__ import annotations

from collections.abc import Mapping


class HacError(Exception):
    """Base class of every error raised on purpose by hac_ros."""


class ParameterError(HacError, ValueError):
    """A parameter value is invalid; the message names the parameter and the reason."""


class InputError(HacError, ValueError):
    """An input array has the wrong shape or content (the message says which and why)."""


class ArgumentText(str):
    """A message that names arguments of a library call (function arguments or parameters).

    As a ``str`` it calls them as the library does (``pose_type``, ``joints_topic``); a front end
    that calls them otherwise (the command line's ``--pose-type``) renders the same message with
    its own names (:meth:`naming`). In ``template`` each of ``arguments`` is written ``{name}``;
    nothing else in it is a placeholder.
    """

    template: str
    arguments: tuple[str, ...]

    def __new__(cls, template: str, *arguments: str) -> ArgumentText:
        text = super().__new__(cls, _named(template, arguments, {}))
        text.template, text.arguments = template, arguments
        return text

    def naming(self, names: Mapping[str, str]) -> str:
        """The message, each argument called by ``names`` (by its own name where ``names`` has
        none)."""
        return _named(self.template, self.arguments, names)


class ArgumentError(HacError, ValueError):
    """An argument of a library call is invalid or does not fit the input; the message is an
    :class:`ArgumentText` (``str(error)`` names the library's arguments, :meth:`naming` a front
    end's)."""

    def __init__(self, template: str, *arguments: str) -> None:
        self.text = ArgumentText(template, *arguments)
        super().__init__(str(self.text))

    def naming(self, names: Mapping[str, str]) -> str:
        return self.text.naming(names)


def _named(template: str, arguments: tuple[str, ...], names: Mapping[str, str]) -> str:
    for argument in arguments:
        template = template.replace('{' + argument + '}', names.get(argument, argument))
    return template

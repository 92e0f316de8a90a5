"""The adapters' one exception type (rosbags style: one ``errors.py`` per package)."""
from hac_ros.core.errors import HacError


class MessageError(HacError, ValueError):
    """A message cannot be converted: the text names the field, what was expected and what was
    found.

    Catch this (or :class:`~hac_ros.core.errors.HacError`, or ``ValueError``) around any adapter
    call; no IndexError, struct.error or numpy error escapes the adapters for a malformed input.
    """

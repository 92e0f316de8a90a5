"""The adapters' one exception type."""
from hac_ros.core.errors import HacError


class MessageError(HacError, ValueError):
    """A message cannot be converted: the text names the field, what was expected and what was found."""

"""The adapters' one exception type (rosbags style: one ``errors.py`` per package).

``msg_adapters`` stands on its own (numpy only, ROS imported lazily), so that any rclpy or rosbags
program can use it without hac_ros; its error is therefore its own, not one of hac_ros' errors.
"""


class MessageError(ValueError):
    """A message cannot be converted: the text names the field, what was expected and what was
    found.

    Catch this (or ``ValueError``) around any adapter call; no IndexError, struct.error or numpy
    error escapes the adapters for a malformed input.
    """

"""Recording I/O: rosbag2 in and out, atomic output staging, ground truth and outputs as arrays.

Everything that reads or writes a recording goes through here (``hac replay``, ``hac eval``,
``hac plot``, the demo, the tests): :class:`Recording` reads (rosbag2 sqlite3 or mcap, a bare
``.mcap``/``.db3`` file, or a ROS 1 ``.bag``; never written), :class:`OutputWriter` writes a new
rosbag2 recording, :class:`~hac_ros.recording.atomic.staged_output` makes any output appear
atomically, and the ``read_*`` functions turn topics into numpy tracks (header stamps as int
nanoseconds; every array's frame and unit in its docstring). Errors a user can fix raise
:class:`~hac_ros.core.basics.errors.HacError`.
"""

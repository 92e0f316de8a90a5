"""An rclpy executor spun on a background thread, stopped before it is shut down.

For a Python process that runs ROS nodes beside other work: the tests, the benchmarks, or a user
embedding :class:`hac_ros.ros.node.HacNode` in a program of their own (``hac_node`` itself spins on
its main thread).

Why not ``threading.Thread(target=executor.spin)`` and ``executor.shutdown()`` from another
thread: with rclpy Jazzy, shutting a SingleThreadedExecutor down while another thread is inside
``spin()`` can leave that thread looping in ``_wait_for_ready_callbacks`` forever, holding the GIL
so often that the rest of the process starves (seen once in about 20 runs of
bench/node_latency.py: the process then hung at 100 % CPU). Here the thread calls ``spin_once``
with a short timeout until :meth:`SpinThread.close` asks it to stop, and the executor is shut down
only after the thread has returned.
"""
from __future__ import annotations

import threading
from typing import Any

POLL_S = 0.05  # the longest the thread waits in one spin_once: how soon close() is seen


class SpinThread:
    """Spins ``executor`` on a daemon thread from construction until :meth:`close`."""

    def __init__(self, executor: Any, name: str = 'hac_spin') -> None:
        self.executor = executor
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from rclpy.executors import ExternalShutdownException

        context = self.executor.context
        try:
            while not self._stop.is_set() and context.ok():
                self.executor.spin_once(timeout_sec=POLL_S)
        except ExternalShutdownException:  # the context was shut down elsewhere
            pass

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def close(self, timeout_s: float = 5.0) -> bool:
        """Stop the thread, then shut the executor down. Returns whether the thread ended within
        ``timeout_s`` (the executor is shut down either way)."""
        self._stop.set()
        self._thread.join(timeout_s)
        self.executor.shutdown(timeout_sec=2.0)
        return not self._thread.is_alive()

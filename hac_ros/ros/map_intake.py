"""hac_node's map clouds: read on the executor thread, built on a thread of their own.

A cloud arrives as raw CDR bytes. Its header is read at once (microseconds); decoding and indexing
(:class:`hac_ros.bridge.inputs.MapBuilder`, as in the replay) run on the builder's thread, and the
finished maps go into the node's inbox in arrival order (:mod:`hac_ros.ros.intake`), where the
processing thread hands them to the calibrator between the other inputs. A cloud still waiting for
the builder when a newer one arrives is superseded in ``cloud_mode: replace`` (it would be replaced
anyway), and so is a built map waiting in the inbox with no joints frame behind it
(:mod:`hac_ros.ros.intake`); ``accumulate`` keeps up to MAPS_WAITING_MAX waiting for the builder.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
from concurrent.futures import Future

from hac_ros.bridge.inputs import IndexBuilder, MapBuilder, MapBuilt
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.rules.params import CloudMode
from hac_ros.ros.intake import Inbox
from msg_adapters import MessageError, RawCloud, parse_cloud_cdr

MAPS_WAITING_MAX = 8  # accumulate mode: clouds waiting for the builder (older ones are dropped)


class MapIntake:
    """The node's map clouds, from bytes to the inbox.

    ``build_index`` makes the index with the current calibrator's parameters (thread-safe);
    ``wake`` is called from the builder's thread when a map is finished: the node triggers a guard
    condition with it, whose callback (:meth:`ready`, on the executor's thread) moves the finished
    maps into the inbox.
    """

    def __init__(self, build_index: IndexBuilder, inbox: Inbox, wake: Callable[[], None]) -> None:
        self.indexed = 0  # map indexes put into the inbox
        self.superseded = 0  # clouds dropped unbuilt: a newer one arrived first
        self.rejected = 0  # clouds that could not be decoded
        self.build_s: deque[float] = deque(maxlen=100)  # recent decode+index durations, seconds
        self.last_index: MapIndex | None = None  # the last index put into the inbox
        self.last_cloud: RawCloud | None = None  # the last cloud received (its bytes are kept)
        self._inbox = inbox
        self._wake = wake
        self._builder = MapBuilder(build_index, workers=1)
        self._building: deque[Future[MapBuilt]] = deque()  # in arrival order
        self._replace = True  # cloud_mode replace: a newer map supersedes the ones waiting

    def receive(self, data: bytes, cloud_mode: str) -> bool:
        """Executor thread: the header of a cloud's CDR bytes read, the cloud queued for the
        builder (``cloud_mode``: the node's parameter). False when the bytes are not a
        PointCloud2 (the node rejects it)."""
        try:
            cloud = parse_cloud_cdr(data)
        except MessageError:
            self.rejected += 1
            return False
        self.last_cloud = cloud
        self.submit(cloud, cloud_mode)
        return True

    def submit(self, cloud: RawCloud, cloud_mode: str) -> None:
        """Queue ``cloud`` for the builder; what ``cloud_mode`` no longer needs is superseded."""
        waiting = [f for f in self._building if not f.done()]
        self._replace = cloud_mode == CloudMode.REPLACE
        if self._replace:
            superseded = waiting
        else:
            superseded = waiting[:max(0, len(waiting) - MAPS_WAITING_MAX + 1)]
        self.superseded += sum(f.cancel() for f in superseded)
        future = self._builder.submit(cloud)
        future.add_done_callback(lambda _: self._wake())
        self._building.append(future)

    def ready(self) -> None:
        """Executor thread: the maps the builder finished, in arrival order, into the inbox."""
        while self._building and self._building[0].done():
            future = self._building.popleft()
            if future.cancelled():
                continue
            built = future.result()
            self.build_s.append(built.build_s)
            if built.index is None:
                self.rejected += 1
            else:
                self.indexed += 1
                self.last_index = built.index
            # a map that could not be built carries its rejection to the calibrator: kept
            self._inbox.put('map', built, supersede=self._replace and built.index is not None)

    @property
    def done(self) -> int:
        """Clouds received and finished with: indexed, rejected, or superseded by a newer one."""
        return self.indexed + self.rejected + self.superseded

    def close(self) -> None:
        """Stop the builder (a map being built is finished and dropped)."""
        self._builder.close()

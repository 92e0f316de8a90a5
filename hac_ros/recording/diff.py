"""Whether two recordings are the same, message for message: topics, types, log times and the
serialized bytes of every message (``hac batch``'s promise that a Ray run equals the process
pool's, and a batch output equals a single replay's)."""
from __future__ import annotations

from pathlib import Path

from hac_ros.recording.reader import Recording


def messages_by_topic(path: str | Path) -> dict[str, tuple[str | None, list[tuple[int, bytes]]]]:
    """topic -> (type, [(log time ns, CDR bytes)] in log-time order) of every topic."""
    out: dict[str, tuple[str | None, list[tuple[int, bytes]]]] = {}
    with Recording(path) as rec:
        for topic, msgtype in rec.topics.items():
            out[topic] = (msgtype, [])
        for topic, log_ns, raw in rec.messages(rec.topics):
            out[topic][1].append((log_ns, bytes(rec.to_cdr(raw, topic, log_ns))))
    return out


def recording_differences(a: str | Path, b: str | Path) -> list[str]:
    """How two recordings differ, topic by topic (types, counts, log times, bytes); [] when
    equal."""
    ma, mb = messages_by_topic(a), messages_by_topic(b)
    differences = []
    for topic in sorted(set(ma) | set(mb)):
        (type_a, msgs_a), (type_b, msgs_b) = ma.get(topic, (None, [])), mb.get(topic, (None, []))
        if type_a != type_b:
            differences.append(f'{topic}: type {type_a} != {type_b}')
        if len(msgs_a) != len(msgs_b):
            differences.append(f'{topic}: {len(msgs_a)} != {len(msgs_b)} messages')
            continue
        times = sum(x[0] != y[0] for x, y in zip(msgs_a, msgs_b))
        payloads = sum(x[1] != y[1] for x, y in zip(msgs_a, msgs_b))
        if times or payloads:
            differences.append(f'{topic}: {times} log times and {payloads} of {len(msgs_a)} '
                               'payloads differ')
    return differences

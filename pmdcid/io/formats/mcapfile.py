"""MCAP logs (``.mcap``) through the ``mcap`` package: ROS 2 (CDR) and JSON messages; series.

Every numeric field of every topic is a series named ``topic.field`` (nested fields
``topic.a.b``; the elements of a numeric array ``topic.field[k]``, or ``topic.field`` when the
array holds one element: ``/joint_states.velocity`` for a one-joint ``sensor_msgs/JointState``;
a ``builtin_interfaces/Time`` as one value in seconds). Its instants are the messages' log times
[s from the file's first message]. ROS 2 messages decode through ``mcap-ros2-support``, JSON
ones with the standard library; topics in other encodings are left out.

An MCAP file ends with its magic bytes after the footer; one that does not was cut short (the
recorder stopped before closing it) and is refused in one line that says so and how to recover
its whole records (``mcap recover``), where the reader would report a garbled record length.
"""

from __future__ import annotations

import json

import numpy as np

from pmdcid.errors import LogError
from pmdcid.io.formats import Series, Signals, need

EXTENSIONS = (".mcap",)
EXTRA = "mcap"
#: a time that looks like ms, us or ns (:func:`pmdcid.io.formats.own_time_fix`)
TIME_UNIT_FIX = "write each message's log_time in nanoseconds, MCAP's unit"
MAGIC = b"\x89MCAP0\r\n"
#: arrays longer than this are not signals (images, point clouds)
MAX_ELEMENTS = 16


def _fields(obj) -> list[tuple[str, object]] | None:
    if isinstance(obj, dict):
        return list(obj.items())
    slots = getattr(type(obj), "__slots__", None)
    if slots:
        return [(k, getattr(obj, k, None)) for k in slots]
    return None


def flatten(prefix: str, obj, out: dict[str, float]) -> None:
    """Numeric leaves of a decoded message as ``prefix.field`` -> value."""
    if isinstance(obj, bool | int | float | np.number) and not isinstance(obj, str):
        out[prefix] = float(obj)
        return
    if isinstance(obj, list | tuple | np.ndarray):
        if 0 < len(obj) <= MAX_ELEMENTS and all(isinstance(v, int | float | np.number)
                                                for v in obj):
            if len(obj) == 1:
                out[prefix] = float(obj[0])
            else:
                for k, v in enumerate(obj):
                    out[f"{prefix}[{k}]"] = float(v)
        return
    fields = _fields(obj)
    if fields is None:
        return
    names = {k for k, _ in fields}
    if names == {"sec", "nanosec"}:  # builtin_interfaces/Time or Duration: one value [s]
        d = dict(fields)
        out[prefix] = float(d["sec"]) + 1e-9 * float(d["nanosec"])
        return
    for k, v in fields:
        flatten(f"{prefix}.{k}", v, out)


def _decoder(schema, channel, ros2):
    if channel.message_encoding == "json":
        return lambda data: json.loads(data)
    if channel.message_encoding == "cdr" and schema is not None:
        try:
            return ros2.DecoderFactory().decoder_for(channel.message_encoding, schema)
        except Exception:  # noqa: BLE001 - a schema the decoder cannot read: topic left out
            return None
    return None


def _topics(reader, wanted) -> list[str] | None:
    """The topics the mapped names (``wanted``: right-hand sides of ``-c``) read, or None (all)
    when there is no mapping or none of them names a topic of the file (then the error lists
    every signal)."""
    if not wanted:
        return None
    summary = reader.get_summary()
    if summary is None:
        return None
    topics = {ch.topic for ch in summary.channels.values()}
    keep = [tp for tp in topics if any(w.startswith(tp + ".") for w in wanted)]
    return keep or None


def _check_end(fh, path: str) -> None:
    """Refuse, in one line, a file that starts as MCAP but does not end as one: cut short."""
    head = fh.read(len(MAGIC))
    size = fh.seek(0, 2)
    fh.seek(max(0, size - len(MAGIC)))
    tail = fh.read(len(MAGIC))
    fh.seek(0)
    if head == MAGIC and (tail != MAGIC or size < 2 * len(MAGIC) + 1):
        raise LogError(f"the MCAP file is cut short ({size} bytes, no footer at its end): it was "
                       "not closed properly; 'mcap recover FILE -o WHOLE.mcap' keeps its whole "
                       "records", path)


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals; with ``wanted`` (the mapped names), only the topics they read are
    decoded (a bag's camera topics are never decoded to read a motor's)."""
    reader_mod = need("mcap.reader", EXTRA, path, ".mcap")
    ros2 = need("mcap_ros2.decoder", EXTRA, path, ".mcap (ROS 2)")
    times: dict[str, list[int]] = {}
    values: dict[str, list[float]] = {}
    decoders: dict[int, object] = {}
    try:
        with open(path, "rb") as fh:
            _check_end(fh, path)
            reader = reader_mod.make_reader(fh)
            topics = _topics(reader, wanted)
            for schema, channel, msg in reader.iter_messages(topics=topics):
                if channel.id not in decoders:
                    decoders[channel.id] = _decoder(schema, channel, ros2)
                dec = decoders[channel.id]
                if dec is None:
                    continue
                leaves: dict[str, float] = {}
                try:
                    flatten(channel.topic, dec(msg.data), leaves)
                except (ValueError, TypeError, KeyError, IndexError):
                    continue  # one undecodable message: skipped
                for name, v in leaves.items():
                    times.setdefault(name, []).append(msg.log_time)
                    values.setdefault(name, []).append(v)
    except Exception as exc:  # noqa: BLE001 - the mcap reader's errors on a broken file
        if isinstance(exc, LogError):
            raise
        raise LogError(f"is not a readable MCAP file ({type(exc).__name__}: "
                       f"{str(exc)[:80]})", path) from None
    if not times:
        return Signals({})
    t0 = min(min(ts) for ts in times.values())
    out = {name: Series(np.asarray(values[name], float),
                        (np.asarray(ts, dtype=np.int64) - t0).astype(float) * 1e-9)
           for name, ts in times.items()}
    return Signals(out)

"""Bulk decoding of fixed-layout scalar messages from MCAP bags, chunk by chunk, with numpy.

A car-test log at 1 kHz holds millions of tiny messages; decoding them one Python object at a
time (rosbags' general deserializer) costs microseconds each and dominated replay. The two
message types the car-test topics use have a layout numpy can read directly from the
decompressed chunk:

- ``std_msgs/msg/Float64`` (CDR, little endian): 4-byte encapsulation header ``00 01 00 00``,
  then the float64 ``data`` at byte 4; 12 bytes in all.
- ``sensor_msgs/msg/Temperature``: encapsulation header, ``header.stamp`` (int32 sec, uint32
  nanosec), ``header.frame_id`` (uint32 length L including the NUL, then L bytes), padding to
  the next multiple of 8 of the payload (which starts after the encapsulation header), then
  float64 ``temperature`` and float64 ``variance``. The frame_id length is read per message, so
  the temperature's offset is computed per message (vectorised).

For each MCAP chunk the reader decompresses the chunk (none / lz4 / zstd), takes the message
offsets of the wanted channels from the chunk's message index records, checks every record
(opcode, channel, data length, encapsulation) and gathers log times and values with numpy; only
the decoded float arrays outlive the chunk, so memory is bounded by one chunk (plus the result).

Anything else — sqlite3 storage, rosbag2 file compression, several files per bag, unindexed or
unchunked MCAP, big-endian CDR, other message types, a record that does not match its layout —
returns ``None`` and the caller uses rosbags' general decoder (``bag_reader``). Both paths give
the same series bit for bit: same bytes decoded, and samples ordered as rosbags yields them
(log time, then chunk position, then record position; then a stable sort per topic).
"""
from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

FLOAT64 = "std_msgs/msg/Float64"
TEMPERATURE = "sensor_msgs/msg/Temperature"
SUPPORTED = (FLOAT64, TEMPERATURE)
CDR_LE = (0x00, 0x01)
MESSAGE_OPCODE = 0x05
MESSAGE_INDEX_OPCODE = 0x07
_MSG_PREFIX = 1 + 8 + 2 + 4 + 8 + 8      # opcode, record length, channel, sequence, log, publish time


class NotBulk(Exception):
    """The bag is not readable by the bulk path (the caller falls back to the general one)."""


def mcap_file_of(path: Path) -> Path | None:
    """The single MCAP file of a bare ``.mcap`` path or of a rosbag2 MCAP directory without
    file compression; None otherwise (sqlite3, several files, compressed files)."""
    path = Path(path)
    if path.is_file():
        return path if path.suffix == ".mcap" else None
    meta = path / "metadata.yaml"
    if not meta.is_file():
        return None
    import yaml

    try:
        loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)    # libyaml when present: the same data
        info = yaml.load(meta.read_text(), Loader=loader)["rosbag2_bagfile_information"]
    except Exception:
        return None
    if info.get("storage_identifier") != "mcap" or info.get("compression_format") or info.get("compression_mode"):
        return None
    files = info.get("relative_file_paths") or []
    if len(files) != 1:
        return None
    f = path / files[0]
    return f if f.is_file() and f.suffix == ".mcap" else None


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == "":
        raw = data
    elif compression == "lz4":
        import lz4.frame

        raw = lz4.frame.decompress(data)
    elif compression == "zstd":
        try:
            from compression import zstd  # Python >= 3.14
        except ImportError:
            try:
                from backports import zstd
            except ImportError as exc:
                raise NotBulk("no zstd decompressor") from exc
        raw = zstd.decompress(data)
    else:
        raise NotBulk(f"chunk compression {compression!r}")
    if len(raw) != size:
        raise NotBulk("chunk size mismatch")
    return raw


def _gather(buf: np.ndarray, pos: np.ndarray, dtype: str) -> np.ndarray:
    """Little-endian scalars of ``dtype`` at byte positions ``pos`` of the uint8 array ``buf``
    (unaligned: rows of a sliding byte window, one fancy index per value)."""
    width = np.dtype(dtype).itemsize
    window = np.lib.stride_tricks.as_strided(buf, shape=(max(buf.size - width + 1, 0), width),
                                             strides=(1, 1), writeable=False)
    return window[pos].view(dtype).ravel()


_PREFIX_FIELDS = [("opcode", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                  ("log_time", "<u8"), ("publish_time", "<u8"), ("encap0", "u1"), ("encap1", "u1"),
                  ("encap_options", "<u2")]
FLOAT64_RECORD = np.dtype(_PREFIX_FIELDS + [("data", "<f8")])                       # 43 bytes
TEMPERATURE_PREFIX = np.dtype(_PREFIX_FIELDS + [("sec", "<i4"), ("nanosec", "<u4"),
                                                ("frame_id_len", "<u4")])           # 47 bytes


def _records(buf: np.ndarray, rec: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """The records at offsets ``rec`` read as the packed structured ``dtype`` (one gather)."""
    width = dtype.itemsize
    if rec.size and rec[-1] + width > buf.size:
        raise NotBulk("record runs past the chunk")
    window = np.lib.stride_tricks.as_strided(buf, shape=(max(buf.size - width + 1, 0), width),
                                             strides=(1, 1), writeable=False)
    return window[rec].view(dtype).ravel()


def _decode(buf: np.ndarray, rec: np.ndarray, cid: int, msgtype: str) -> tuple[np.ndarray, np.ndarray]:
    """(log times, values) of channel ``cid``'s messages whose records start at the ascending
    offsets ``rec``; every record's opcode, channel, length and CDR header checked."""
    head = _records(buf, rec, FLOAT64_RECORD if msgtype == FLOAT64 else TEMPERATURE_PREFIX)
    if (np.any(head["opcode"] != MESSAGE_OPCODE) or np.any(head["channel"] != cid)
            or np.any(head["encap0"] != CDR_LE[0]) or np.any(head["encap1"] != CDR_LE[1])):
        raise NotBulk("message index does not point at this channel's little-endian CDR messages")
    data_len = head["length"].astype(np.int64) - (_MSG_PREFIX - 9)
    log_time = head["log_time"].astype(np.int64)
    if msgtype == FLOAT64:
        if np.any(data_len != 12):
            raise NotBulk("Float64 record of unexpected length")
        return log_time, head["data"].astype(np.float64)
    # Temperature: payload (after the 4-byte encapsulation) = stamp, frame_id, pad to 8, values
    value_at = ((12 + head["frame_id_len"].astype(np.int64) + 7) // 8) * 8
    if np.any(data_len != 4 + value_at + 16):
        raise NotBulk("Temperature record of unexpected length")
    value_pos = rec + _MSG_PREFIX + 4 + value_at
    if value_pos[-1] + 8 > buf.size or np.any(value_pos + 8 > buf.size):
        raise NotBulk("Temperature record runs past the chunk")
    return log_time, _gather(buf, value_pos, "<f8")


def read_scalar_topics(path, wanted) -> tuple[dict, int] | None:
    """``({topic: (log_times_ns int64, values float64)}, first_log_time_ns)`` for the wanted
    topics present in an MCAP bag, decoded in bulk; the times ascending (stable, rosbags'
    order). None when the bag needs the general decoder (module doc)."""
    f = mcap_file_of(Path(path))
    if f is None:
        return None
    try:
        return _read(f, set(wanted))
    except (NotBulk, IndexError):
        return None


def _open_summary(fh, wanted: set):
    """(summary, {channel id: (topic, message type)} of the wanted topics, chunk indexes in file
    order); NotBulk when the bag cannot take the bulk path."""
    from mcap.exceptions import McapError
    from mcap.reader import SeekingReader

    try:
        summary = SeekingReader(fh).get_summary()
    except (McapError, struct.error, ValueError, EOFError) as exc:
        raise NotBulk(str(exc)) from None
    if summary is None or not summary.chunk_indexes or summary.statistics is None:
        raise NotBulk("no summary / chunk index")
    if summary.statistics.message_count == 0:
        raise NotBulk("no messages")   # the general path words the error
    channels = {}
    for cid, ch in summary.channels.items():
        if ch.topic not in wanted:
            continue
        schema = summary.schemas.get(ch.schema_id)
        if ch.message_encoding != "cdr" or schema is None or schema.name not in SUPPORTED:
            raise NotBulk(f"{ch.topic}: not a bulk-decodable type")
        channels[cid] = (ch.topic, schema.name)
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    return summary, channels, chunks


def _chunk_parts(fh, ci, ordinal: int, channels: dict, counts: dict) -> list:
    """[(topic, log times, positions, values)] of the wanted channels' messages in one chunk
    (position = chunk ordinal << 32 | record offset: rosbags' order among equal log times)."""
    mine = [cid for cid in channels if cid in ci.message_index_offsets]
    if not mine:
        if any(counts.get(cid, 0) for cid in channels) and not ci.message_index_offsets:
            raise NotBulk("chunk without message index")
        return []
    if ci.uncompressed_size >= 1 << 32:
        raise NotBulk("chunk of 4 GiB or more")
    fh.seek(ci.chunk_start_offset)
    head = fh.read(9 + 8 + 8 + 8 + 4 + 4)
    if len(head) < 41 or head[0] != 0x06:
        raise NotBulk("not a chunk record")
    (crc, clen) = struct.unpack_from("<II", head, 33)
    compression = fh.read(clen).decode()
    (records_len,) = struct.unpack("<Q", fh.read(8))
    raw = _decompress(fh.read(records_len), compression, ci.uncompressed_size)
    if crc and zlib.crc32(raw) != crc:
        raise NotBulk("chunk checksum mismatch")   # the general path reports it
    buf = np.frombuffer(raw, dtype=np.uint8)
    index_start = ci.chunk_start_offset + ci.chunk_length
    fh.seek(index_start)
    index_block = fh.read(ci.message_index_length)
    parts = []
    for cid in mine:
        at = ci.message_index_offsets[cid] - index_start
        if index_block[at] != MESSAGE_INDEX_OPCODE:
            raise NotBulk("not a message index record")
        (rec_cid, nbytes) = struct.unpack_from("<HI", index_block, at + 9)
        if rec_cid != cid or nbytes % 16:
            raise NotBulk("message index mismatch")
        entries = np.frombuffer(index_block, dtype="<u8", count=nbytes // 8, offset=at + 15)
        rec = entries[1::2].astype(np.int64)
        if rec.size == 0:
            continue
        if not np.all(rec[1:] > rec[:-1]):
            rec.sort()
        if rec[0] < 0:
            raise NotBulk("message offset outside the chunk")
        topic, msgtype = channels[cid]
        log_time, values = _decode(buf, rec, cid, msgtype)
        parts.append((topic, log_time, rec + (ordinal << 32), values))
    return parts


def _first_time(summary, chunks) -> int:
    return min(int(summary.statistics.message_start_time), min(int(c.message_start_time) for c in chunks))


def _read(f: Path, wanted: set) -> tuple[dict, int]:
    with f.open("rb") as fh:
        summary, channels, chunks = _open_summary(fh, wanted)
        counts = summary.statistics.channel_message_counts
        parts = {topic: [] for topic, _ in channels.values()}
        for ordinal, ci in enumerate(chunks):
            for topic, log_time, position, values in _chunk_parts(fh, ci, ordinal, channels, counts):
                parts[topic].append((log_time, position, values))
        series = {}
        for topic, items in list(parts.items()):
            if not items:
                continue
            times = np.concatenate([p[0] for p in items])
            values = np.concatenate([p[2] for p in items])
            if np.all(times[1:] >= times[:-1]):        # written in time order: nothing to reorder
                series[topic] = (times, values)
            else:
                position = np.concatenate([p[1] for p in items])
                order = np.lexsort((position, times))
                series[topic] = (times[order], values[order])
            parts[topic] = None
        return series, _first_time(summary, chunks)


_EMPTY = (np.zeros(0, np.int64), np.zeros(0))


class ScalarStream:
    """The wanted topics of an MCAP bag decoded in bulk one chunk at a time (memory bounded by
    a chunk, not the bag): ``batches()`` yields ``{topic: (log_times_ns, values)}`` of the
    samples that are final — every later sample has a later log time — in the order
    ``read_scalar_topics`` gives them; the batches of a topic concatenated are its series
    there, bit for bit. Open with ``scalar_stream``; iterating may still raise ``NotBulk``
    (a corrupt chunk) after some batches: the caller then starts over with the general decoder.
    """

    def __init__(self, f: Path, wanted: set):
        self.file = f
        with f.open("rb") as fh:
            summary, self._channels, self._chunks = _open_summary(fh, wanted)
        for ci in self._chunks:
            if ci.compression not in ("", "lz4", "zstd"):
                raise NotBulk(f"chunk compression {ci.compression!r}")
        self._counts = dict(summary.statistics.channel_message_counts)
        self.first_ns = _first_time(summary, self._chunks)
        self.topics = {topic for cid, (topic, _) in self._channels.items() if self._counts.get(cid, 0) > 0}

    def batches(self):
        chunks = self._chunks
        # watermark after chunk j: the earliest log time any later chunk (file order) holds
        later_start = [0] * len(chunks)
        low = None
        for j in range(len(chunks) - 1, -1, -1):
            later_start[j] = low
            s = int(chunks[j].message_start_time)
            low = s if low is None else min(low, s)
        topics = sorted({topic for topic, _ in self._channels.values()})
        pending = {topic: None for topic in topics}    # (times, positions, values), sorted
        with self.file.open("rb") as fh:
            for ordinal, ci in enumerate(chunks):
                got = {}
                for topic, log_time, position, values in _chunk_parts(fh, ci, ordinal, self._channels, self._counts):
                    if log_time.min() < int(ci.message_start_time):
                        raise NotBulk("chunk index start time after a message of the chunk")
                    got.setdefault(topic, []).append((log_time, position, values))
                mark = later_start[ordinal]
                out = {}
                for topic in topics:
                    items = ([pending[topic]] if pending[topic] is not None else []) + got.get(topic, [])
                    if not items:
                        continue
                    if len(items) == 1:
                        times, position, values = items[0]
                    else:
                        times = np.concatenate([p[0] for p in items])
                        position = np.concatenate([p[1] for p in items])
                        values = np.concatenate([p[2] for p in items])
                    if times.size > 1 and not np.all(times[1:] >= times[:-1]):
                        order = np.lexsort((position, times))
                        times, position, values = times[order], position[order], values[order]
                    cut = times.size if mark is None else int(np.searchsorted(times, mark, side="left"))
                    if cut:
                        out[topic] = (times[:cut], values[:cut])
                    pending[topic] = (times[cut:], position[cut:], values[cut:]) if cut < times.size else None
                if out:
                    yield out


def scalar_stream(path, wanted) -> ScalarStream | None:
    """A ``ScalarStream`` of an MCAP bag, or None when it needs the general decoder."""
    f = mcap_file_of(Path(path))
    if f is None:
        return None
    try:
        return ScalarStream(f, set(wanted))
    except (NotBulk, IndexError):
        return None


def mcap_header(path) -> tuple[int, set] | None:
    """(log time of the first message, topics with messages) from an MCAP bag's summary, or
    None (not a single-file MCAP bag with statistics: ask rosbags)."""
    f = mcap_file_of(Path(path))
    if f is None:
        return None
    from mcap.exceptions import McapError
    from mcap.reader import SeekingReader

    try:
        with f.open("rb") as fh:
            summary = SeekingReader(fh).get_summary()
    except (McapError, struct.error, ValueError, EOFError, OSError):
        return None
    if summary is None or summary.statistics is None or not summary.statistics.message_count:
        return None
    counts = summary.statistics.channel_message_counts
    topics = {ch.topic for cid, ch in summary.channels.items() if counts.get(cid, 0) > 0}
    return int(summary.statistics.message_start_time), topics

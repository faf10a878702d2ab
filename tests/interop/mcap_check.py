#!/usr/bin/env python3
"""Reads a presrs MCAP file with the `mcap` package (an independent reader) and prints one
JSON object: channels with their schemas and message counts, whether log times go forward in
file order, each image's size and CRC-32 (zlib's: the tactile transfer's own CRC), each
terrain topic's steps and terrain names.

    mcap_check.py FILE            a finished file: summary and chunk indexes must be there
    mcap_check.py FILE --stream   a file whose writer was killed: read records in order until
                                  the torn end (reports where it stopped)
"""
import base64, json, sys, zlib
from collections import defaultdict

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.records import Channel, Chunk, Message, Schema

def main(path, stream):
    out = {"channels": {}, "file_order_nondecreasing": True, "images": defaultdict(list),
           "steps": defaultdict(list), "terrains": defaultdict(list), "messages": 0}
    schemas, channels, last = {}, {}, 0

    def on_message(ch, data, log_time):
        nonlocal last
        if log_time < last:
            out["file_order_nondecreasing"] = False
        last = log_time
        out["messages"] += 1
        c = out["channels"][ch.topic]
        c["count"] += 1
        m = json.loads(data)
        if c["schema_name"] == "foxglove.RawImage":
            px = base64.b64decode(m["data"])
            out["images"][ch.topic].append([m["width"], m["height"], m["encoding"], zlib.crc32(px), len(px)])
        elif c["schema_name"] == "presrs.TerrainClass":
            out["steps"][ch.topic].append(m["Step"])
            out["terrains"][ch.topic].append(m["Terrain"])

    def on_channel(ch):
        channels[ch.id] = ch
        s = schemas.get(ch.schema_id)
        out["channels"].setdefault(ch.topic, {
            "schema_id": ch.schema_id,
            "schema_name": s.name if s else None,
            "schema_encoding": s.encoding if s else None,
            "schema_is_json": bool(s) and isinstance(json.loads(s.data), dict),
            "message_encoding": ch.message_encoding,
            "count": 0,
        })

    with open(path, "rb") as f:
        if stream:
            out["torn_end"] = None
            try:
                for rec in StreamReader(f, skip_magic=False, emit_chunks=False).records:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec
                    elif isinstance(rec, Channel):
                        on_channel(rec)
                    elif isinstance(rec, Message):
                        on_message(channels[rec.channel_id], rec.data, rec.log_time)
            except Exception as e:  # the record the kill cut short
                out["torn_end"] = f"{type(e).__name__}: {e}"
        else:
            r = make_reader(f)
            summary = r.get_summary()
            out["chunks"] = len(summary.chunk_indexes)
            out["statistics_messages"] = summary.statistics.message_count
            for s in summary.schemas.values():
                schemas[s.id] = s
            for ch in summary.channels.values():
                on_channel(ch)
            for s, ch, m in r.iter_messages(log_time_order=False):
                on_message(ch, m.data, m.log_time)
    print(json.dumps(out))

if __name__ == "__main__":
    main(sys.argv[1], "--stream" in sys.argv[2:])

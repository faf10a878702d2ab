#!/usr/bin/env python3
"""Independent client for the interop tests: Python cantools and python-can against our DBC.

decode DBC VECTORS.json   decode frames made by our Rust encoder, compare every signal
encode DBC OUT.json SEED  encode random messages (and whole tactile images) with cantools
log DBC LOG               read a candump log with python-can, decode it with cantools, print a summary
choice DBC ID HEX SIGNAL  decode one frame and print the signal's named value (its VAL_ choice)
"""
import json
import random
import sys
import zlib

import cantools


def load(dbc):
    """The DBC parsed by cantools. With PRESRS_DBC_CACHE set (tests/vcan/run.sh sets it), the
    parsed database is kept there, pickled under the file's SHA-256, and reused: parsing
    presrs.dbc takes cantools 3.7 s on the host and most of a minute in the emulated VM, where
    the same database then loads in seconds (measured 2026-11-24)."""
    import os
    cache = os.environ.get("PRESRS_DBC_CACHE")
    if not cache:
        return cantools.database.load_file(dbc)
    import hashlib
    import pickle
    with open(dbc, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    path = os.path.join(cache, f"dbc-{digest}-cantools-{cantools.__version__}.pickle")
    try:
        with open(path, "rb") as f:
            return pickle.load(f)
    except OSError:
        pass
    db = cantools.database.load_file(dbc)
    try:
        os.makedirs(cache, exist_ok=True)
        with open(path + ".tmp", "wb") as f:
            pickle.dump(db, f)
        os.replace(path + ".tmp", path)
    except OSError:
        pass  # a read-only cache: parse each time
    return db


def frame_id(v):
    return v["id"]


def decode(dbc, vectors):
    db = load(dbc)
    vecs = json.load(open(vectors))
    bad = 0
    n_sig = 0
    for v in vecs:
        msg = db.get_message_by_frame_id(frame_id(v))
        got = msg.decode(bytes.fromhex(v["data"]), decode_choices=False)
        for name, want in v["expected"].items():
            n_sig += 1
            if name not in got:
                print(f"{msg.name}: signal {name} missing from cantools' decode {got}")
                bad += 1
                continue
            sig = msg.get_signal_by_name(name)
            tol = abs(sig.scale) * 0.5 + 1e-9
            if abs(float(got[name]) - float(want)) > tol:
                print(f"{msg.name}: {name} cantools={got[name]} ours={want}")
                bad += 1
    print(f"cantools decoded {len(vecs)} frames, {n_sig} signals, {bad} mismatches")
    return 1 if bad else 0


def choice(dbc, frame_id_text, data_hex, signal):
    msg = load(dbc).get_message_by_frame_id(int(frame_id_text))
    print(msg.decode(bytes.fromhex(data_hex), decode_choices=True)[signal])
    return 0


def rand_value(rng, sig):
    lo = sig.minimum if sig.minimum is not None else 0
    hi = sig.maximum if sig.maximum is not None else 0
    raw_lo = round((lo - sig.offset) / sig.scale)
    raw_hi = round((hi - sig.offset) / sig.scale)
    raw = rng.randint(int(raw_lo), int(raw_hi))
    return raw * sig.scale + sig.offset


def encode(dbc, out, seed):
    db = load(dbc)
    rng = random.Random(int(seed))
    vectors = []
    for msg in db.messages:
        if msg.name.startswith("Tactile"):
            continue
        for _ in range(20):
            sigs = {s.name: rand_value(rng, s) for s in msg.signals}
            data = msg.encode(sigs, strict=True)
            vectors.append({"name": msg.name, "id": msg.frame_id & 0x1FFFFFFF,
                            "extended": msg.is_extended_frame, "data": data.hex(),
                            "signals": sigs})
    images = []
    for name, dps, first in (("TactileFrame_F2", 62, 1), ("TactileFrameClassic_F2", 5, 3)):
        msg = db.get_message_by_name(name)
        rows, cols = 44, 44
        pixels = [rng.randint(0, 255) for _ in range(rows * cols)]
        payload = bytes(pixels)
        count = -(-len(payload) // dps)
        frames = []
        head = {"FrameSeq": 9, "SegmentIndex": 0, "Rows": rows, "Cols": cols, "BitsPerPixel": 8,
                "SegmentCount": count}
        if first == 1:
            head.update({"Crc32": zlib.crc32(payload), "TimestampUs": 4242})
            frames.append(msg.encode(head).hex())
        else:
            frames.append(msg.encode(head).hex())
            frames.append(msg.encode({"FrameSeq": 9, "SegmentIndex": 1, "Crc32": zlib.crc32(payload)}).hex())
            frames.append(msg.encode({"FrameSeq": 9, "SegmentIndex": 2, "TimestampUs": 4242}).hex())
        for s in range(count):
            chunk = payload[s * dps:(s + 1) * dps].ljust(dps, b"\0")
            sig = {"FrameSeq": 9, "SegmentIndex": first + s}
            sig.update({f"Px{i:02}": chunk[i] for i in range(dps)})
            frames.append(msg.encode(sig).hex())
        images.append({"name": name, "id": msg.frame_id, "frames": frames, "pixels": pixels})
    json.dump({"vectors": vectors, "images": images}, open(out, "w"))
    print(f"cantools encoded {len(vectors)} messages and {len(images)} tactile images")
    return 0


def log(dbc, path):
    import can
    db = load(dbc)
    n = 0
    kinds = {}
    images = 0
    for m in can.CanutilsLogReader(path):
        msg = db.get_message_by_frame_id(m.arbitration_id)
        sig = msg.decode(bytes(m.data), decode_choices=False)
        kind = msg.name.split("_F")[0]
        kinds[kind] = kinds.get(kind, 0) + 1
        if kind == "TactileFrame" and sig["SegmentIndex"] == 0:
            images += 1
        if kind == "TactileFrame" and not (m.is_fd and m.bitrate_switch and len(m.data) == 64):
            print(f"tactile frame not FD/BRS/64: {m}")
            return 1
        n += 1
    print(json.dumps({"frames": n, "kinds": kinds, "tactile_headers": images}))
    return 0


if __name__ == "__main__":
    cmd = sys.argv[1]
    sys.exit({"decode": decode, "encode": encode, "log": log, "choice": choice}[cmd](*sys.argv[2:]))

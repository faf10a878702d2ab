#!/usr/bin/env python3
"""Independent clients for the ROS 2 tests: Python `eclipse-zenoh` (a router and a
subscriber, by key expression and liveliness token, as rmw_zenoh's graph cache reads them),
`rosbags` (CDR, RIHS01 hashes, rosbag2 directories) and cantools/python-can (the candump log).

router PORT                     a Zenoh router on tcp/127.0.0.1:PORT until killed
subscribe PORT OUT.json SECONDS  subscribe to every key and liveliness token through that
                                 router for SECONDS (or until OUT.json.stop exists); decode
                                 every payload with rosbags
bag DIR DBC CANDUMP             read a rosbag2 directory with rosbags and compare it with the
                                 candump log decoded by cantools
live SUB.json BAGDIR...         the subscriber saw each bag's messages, once, in order

Each prints a JSON summary; a failed check exits 1 saying what differs.
"""
import json
import math
import os
import sys
import time
from collections import Counter, defaultdict

HERE = os.path.dirname(os.path.abspath(__file__))
MSG_DIR = os.path.join(HERE, "..", "..", "ros2", "presrs_msgs", "msg")


def fail(msg):
    print(f"ros2_check: {msg}", file=sys.stderr)
    sys.exit(1)


def typestore():
    """ROS 2 Jazzy's standard types, and ours from ros2/presrs_msgs/msg/*.msg."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    add = {}
    for f in sorted(os.listdir(MSG_DIR)):
        name = f"presrs_msgs/msg/{f[:-4]}"
        add.update(get_types_from_msg(open(os.path.join(MSG_DIR, f)).read(), name))
    ts.register(add)
    return ts


def dds_to_ros(dds):
    """`pkg::msg::dds_::Name_` -> `pkg/msg/Name`."""
    pkg, kind, _, name = dds.split("::")
    return f"{pkg}/{kind}/{name[:-1]}"


def zenoh_config(port, mode):
    import zenoh

    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    key = "listen/endpoints" if mode == "router" else "connect/endpoints"
    c.insert_json5(key, json.dumps([f"tcp/127.0.0.1:{port}"]))
    c.insert_json5("scouting/multicast/enabled", "false")
    if mode == "client":
        # Reconnect fast and forever when the router goes away and comes back.
        c.insert_json5("connect/timeout_ms", "-1")
        c.insert_json5("connect/exit_on_failure", "false")
        c.insert_json5(
            "connect/retry",
            "{period_init_ms: 100, period_max_ms: 500, period_increase_factor: 2}",
        )
    return c


def router(port):
    import zenoh

    s = zenoh.open(zenoh_config(port, "router"))
    print("router ready", flush=True)
    try:
        while True:
            time.sleep(1)
    finally:
        s.close()


def attachment(raw):
    """rmw_zenoh's attachment, read with zenoh-ext's deserializer: sequence number, source
    timestamp (int64 each), GID (16 bytes)."""
    from zenoh.ext import Int64, z_deserialize
    import zenoh

    seq = z_deserialize(Int64, zenoh.ZBytes(raw[:8]))
    ts = z_deserialize(Int64, zenoh.ZBytes(raw[8:16]))
    if raw[16] != 16 or len(raw) != 33:
        fail(f"attachment: expected 8+8+1+16 bytes (a 16-byte GID), got {raw.hex()}")
    return int(seq), int(ts), raw[17:].hex()


def subscribe(port, out, seconds):
    import zenoh

    ts = typestore()
    s = zenoh.open(zenoh_config(port, "client"))
    samples = []
    tokens = set()

    def on_sample(sample):
        att = sample.attachment.to_bytes() if sample.attachment is not None else b""
        samples.append((str(sample.key_expr), time.time(), sample.payload.to_bytes(), att))

    def on_token(sample):
        if sample.kind == zenoh.SampleKind.PUT:
            tokens.add(str(sample.key_expr))

    sub = s.declare_subscriber("**", on_sample)
    lsub = s.liveliness().declare_subscriber("@ros2_lv/**", on_token, history=True)
    print("subscriber ready", flush=True)
    # Until SECONDS, or until OUT.json.stop appears.
    end = time.time() + seconds
    while time.time() < end and not os.path.exists(out + ".stop"):
        time.sleep(0.05)
    sub.undeclare()
    lsub.undeclare()
    s.close()

    topics = {}
    hashes = {}
    for key, t_recv, payload, att in samples:
        parts = key.split("/")
        if len(parts) < 4 or not parts[-1].startswith("RIHS01_"):
            continue
        domain, dds, hsh = parts[0], parts[-2], parts[-1]
        topic = "/" + "/".join(parts[1:-2])
        ros_type = dds_to_ros(dds)
        want = ts.hash_rihs01(ros_type)
        if hsh != want:
            fail(f"{key}: our hash {hsh}, rosbags computes {want} for {ros_type}")
        hashes[ros_type] = hsh
        msg = ts.deserialize_cdr(payload, ros_type)
        seq, src_ns, gid = attachment(att)
        t = topics.setdefault(
            topic,
            {"type": ros_type, "domain": domain, "count": 0, "seqs": [], "gids": set(),
             "recv": [], "src": [], "values": []},
        )
        t["count"] += 1
        t["seqs"].append(seq)
        t["gids"].add(gid)
        t.setdefault("gid_of", []).append(gid)
        t["recv"].append(t_recv)
        t["src"].append(src_ns / 1e9)
        t["values"].append(summary(ros_type, msg))
    for topic, t in topics.items():
        t["gids"] = sorted(t["gids"])
    json.dump(
        {"topics": topics, "hashes": hashes, "tokens": sorted(tokens)},
        open(out, "w"),
    )
    print(json.dumps({"samples": len(samples), "topics": len(topics), "tokens": len(tokens)}))


def summary(ros_type, m):
    """The values the tests compare, per type."""
    if ros_type == "presrs_msgs/msg/TerrainClass":
        # Unknown ground chose no terrain: its confidence is NaN.
        conf = None if math.isnan(m.confidence) else round(m.confidence * 200)
        return [m.foot, m.step, m.terrain_id, m.terrain_name, conf,
                m.unknown_reason, m.flags, m.latency_us]
    if ros_type == "presrs_msgs/msg/FootContact":
        return [m.foot, bool(m.stance), m.seq, m.foot_timestamp_us]
    if ros_type == "presrs_msgs/msg/GaitState":
        return [m.gait, m.terrain_id, m.reason, m.foot]
    if ros_type == "presrs_msgs/msg/StepState":
        return [m.leg, round(m.speed_m_s, 3), round(m.stance_s, 3), round(m.flight_s, 3),
                round(m.energy_ratio, 3)]
    if ros_type == "sensor_msgs/msg/JointState":
        return [list(m.name), [round(p, 4) for p in m.position]]
    if ros_type == "sensor_msgs/msg/Image":
        return [m.height, m.width, m.encoding, m.step, len(m.data), int(m.data.astype("int64").sum())]
    if ros_type == "diagnostic_msgs/msg/DiagnosticArray":
        return [[s.name, int(s.level), s.message] for s in m.status]
    return None


def read_bag(path):
    from rosbags.rosbag2 import Reader

    ts = typestore()
    out = defaultdict(list)
    types = {}
    with Reader(path) as r:
        for c in r.connections:
            want = ts.hash_rihs01(c.msgtype)
            if c.digest and c.digest != want:
                fail(f"{path}: {c.topic}: metadata hash {c.digest}, rosbags computes {want}")
            types[c.topic] = c.msgtype
        for c, t, raw in r.messages():
            out[c.topic].append((t, summary(c.msgtype, ts.deserialize_cdr(raw, c.msgtype))))
    return out, types


def candump(dbc, log):
    """The log's messages decoded by cantools, per kind and foot, in order."""
    import can
    import cantools

    db = cantools.database.load_file(dbc)
    out = defaultdict(list)
    for m in can.CanutilsLogReader(log):
        try:
            msg = db.get_message_by_frame_id(m.arbitration_id)
        except KeyError:
            continue
        name = msg.name
        kind, _, foot = name.partition("_F")
        foot = int(foot) if foot else 0
        if kind.startswith("Tactile"):
            continue
        v = msg.decode(bytes(m.data), decode_choices=False)
        out[(kind, foot)].append(v)
    return out


def bag(path, dbc, log):
    msgs, types = read_bag(path)
    frames = candump(dbc, log)
    ns = os.environ.get("PRESRS_NS", "")
    checked = {}

    def topic(rel):
        return f"{ns}/{rel}"

    for (kind, foot), vals in frames.items():
        if kind == "TerrainClass":
            got = [v for _, v in msgs.get(topic(f"foot{foot}/terrain"), [])]
            want = [[foot, v["Step"], v["TerrainId"], None,
                     None if v["TerrainId"] == 255 else round(v["Confidence"] * 2), None,
                     None, v["LatencyUs"]] for v in vals]
            strip = [[g[0], g[1], g[2], None, g[4], None, None, g[7]] for g in got]
            if strip != want:
                fail(f"{path}: foot{foot}/terrain differs from the log: {len(got)} vs {len(want)} "
                     f"messages; first {strip[:2]} vs {want[:2]}")
        elif kind == "FootContact":
            got = [v for _, v in msgs.get(topic(f"foot{foot}/contact"), [])]
            want = [[foot, bool(v["Contact"]), v["Sequence"], v["TimestampUs"]] for v in vals]
            if got != want:
                fail(f"{path}: foot{foot}/contact differs from the log ({len(got)} vs {len(want)})")
        elif kind == "LegState":
            got = [v[1] for _, v in msgs.get(topic(f"leg{foot}/joint_states"), [])]
            want = [[round(v["LegAngle"], 4), round(v["LegLength"], 4)] for v in vals]
            if len(got) != len(want) or any(
                abs(a - b) > 1e-4 for g, w in zip(got, want) for a, b in zip(g, w)
            ):
                fail(f"{path}: leg{foot}/joint_states differs from the log ({len(got)} vs {len(want)})")
        elif kind == "GaitStatus":
            got = [v for _, v in msgs.get(topic("gait"), [])]
            want = [[v["ActiveGait"], v["TerrainId"], None, v["Foot"]] for v in vals]
            if [[g[0], g[1], None, g[3]] for g in got] != want:
                fail(f"{path}: gait differs from the log ({len(got)} vs {len(want)})")
        elif kind in ("NodeStatus", "LegStatus"):
            continue
        else:
            continue
        checked[f"{kind}_F{foot}"] = len(vals)
    diag = len(msgs.get("/diagnostics", []))
    want_diag = sum(len(v) for (k, _), v in frames.items() if k in ("NodeStatus", "LegStatus"))
    if diag != want_diag:
        fail(f"{path}: {diag} /diagnostics, the log has {want_diag} NodeStatus and LegStatus")
    images = {t: len(v) for t, v in msgs.items() if t.endswith("/image")}
    for t, v in msgs.items():
        if t.endswith("/image"):
            for _, (h, w, enc, step, n, _) in v:
                if (h, w, enc, step, n) != (44, 44, "mono8", 44, 44 * 44):
                    fail(f"{path}: {t}: image {h}x{w} {enc} step {step}, {n} bytes")
    print(json.dumps({"checked": checked, "diagnostics": diag, "images": images,
                      "types": types}))


def live(sub_json, bags):
    """Each bag's messages, each topic from one publisher (a GID: `/diagnostics` has one per
    robot), all received, once, in order."""
    sub = json.load(open(sub_json))
    topics = sub["topics"]
    report = {}
    for b in bags:
        msgs, _ = read_bag(b)
        for topic, vals in msgs.items():
            got = topics.get(topic)
            if got is None:
                fail(f"the subscriber saw nothing on {topic} ({len(vals)} in {b})")
            want = [v for _, v in vals]
            by_gid = defaultdict(lambda: ([], []))
            for gid, seq, v in zip(got["gid_of"], got["seqs"], got["values"]):
                by_gid[gid][0].append(seq)
                by_gid[gid][1].append(v)
            match = [g for g, (_, vs) in by_gid.items() if vs == want]
            if not match:
                best = max(len(vs) for _, vs in by_gid.values())
                fail(f"{topic}: no publisher's messages equal {b}'s {len(want)} "
                     f"(the subscriber got at most {best} from one publisher)")
            seqs = by_gid[match[0]][0]
            if seqs != sorted(set(seqs)):
                fail(f"{topic}: sequence numbers out of order or repeated")
            report[topic] = len(seqs)
    print(json.dumps({"topics": report}))


def yaml_load(text):
    """YAML by ruamel.yaml (rosbags' own YAML library: no other package needed)."""
    from ruamel.yaml import YAML

    return YAML(typ="safe").load(text)


QOS_FIELDS = ("reliability", "durability", "history", "depth")


def qos_ok(text_or_list, where):
    """An offered QoS profile list as rosbag2 writes it: YAML (text, or already parsed) with a
    known reliability, durability and history and a depth."""
    items = yaml_load(text_or_list) if isinstance(text_or_list, str) else text_or_list
    if not isinstance(items, list) or not items:
        fail(f"{where}: offered_qos_profiles is not a list of profiles: {text_or_list!r}")
    for q in items:
        missing = [k for k in QOS_FIELDS if k not in q]
        if missing:
            fail(f"{where}: QoS profile lacks {missing}: {q}")
        if q["reliability"] not in ("reliable", "best_effort") or q["durability"] not in (
                "volatile", "transient_local") or q["history"] not in ("keep_last", "keep_all"):
            fail(f"{where}: QoS values not ROS 2's: {q}")
        if not isinstance(q["depth"], int):
            fail(f"{where}: depth {q['depth']!r}")
    return items[0]


def model(path, csv_path, ns):
    """`presrs mcap --ros2 --model`'s bag against `presrs node --replay --csv`'s table: one
    footN/terrain/model message per row, with its values; and every topic's QoS, in
    metadata.yaml and in the MCAP channel, parses as YAML with the four fields."""
    import csv as csvmod

    from mcap.reader import make_reader

    msgs, _ = read_bag(path)
    rows = list(csvmod.DictReader(open(csv_path)))
    by_foot = defaultdict(list)
    for r in rows:
        by_foot[int(r["foot"])].append(r)
    compared = 0
    for foot, want in by_foot.items():
        got = [(t, v) for t, v in msgs.get(f"{ns}/foot{foot}/terrain/model", [])]
        if len(got) != len(want):
            fail(f"{path}: {len(got)} foot{foot}/terrain/model messages, the CSV has {len(want)} rows")
        for (t, g), r in zip(got, want):
            conf = None if r["confidence_pct"] == "" else round(float(r["confidence_pct"]) * 2)
            w = [foot, int(r["step"]), r["terrain"], conf, r["unknown_reason"]]
            if [g[0], g[1], g[3], g[4], g[5]] != w:
                fail(f"{path}: foot{foot}/terrain/model {g} differs from the CSV row {r}")
            decided_ns = int(round(float(r["decision_s"]) * 1e6)) * 1000
            if t != decided_ns:
                fail(f"{path}: message at {t} ns, the CSV decided it at {decided_ns}")
            compared += 1
    meta = yaml_load(open(os.path.join(path, "metadata.yaml")).read())["rosbag2_bagfile_information"]
    profiles = {}
    for tm in meta["topics_with_message_count"]:
        m = tm["topic_metadata"]
        profiles[m["name"]] = qos_ok(m["offered_qos_profiles"], f"metadata.yaml {m['name']}")
    mcaps = [f for f in os.listdir(path) if f.endswith(".mcap")]
    with open(os.path.join(path, mcaps[0]), "rb") as f:
        for ch in make_reader(f).get_summary().channels.values():
            qos_ok(ch.metadata["offered_qos_profiles"], f"MCAP channel {ch.topic}")
    print(json.dumps({"compared": compared, "ros_distro": meta.get("ros_distro"),
                      "version": meta.get("version"), "qos": profiles}))


def main():
    cmd = sys.argv[1] if len(sys.argv) > 1 else ""
    if cmd == "router":
        router(int(sys.argv[2]))
    elif cmd == "subscribe":
        subscribe(int(sys.argv[2]), sys.argv[3], float(sys.argv[4]))
    elif cmd == "bag":
        bag(sys.argv[2], sys.argv[3], sys.argv[4])
    elif cmd == "live":
        live(sys.argv[2], sys.argv[3:])
    elif cmd == "model":
        model(sys.argv[2], sys.argv[3], os.environ.get("PRESRS_NS", ""))
    else:
        fail(__doc__)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""An independent Foxglove WebSocket client (protocol foxglove.sdk.v1, formerly foxglove.websocket.v1, spoken with the
plain `websockets` package): connects to a presrs live view, subscribes to the topics given,
and prints one JSON line per topic with the first message received on it, then exits.

    foxglove_client.py ws://127.0.0.1:8765 /foot0/image /foot0/terrain [--timeout 60] [--ready FILE]

--ready FILE: the file is created once the server has said hello (serverInfo), so that a test
starts the robot only when the client can see it. (In the vcan VM under load, this script
took up to 80 s from its start to its first connection: the pyenv shim and `import websockets`
alone took 14 s and more; a simulator started after a fixed 1.5 s had finished by then, and
the client, subscribed in time for nothing, got no data.)

Exits 1 when a topic got nothing before the timeout (the line says which)."""
import asyncio, json, struct, sys, time

import websockets


async def main(url, topics, timeout, ready=None):
    deadline = time.monotonic() + timeout
    ws = None
    while ws is None:  # the server may still be starting
        try:
            ws = await websockets.connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None)
        except OSError:
            if time.monotonic() > deadline:
                print(json.dumps({"error": f"cannot connect to {url}"}))
                return 1
            await asyncio.sleep(0.2)
    subs, got, schemas, next_id = {}, {}, {}, 1
    # What the server said, for the error line when a topic gets nothing: its advertised
    # topics, its status messages and how many data messages came at all.
    advertised, statuses, data_messages = [], [], 0
    # channel id per wanted topic, from the server's advertisements
    channels = {}
    # foxglove's server can answer a subscribe sent right after a channel's advertisement
    # with "unknown channel" (seen once in CI, 2026-11-24: /gait, advertised, then refused
    # 0.2 s later, nothing ever sent; the SDK has known races between a channel's
    # registration and subscriptions to it, foxglove/foxglove-sdk#533). A client asks again for
    # what it still has no data on, as the Foxglove app does when a panel is reopened.
    retry_every, last_try = 2.0, time.monotonic()
    async with ws:
        while len(got) < len(topics):
            left = deadline - time.monotonic()
            if left <= 0:
                break
            if time.monotonic() - last_try >= retry_every:
                last_try = time.monotonic()
                again = []
                for topic, ch_id in channels.items():
                    if topic not in got:
                        subs[next_id] = topic
                        again.append({"id": next_id, "channelId": ch_id})
                        next_id += 1
                if again:
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": again}))
            try:
                msg = await asyncio.wait_for(ws.recv(), min(left, retry_every))
            except asyncio.TimeoutError:
                continue
            if isinstance(msg, str):
                m = json.loads(msg)
                if m.get("op") == "serverInfo" and ready:
                    open(ready, "w").close()
                if m.get("op") == "status":
                    statuses.append(m.get("message", ""))
                if m.get("op") == "advertise":
                    new = []
                    advertised.extend(ch["topic"] for ch in m["channels"])
                    for ch in m["channels"]:
                        if ch["topic"] not in topics:
                            continue
                        first = ch["topic"] not in channels
                        # A topic advertised again (a new channel id) is retried on the new id.
                        channels[ch["topic"]] = ch["id"]
                        schemas[ch["topic"]] = (ch["schemaName"], ch["encoding"], ch.get("schema", ""))
                        if first:
                            subs[next_id] = ch["topic"]
                            new.append({"id": next_id, "channelId": ch["id"]})
                            next_id += 1
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            else:
                op = msg[0]
                if op != 1:  # MessageData
                    continue
                data_messages += 1
                sub, log_time = struct.unpack_from("<IQ", msg, 1)
                topic = subs.get(sub)
                if topic and topic not in got:
                    name, enc, schema = schemas[topic]
                    got[topic] = {
                        "topic": topic,
                        "schema_name": name,
                        "encoding": enc,
                        "schema_is_json": bool(json.loads(schema)) if schema else False,
                        "log_time": log_time,
                        "message": json.loads(msg[13:].decode()),
                    }
    for t in topics:
        nothing = {"topic": t, "error": "nothing received", "advertised": advertised,
                   "server_status": statuses[-5:], "data_messages": data_messages}
        print(json.dumps(got.get(t, nothing)))
    return 0 if len(got) == len(topics) else 1


if __name__ == "__main__":
    args = sys.argv[1:]
    timeout, ready = 60.0, None
    if "--timeout" in args:
        i = args.index("--timeout")
        timeout = float(args[i + 1])
        del args[i : i + 2]
    if "--ready" in args:
        i = args.index("--ready")
        ready = args[i + 1]
        del args[i : i + 2]
    sys.exit(asyncio.run(main(args[0], args[1:], timeout, ready)))

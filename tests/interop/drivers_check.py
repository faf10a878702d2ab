#!/usr/bin/env python3
"""The motor drivers' own Python packages against our leg bridge and simulated drivers.

Reads a JSON file of vectors written by tests/interop_drivers.rs and prints JSON:
- moteus (mjbots' `moteus` package): decodes our bridge's commands and our simulated moteus's
  replies with `moteus.protocol.parse_registers`, and encodes position commands with
  `moteus.Controller.make_position` for our simulated moteus to read;
- ODrive CANSimple: decodes our frames and encodes the ODrive's with cantools reading the DBC
  that ships in the `odrive-can` package (odrive-cansimple-0.6.10.dbc);
- MIT protocol (`mini-cheetah-motor-driver-socketcan`): encodes commands with
  `CanMotorController.send_rad_command` (its socket replaced by a capture) and decodes our
  simulated motor's replies with its `decode_motor_status` / `convert_raw_to_physical_rad`.

`drivers_check.py log SPEC.json` instead reads the candump log of a closed-loop run
(`presrs demo --leg P --candump LOG`) with python-can's own reader and decodes every motor
frame in it with the protocol's package, one JSON row per frame, in the log's order:
{"t", "joint", "kind", ...values in rad, rad/s, N m/rad, N m s/rad, N m}.
"""
import json
import math
import os
import sys

import cantools
import moteus
import moteus.protocol as mp
import odrive_can
from motor_driver import canmotorlib


def num(x):
    """A number for JSON: NaN (a moteus "no value") as null."""
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else x


def moteus_part(v):
    reg = mp.Register
    out = {"commands": [], "replies": [], "made": []}
    for c in v["commands"]:
        r = mp.parse_registers(bytes.fromhex(c))
        cmd = r.command
        out["commands"].append({
            "mode": num(cmd.get(reg.MODE)),
            "position": num(cmd.get(reg.COMMAND_POSITION)),
            "velocity": num(cmd.get(reg.COMMAND_VELOCITY)),
            "feedforward_torque": num(cmd.get(reg.COMMAND_FEEDFORWARD_TORQUE)),
            "kp_scale": num(cmd.get(reg.COMMAND_KP_SCALE)),
            "kd_scale": num(cmd.get(reg.COMMAND_KD_SCALE)),
            "watchdog": num(cmd.get(reg.COMMAND_TIMEOUT)),
            "queried": sorted(q[0] for q in r.query),
        })
    for d in v["replies"]:
        resp = mp.parse_reply(bytes.fromhex(d))
        out["replies"].append({
            "mode": int(resp[reg.MODE]),
            "position": resp[reg.POSITION],
            "velocity": resp[reg.VELOCITY],
            "torque": resp[reg.TORQUE],
            "fault": int(resp[reg.FAULT]),
        })
    for m in v["make"]:
        c = moteus.Controller(id=m["id"])
        cmd = c.make_position(position=m["position"], velocity=m["velocity"],
                              feedforward_torque=m["feedforward_torque"],
                              kp_scale=m["kp_scale"], kd_scale=m["kd_scale"],
                              watchdog_timeout=m["watchdog"], query=True)
        # As moteus.transport builds the arbitration id from a Command.
        arb = (cmd.destination | (0x8000 if cmd.reply_required else 0) | (cmd.source << 8)
               | (cmd.can_prefix << 16))
        out["made"].append({"id": arb, "data": bytes(cmd.data).hex()})
    return out


def odrive_part(v):
    dbc = os.path.join(os.path.dirname(odrive_can.__file__), "dbc", "odrive-cansimple-0.6.10.dbc")
    db = cantools.database.load_file(dbc)
    out = {"decoded": [], "encoded": []}
    for f in v["frames"]:
        node, cmd = f["id"] >> 5, f["id"] & 0x1F
        msg = db.get_message_by_frame_id(cmd)  # the DBC describes axis 0 (node 0)
        sig = msg.decode(bytes.fromhex(f["data"]), decode_choices=False, scaling=True)
        out["decoded"].append({"node": node, "name": msg.name, "signals": {k: float(x) for k, x in sig.items()}})
    for e in v["encode"]:
        msg = db.get_message_by_name(e["name"])
        full = {s.name: 0 for s in msg.signals}
        full.update(e["signals"])
        data = msg.encode(full, scaling=True)
        out["encoded"].append({"id": (e["node"] << 5) | msg.frame_id, "data": data.hex()})
    return out


class Capture(canmotorlib.CanMotorController):
    """The driver with its socket replaced: sent frames are kept, replies are ours."""

    def __init__(self, motor_type, reply):
        canmotorlib.CanMotorController.can_socket_declared = True  # no socket is opened
        super().__init__(can_socket="none", motor_id=1, motor_type=motor_type)
        self.sent = []
        self.reply = reply

    def _send_can_frame(self, data):
        self.sent.append(bytes(data))

    def _recv_can_frame(self):
        return 0, len(self.reply), self.reply


def mit_part(v):
    # Our model names with dashes and dots ("AK80-9-V1.1"); the driver's: "AK80_9_V1p1".
    model = v["model"].replace("-", "_").replace(".", "p")
    out = {"encoded": [], "replies": []}
    for c in v["commands"]:
        m = Capture(model, bytes(6))
        m.send_rad_command(c["position"], c["velocity"], c["kp"], c["kd"], c["torque"])
        out["encoded"].append(m.sent[-1].hex())
    for d in v["replies"]:
        m = Capture(model, bytes.fromhex(d))
        raw = m.decode_motor_status(bytes.fromhex(d))
        p, vel, t = m.convert_raw_to_physical_rad(*raw)
        # The driver applies its model's AXIS_DIRECTION; the wire value is before it.
        s = m.motorParams["AXIS_DIRECTION"]
        out["replies"].append({"position": p * s, "velocity": vel * s, "torque": t * s})
    return out


def log_moteus(msg, spec):
    """A moteus frame: ids are (source << 8) | destination, 0x8000 when a reply is asked."""
    reg = mp.Register
    dest, source = msg.arbitration_id & 0x7F, (msg.arbitration_id >> 8) & 0x7F
    ours = spec["source"]
    if source == ours and dest in spec["joints"]:
        r = mp.parse_registers(bytes(msg.data))
        cmd = r.command
        mode = cmd.get(reg.MODE)
        row = {"joint": dest, "kind": "command", "mode": num(mode)}
        if mode is not None and int(mode) == 10:  # position mode
            # moteus position mode: kp_scale times the configured servo.pid_position.kp
            # (N m per revolution of error), so N m/rad is scale * kp / 2 pi.
            kp_full, kd_full = spec["joints"][dest]
            # Revolutions to rad; NaN (moteus: "no value") stays none.
            rad = lambda x: None if num(x) is None else x * 2 * math.pi
            row.update({
                "position": rad(cmd.get(reg.COMMAND_POSITION)),
                "velocity": rad(cmd.get(reg.COMMAND_VELOCITY, 0.0)),
                "torque": num(cmd.get(reg.COMMAND_FEEDFORWARD_TORQUE, 0.0)),
                "kp": cmd.get(reg.COMMAND_KP_SCALE, 1.0) * kp_full / (2 * math.pi),
                "kd": cmd.get(reg.COMMAND_KD_SCALE, 1.0) * kd_full / (2 * math.pi),
            })
        return row
    if dest == ours and source in spec["joints"]:
        resp = mp.parse_reply(bytes(msg.data))
        return {"joint": source, "kind": "reply", "mode": int(resp[reg.MODE]),
                "position": resp[reg.POSITION] * 2 * math.pi,
                "velocity": resp[reg.VELOCITY] * 2 * math.pi,
                "torque": resp[reg.TORQUE], "fault": int(resp[reg.FAULT])}
    return None


def log_odrive(msg, spec, db):
    node, cmd = msg.arbitration_id >> 5, msg.arbitration_id & 0x1F
    if msg.is_extended_id or node not in spec["joints"]:
        return None
    try:
        m = db.get_message_by_frame_id(cmd)
    except KeyError:
        return {"joint": node, "kind": "unknown", "cmd": cmd}
    if len(msg.data) == 0:  # a request (RTR) for a Get_ message
        return {"joint": node, "kind": m.name.split("_", 1)[1]}
    sig = m.decode(bytes(msg.data), decode_choices=False, scaling=True)
    row = {"joint": node, "kind": m.name.split("_", 1)[1]}  # "Axis0_Heartbeat": "Heartbeat"
    row.update({k: float(x) for k, x in sig.items()})
    return row


def log_mit(msg, spec, params):
    """Commands: the packed 8 bytes (16-bit position, 12-bit velocity, kp, kd, torque, big
    endian), unpacked with the driver's own BitArray and uint_to_float over its model's ranges;
    replies (on the master id, the motor's id first) with its decode_motor_status."""
    if msg.is_extended_id:
        return None
    d = bytes(msg.data)
    if msg.arbitration_id in spec["joints"] and len(d) == 8:
        special = {b"\xff" * 7 + b"\xfc": "enter", b"\xff" * 7 + b"\xfd": "exit",
                   b"\xff" * 7 + b"\xfe": "zero"}
        if d in special:
            return {"joint": msg.arbitration_id, "kind": special[d]}
        b = canmotorlib.BitArray(d)  # bytes, positionally: bitstring 4 and 5 alike
        u = canmotorlib.uint_to_float
        return {"joint": msg.arbitration_id, "kind": "command",
                "position": u(b[0:16].uint, params["P_MIN"], params["P_MAX"], 16),
                "velocity": u(b[16:28].uint, params["V_MIN"], params["V_MAX"], 12),
                "kp": u(b[28:40].uint, params["KP_MIN"], params["KP_MAX"], 12),
                "kd": u(b[40:52].uint, params["KD_MIN"], params["KD_MAX"], 12),
                "torque": u(b[52:64].uint, params["T_MIN"], params["T_MAX"], 12)}
    if msg.arbitration_id == spec["master"] and len(d) >= 6 and d[0] in spec["joints"]:
        m = Capture(spec["model"], d)
        p, vel, t = m.convert_raw_to_physical_rad(*m.decode_motor_status(d[:6]))
        s = m.motorParams["AXIS_DIRECTION"]
        return {"joint": d[0], "kind": "reply", "position": p * s, "velocity": vel * s,
                "torque": t * s, "fault": d[7] if len(d) >= 8 else 0}
    return None


def log_main(spec):
    import can
    proto = spec["protocol"]
    # JSON object keys are strings; the joints' ids are numbers on the bus.
    spec["joints"] = {int(k): v for k, v in spec["joints"].items()}
    if proto == "odrive":
        dbc = os.path.join(os.path.dirname(odrive_can.__file__), "dbc",
                           "odrive-cansimple-0.6.10.dbc")
        db = cantools.database.load_file(dbc)
        decode = lambda m: log_odrive(m, spec, db)
    elif proto == "mit":
        spec["model"] = spec["model"].replace("-", "_").replace(".", "p")
        params = Capture(spec["model"], bytes(6)).motorParams
        decode = lambda m: log_mit(m, spec, params)
    else:
        decode = lambda m: log_moteus(m, spec)
    rows, frames = [], 0
    for msg in can.CanutilsLogReader(spec["log"]):
        frames += 1
        row = decode(msg)
        if row is not None:
            row["t"] = msg.timestamp
            rows.append(row)
    return {"frames": frames, "rows": rows}


def main():
    if sys.argv[1] == "log":
        real = sys.stdout
        sys.stdout = sys.stderr
        try:
            res = log_main(json.load(open(sys.argv[2])))
        finally:
            sys.stdout = real
        json.dump(res, sys.stdout)
        return
    v = json.load(open(sys.argv[1]))
    # Quiet the MIT driver's prints: stdout carries our JSON.
    real = sys.stdout
    sys.stdout = sys.stderr
    try:
        res = {"moteus": moteus_part(v["moteus"]), "odrive": odrive_part(v["odrive"]), "mit": mit_part(v["mit"])}
    finally:
        sys.stdout = real
    json.dump(res, sys.stdout)


if __name__ == "__main__":
    main()

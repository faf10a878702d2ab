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


def main():
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

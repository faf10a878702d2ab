#!/usr/bin/env python3
"""Writes the real plantar-pressure *time series* of the `jiku-data` package's SpeedPP2DS set
(Pataky et al. 2008: 10 subjects x 3 walking speeds x 20 trials, 63x33 sensels at 500 Hz, each
trial from first contact) as a foot's CAN traffic: candump logs that `presrs capture` and
`presrs node --replay` read as they read a robot's. Written from docs/protocol.md alone (it
imports nothing of this project), so it is also a second implementation of the foot's side.

Per trial, on the foot's clock: a flight (FootContact 0 at 100 Hz), the touchdown edge at the
trial's first frame, the stance's images at 100 Hz (every fifth frame of the 500 Hz series: the
one nearest each tick of the foot's 100 Hz grid, which runs on across trials, so each stance
meets it at another phase) as 16-bit 63x33 TactileFrame transfers (CAN FD, 68 data segments),
and the liftoff edge after its last loaded frame. One log per block of trials (0-9, 10-14, 15-19
of each subject and speed, in recording order; the "runs" of scripts/speedpp2d.py), each with
its labels CSV (`start_s,end_s,terrain,foot`: the subject, as `presrs capture --labels` reads
it):

    OUT/trials00-09.log, .csv   OUT/trials10-14.log, .csv   OUT/trials15-19.log, .csv
    OUT/terrains.toml           the subjects as terrains (ids 100-109)

    python3 scripts/speedpp2d_stream.py --out DIR [--subjects 0,1,2] [--image-ms 400]
    presrs capture --replay DIR/trials00-09.log --labels DIR/trials00-09.csv \
        --config node.toml --out SET          # node.toml: terrains = "DIR/terrains.toml"

`--image-ms` stops each stance's images that long after touchdown (default: the whole stance);
a foot may send any subset of its images (docs/protocol.md), and the logs are 0.7 MB a trial in
full. Images in flight are not sent (allowed: the node ignores them).

The installed package's `SpeedPP2DS` class does not construct (jiku-data 0.1.16: its
`_set_data` takes no argument but is called with one), so the script reads the package's own
files with the class's own `_loadh5`. Its files are GPL: read here, never copied into this
repository. Needs `pip install jiku-data` (scripts/install-deps.sh installs it).
"""
import argparse
import inspect
import os
import random
import sys
import zlib

BLOCKS = [("trials00-09", range(0, 10)), ("trials10-14", range(10, 15)), ("trials15-19", range(15, 20))]
EPOCH_S = 1_700_000_000  # the logs' receive clock, as `presrs lab sim --log` writes
FOOT_ID_CONTACT = 0x100
FOOT_ID_TACTILE = 0x600
TICK_US = 10_000  # the foot's 100 Hz
FLIGHT_US = 300_000


def contact(seq, stance, t_us):
    return f"{FOOT_ID_CONTACT:03X}#{int(stance):02X}{seq & 0xFF:02X}{(t_us & 0xFFFFFFFF).to_bytes(4, 'little').hex().upper()}0000"


def image_frames(frame_seq, img, t_us):
    """One TactileFrame transfer (CAN FD): a header segment and ceil(bytes / 62) data segments."""
    rows, cols = img.shape
    pixels = img.astype("<u2").tobytes()
    n = -(-len(pixels) // 62)
    head = bytes([frame_seq & 0xFF, 0, rows, cols, 16, n])
    head += zlib.crc32(pixels).to_bytes(4, "little") + (t_us & 0xFFFFFFFF).to_bytes(4, "little")
    out = [head.ljust(64, b"\0")]
    for i in range(1, n + 1):
        chunk = pixels[(i - 1) * 62 : i * 62]
        out.append((bytes([frame_seq & 0xFF, i]) + chunk).ljust(64, b"\0"))
    # `##1`: CAN FD with bit-rate switch, as candump -L writes it.
    return [f"{FOOT_ID_TACTILE:03X}##1{f.hex().upper()}" for f in out]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder for the logs, labels and terrains file")
    ap.add_argument("--subjects", default="0,1,2,3,4,5,6,7,8,9", help="comma-separated, 0-9")
    ap.add_argument("--image-ms", type=int, default=0, help="images only this long after touchdown (0: the whole stance)")
    ap.add_argument("--seed", type=int, default=1, help="the flights' jitter")
    a = ap.parse_args()
    try:
        import numpy as np
        from jikudata.datasets.SpeedPP2DS import SpeedPP2DS
    except ImportError as e:
        sys.exit(f"speedpp2d_stream: {e}: install it with `python3 -m pip install jiku-data`")
    try:
        subjects = sorted({int(s) for s in a.subjects.split(",")})
    except ValueError:
        sys.exit(f"speedpp2d_stream: --subjects {a.subjects!r}: give numbers 0-9, comma-separated")
    if not subjects or subjects[0] < 0 or subjects[-1] > 9:
        sys.exit(f"speedpp2d_stream: --subjects {a.subjects!r}: give numbers 0-9, comma-separated")
    pkg = os.path.dirname(inspect.getfile(SpeedPP2DS))
    conds = np.loadtxt(os.path.join(pkg, "data_x", "conditions.csv"), delimiter=",", skiprows=1, dtype=int)
    rng = random.Random(a.seed)
    os.makedirs(a.out, exist_ok=True)
    # Per block: its trials of every subject, (subject, speed, trial number, series).
    blocks = {name: [] for name, _ in BLOCKS}
    for s in subjects:
        y = SpeedPP2DS._loadh5(os.path.join(pkg, "data_y", f"subj{s:03}.h5"))
        if y.ndim != 4 or y.shape[0] != 60 or y.max() > 65535:
            sys.exit(f"speedpp2d_stream: subject {s}: unexpected series {y.shape}, max {y.max()}")
        count = {}
        for i in range(60):
            c = int(conds[i, 1 + s])
            t = count.get(c, 0)
            count[c] = t + 1
            name = next(n for n, r in BLOCKS if t in r)
            blocks[name].append((s, c, t, y[i]))
    total = 0
    for name, trials in blocks.items():
        # Interleave the subjects, as a robot would cross terrains (a seeded shuffle).
        rng.shuffle(trials)
        lines, labels = [], ["start_s,end_s,terrain,foot"]
        seq, frame_seq, now = 0, 0, 0

        def emit(t_us, body):
            lines.append(f"({EPOCH_S + t_us // 1_000_000}.{t_us % 1_000_000:06d}) can0 {body}")

        for s, c, t, series in trials:
            load = series.sum(axis=(0, 1))
            loaded = np.nonzero(load)[0]
            if len(loaded) == 0:
                continue
            td = now + FLIGHT_US + rng.randrange(TICK_US)
            lo = td + (int(loaded[-1]) + 1) * 2000
            # Flight: the switch open at every tick.
            tick = -(-now // TICK_US) * TICK_US
            while tick < td:
                seq += 1
                emit(tick, contact(seq, False, tick))
                tick += TICK_US
            seq += 1
            emit(td, contact(seq, True, td))
            end_images = lo if a.image_ms <= 0 else min(lo, td + a.image_ms * 1000)
            while tick < lo:
                seq += 1
                emit(tick, contact(seq, True, tick))
                if tick < end_images:
                    k = min(round((tick - td) / 2000), series.shape[2] - 1)
                    frame_seq += 1
                    for f in image_frames(frame_seq, series[:, :, k], tick):
                        emit(tick, f)
                tick += TICK_US
            seq += 1
            emit(lo, contact(seq, False, lo))
            # The range holds the stance with room either side (the flights are 300-310 ms).
            t0, t1 = EPOCH_S * 1_000_000 + td - 1000, EPOCH_S * 1_000_000 + lo + 100_000
            labels.append(f"{t0 / 1e6:.6f},{t1 / 1e6:.6f},subj{s:02d},0")
            now = lo
            total += 1
        with open(os.path.join(a.out, f"{name}.log"), "w") as f:
            f.write("\n".join(lines) + "\n")
        with open(os.path.join(a.out, f"{name}.csv"), "w") as f:
            f.write("\n".join(labels) + "\n")
    with open(os.path.join(a.out, "terrains.toml"), "w") as f:
        f.write("# SpeedPP2DS's subjects as terrains (written by scripts/speedpp2d_stream.py)\n")
        for s in subjects:
            f.write(f'[[terrain]]\nid = {100 + s}\nname = "subj{s:02d}"\n\n')
    print(f"wrote {total} stances of {len(subjects)} subjects as {len(BLOCKS)} logs to {a.out}")


if __name__ == "__main__":
    main()

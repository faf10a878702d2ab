#!/usr/bin/env python3
"""Writes the real plantar-pressure images of the `jiku-data` package's SpeedPP2D set (Pataky
et al. 2008: 10 subjects x 3 walking speeds x 20 trials, 63x33 peak-pressure maps) as a
presrs lab dataset, from the installed package (its files are GPL: they are read here, never copied
into this repository):

    OUT/subjNN/speedS_trialTT.pgm   16-bit PGM, one class per subject
    OUT/manifest.csv                the `presrs capture` manifest; `source` = the block of trials
                                    (0-9, 10-14, 15-19 of each speed, in recording order), so
                                    that `presrs train` and `presrs lab experiment open-set` hold
                                    out later trials as the "next run". (Not the speeds: a
                                    subject's walk changes more between speeds than between
                                    subjects, measured: 38% of subjects right across speeds.)
                                    `gait` = the walking speed (1-3: slow, normal, fast; the
                                    package's speeds average 1.09, 1.44 and 1.95 m/s): the
                                    gait a walking foot touched down in, as `presrs capture`
                                    records GaitStatus.
    OUT/terrains.toml               a terrains file naming the subjects (ids 100-109)

    python3 scripts/speedpp2d.py --out DIR
    python3 scripts/speedpp2d.py --out DIR --runs speed-blocks   # source = speedS/trialsXX-YY
    presrs lab experiment open-set --normalize-load --extra-source DIR --terrains DIR/terrains.toml

Load-normalise (`--normalize-load`, also for `presrs train`): the three speeds load the foot
differently and the person is in the shape. Measured (open-set, seeds 1-3): a left-out subject
called unknown 87-93% (AUROC 0.980-0.983) with it, 55-63% (0.915-0.936) without (both before
the calibration run's images became the model's references; with them 83-89%, AUROC
0.986-0.987).

Needs `pip install jiku-data` (scripts/install-deps.sh installs it with the test requirements).
"""
import argparse
import os
import sys


def run(trial):
    return "trials00-09" if trial < 10 else "trials10-14" if trial < 15 else "trials15-19"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="dataset folder to write")
    ap.add_argument(
        "--runs",
        choices=["blocks", "speed-blocks"],
        default="blocks",
        help="the manifest's `source`: the block of trials (default), or the speed and the "
        "block (`speed2/trials10-14`), to hold out a walking speed as a gait the model never saw",
    )
    a = ap.parse_args()
    try:
        import jikudata
        import numpy as np
    except ImportError as e:
        sys.exit(f"speedpp2d: {e}: install it with `python3 -m pip install jiku-data`")
    d = jikudata.SpeedPP2D()
    y = np.asarray(d.y)
    subj, cond = np.asarray(d.x["subj"]), np.asarray(d.x["cond"])
    if y.ndim != 3 or len(y) != len(subj):
        sys.exit(f"speedpp2d: unexpected SpeedPP2D shape {y.shape}")
    if not set(np.unique(cond).tolist()) <= {1, 2, 3}:
        sys.exit(f"speedpp2d: speeds {sorted(set(cond.tolist()))}, want 1-3 (the gait column)")
    if y.min() < 0 or y.max() > 65535:
        sys.exit("speedpp2d: pressures outside 0..65535 cannot be a 16-bit image")
    os.makedirs(a.out, exist_ok=True)
    lines = ["file,terrain,foot,step,touchdown_s,sample_s,load_sum,damage_pct,source,gait"]
    trial = {}
    for i in range(len(y)):
        s, c = int(subj[i]), int(cond[i])
        t = trial.get((s, c), 0)
        trial[(s, c)] = t + 1
        cls = f"subj{s:02d}"
        os.makedirs(os.path.join(a.out, cls), exist_ok=True)
        name = f"speed{c}_trial{t:02d}.pgm"
        img = y[i].astype(">u2")
        rows, cols = img.shape
        with open(os.path.join(a.out, cls, name), "wb") as f:
            f.write(f"P5\n{cols} {rows}\n65535\n".encode())
            f.write(img.tobytes())
        step = c * 100 + t
        lines.append(
            f"{cls}/{name},{cls},0,{step},{step}.000000,{step}.070000,"
            f"{int(y[i].sum())},0.0,"
            + (run(t) if a.runs == "blocks" else f"speed{c}/{run(t)}")
            + f",{c}"
        )
    with open(os.path.join(a.out, "manifest.csv"), "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(a.out, "terrains.toml"), "w") as f:
        f.write("# SpeedPP2D's subjects as classes (written by scripts/speedpp2d.py)\n")
        for s in sorted({int(v) for v in subj}):
            f.write(f'[[terrain]]\nid = {100 + s}\nname = "subj{s:02d}"\n\n')
    print(f"wrote {len(y)} images of {len(set(subj.tolist()))} subjects to {a.out}")


if __name__ == "__main__":
    main()

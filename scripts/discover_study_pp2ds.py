#!/usr/bin/env python3
"""`presrs discover` and `--add` on real plantar pressure (the `jiku-data` package's SpeedPP2DS,
people walking; scripts/speedpp2d_stream.py sends it as a foot's CAN traffic), each person of
a group of four left out in turn as the new "ground":

    model      `presrs train` on trials 00-09 of the other three (captured from the logs)
    keep       `presrs node --replay trials10-14.log --keep-unknown` (all four people)
    discover   the groups; the left-out person's share of the best new-ground group
    --add      that group as `newground`; trials 15-19 through the old and the new model

    scripts/discover_study_pp2ds.py [--bin target/debug/presrs] [--groups 0-3,3-6,6-9]

Prints one JSON line per left-out person, then a summary per group of four. Needs `pip install
jiku-data` (scripts/install-deps.sh installs it); its files are GPL and stay in the package.
"""
import argparse, csv, json, os, shutil, subprocess, sys, tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{r.stderr[-2000:]}")
    return r.stdout


def labels_of(path):
    return [(float(r["start_s"]), float(r["end_s"]), r["terrain"]) for r in csv.DictReader(open(path))]


def truth_at(labels, t):
    for s, e, who in labels:
        if s <= t < e:
            return who
    return None


def decisions(a, log, model, cfg, terrains, labels):
    out = run([a.bin, "node", "--replay", log, "--model", model, "--config", cfg, "--json"]
              + (["--terrains", terrains] if os.path.exists(terrains) else []))
    return [(truth_at(labels, v["t_us"] * 1e-6), v["terrain"], v["t_us"] * 1e-6, v["foot"], v["step"])
            for v in map(json.loads, out.splitlines())]


def one(a, d, cfg, people, left):
    set_dir = os.path.join(d, f"set-{left}")
    csv_in = os.path.join(d, "trials00-09.csv")
    rows = [r for r in csv.DictReader(open(csv_in)) if r["terrain"] != left]  # left None: all
    lab = os.path.join(d, f"labels-{left}.csv")
    with open(lab, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    run([a.bin, "capture", "--replay", os.path.join(d, "trials00-09.log"), "--labels", lab,
         "--config", cfg, "--out", set_dir])
    model = os.path.join(d, f"model-{left}.json")
    run([a.bin, "train", "--data", set_dir, "--out", model, "--terrains",
         os.path.join(d, "terrains.toml")])
    kept = os.path.join(d, f"kept-{left}")
    keep_labels = labels_of(os.path.join(d, "trials10-14.csv"))
    steps = decisions(a, os.path.join(d, "trials10-14.log"), model, cfg, "", keep_labels)
    who = {(foot, step): t for t, _, _, foot, step in steps}
    run([a.bin, "node", "--replay", os.path.join(d, "trials10-14.log"), "--model", model,
         "--config", cfg, "--keep-unknown", kept])
    left_steps = sum(t == left for t, *_ in steps)
    kept_rows = [r for r in csv.DictReader(open(os.path.join(kept, "kept.csv")))
                 if r["reason"] != "known"] if os.path.exists(os.path.join(kept, "kept.csv")) else []
    res = {"people": people, "left_out": left or "(none)", "left_steps": left_steps, "kept": len(kept_rows),
           "kept_left": sum(who.get((int(r["foot"]), int(r["step"]))) == left for r in kept_rows)}
    if not kept_rows:
        return res
    g = json.loads(run([a.bin, "discover", kept, "--model", model, "--json"]))
    of = {r["file"]: who.get((int(r["foot"]), int(r["step"]))) for r in kept_rows}
    new = [x for x in g["groups"] if x["new_ground"]]
    res["new_groups"] = len(new)
    res["groups"] = [(x["stances"], x["new_ground"], sum(of[f] == left for f in x["files"]),
                      round(x["separation"], 2)) for x in g["groups"]]
    best = max(new, key=lambda x: sum(of[f] == left for f in x["files"]), default=None)
    if not best or left is None:
        return res
    hit = sum(of[f] == left for f in best["files"])
    res["recall"], res["purity"] = round(hit / max(left_steps, 1), 3), round(hit / len(best["files"]), 3)
    new_model = os.path.join(d, f"added-{left}.json")
    terrains = os.path.join(d, f"terrains-{left}.toml")
    shutil.copy(os.path.join(d, "terrains.toml"), terrains)
    run([a.bin, "discover", kept, "--model", model, "--add", "newground", "--group",
         str(best["group"]), "--out-model", new_model, "--terrains", terrains])
    fresh = labels_of(os.path.join(d, "trials15-19.csv"))
    log = os.path.join(d, "trials15-19.log")
    before = decisions(a, log, model, cfg, terrains, fresh)
    after = decisions(a, log, new_model, cfg, terrains, fresh)

    def known(ds):
        on = [(t, c) for t, c, *_ in ds if t and t != left]
        return round(sum(t == c for t, c in on) / max(len(on), 1), 3)
    on_new = [c for t, c, *_ in after if t == left]
    res.update(new_right=round(sum(c == "newground" for c in on_new) / max(len(on_new), 1), 3),
               known_before=known(before), known_after=known(after))
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/debug/presrs")
    ap.add_argument("--groups", default="0-3,3-6,6-9", help="first-last subject of each group of four")
    a = ap.parse_args()
    work = tempfile.mkdtemp(prefix="presrs-discover-pp2ds-")
    out = []
    for grp in a.groups.split(","):
        lo, hi = (int(x) for x in grp.split("-"))
        subjects = list(range(lo, hi + 1))
        d = os.path.join(work, grp)
        os.makedirs(d)
        r = subprocess.run([sys.executable, os.path.join(HERE, "speedpp2d_stream.py"), "--out", d,
                            "--subjects", ",".join(map(str, subjects)), "--image-ms", "200"],
                           capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(r.stderr)
        cfg = os.path.join(d, "node.toml")
        with open(cfg, "w") as f:
            f.write(f'terrains = "{os.path.join(d, "terrains.toml")}"\nsample_ms = 150\n')
        people = sorted({r["terrain"] for r in csv.DictReader(open(os.path.join(d, "trials00-09.csv")))})
        # Each person left out in turn, then none (a run over known ground only).
        for left in people + [None]:
            res = one(a, d, cfg, grp, left)
            out.append(res)
            print(json.dumps(res), flush=True)
    if not os.environ.get("STUDY_KEEP"):
        shutil.rmtree(work, ignore_errors=True)
    print("summary:")
    for grp in a.groups.split(","):
        rs = [r for r in out if r["people"] == grp]
        known_only = [r for r in rs if r["left_out"] == "(none)"]
        rs = [r for r in rs if r["left_out"] != "(none)"]
        print(f"  people {grp}: new groups {[r.get('new_groups') for r in rs]}; recall "
              f"{[r.get('recall') for r in rs]}; purity {[r.get('purity') for r in rs]}; after --add: "
              f"new right {[r.get('new_right') for r in rs]}; known "
              f"{[(r.get('known_before'), r.get('known_after')) for r in rs]}; known only: new "
              f"groups {[r.get('new_groups', 0) for r in known_only]}")


if __name__ == "__main__":
    main()

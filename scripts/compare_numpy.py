#!/usr/bin/env python3
"""Side-by-side speed of the classifier: the same pipeline in Python (numpy, and scikit-learn's
KernelDensity for the Parzen step) against `presrs`, one image at a time, on the same data and
the same model file.

    presrs lab dataset static --out /tmp/ds/static
    presrs train --data /tmp/ds/static --out /tmp/ds/static.json --crop 2,2,2,2 --dims 52
    python3 scripts/compare_numpy.py --model /tmp/ds/static.json --data /tmp/ds/static

Per image, both sides do: crop (and downsample), rows concatenated and zero-padded to N, FFT
magnitude (first N/2+1 bins), PCA projection with the model's mean and matrix, and the Parzen
decision over the model's stored samples. numpy uses `rfft` (its fastest real transform). Our
time is `presrs eval --json`'s `classify_us_median` on the same images. The script also checks
that both sides pick the same terrain for every image (`presrs lab classify`), so the timing is of
the same computation. Prints one JSON object; exits 1 if the decisions disagree.
"""
import argparse
import json
import pathlib
import statistics
import subprocess
import sys
import time

import numpy as np


def read_pgm(path):
    """P2 or P5, maxval up to 65535 (what `presrs lab dataset` writes)."""
    data = path.read_bytes()
    tokens, pos = [], 0
    while len(tokens) < 4:
        while data[pos : pos + 1].isspace():
            pos += 1
        if data[pos : pos + 1] == b"#":
            while data[pos : pos + 1] not in (b"\n", b""):
                pos += 1
            continue
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace():
            pos += 1
        tokens.append(data[start:pos])
    magic, cols, rows, maxval = tokens[0], int(tokens[1]), int(tokens[2]), int(tokens[3])
    if magic == b"P5":
        dtype = ">u2" if maxval > 255 else "u1"
        px = np.frombuffer(data[pos + 1 :], dtype=dtype, count=rows * cols)
    elif magic == b"P2":
        px = np.array(data[pos:].split()[: rows * cols], dtype=np.int64)
    else:
        raise SystemExit(f"{path}: not a PGM (magic {magic!r})")
    return px.reshape(rows, cols).astype(np.float32)


class NumpyPipeline:
    def __init__(self, m):
        self.crop = m["crop"]
        self.k = max(1, m["downsample"])
        self.n_fft = m["n_fft"]
        self.h = m["h"]
        self.mean = np.asarray(m["pca_mean"], dtype=np.float32)
        self.U = np.asarray(m["pca_matrix"], dtype=np.float32).reshape(self.h, -1)
        self.P = np.asarray(m["samples"], dtype=np.float32).reshape(-1, self.h)
        self.labels = np.asarray(m["sample_classes"])
        self.n_classes = len(m["classes"])
        self.inv_two_s2 = 1.0 / (2.0 * m["kernel_width"] ** 2)
        counts = np.bincount(self.labels, minlength=self.n_classes)
        self.log_count = np.log(counts)
        self.normalize = m["normalize_load"]

    def work(self, img):
        c = self.crop
        rows, cols = img.shape
        return img[c["top"] : rows - c["bottom"] : self.k, c["left"] : cols - c["right"] : self.k]

    def classify(self, img):
        w = self.work(img).ravel()
        if self.normalize is not None and w.sum() > 0:
            w = w * (self.normalize / w.sum())
        f = np.abs(np.fft.rfft(w, n=self.n_fft))
        q = self.U @ (f - self.mean)
        d2 = ((self.P - q) ** 2).sum(axis=1)
        e = -d2 * self.inv_two_s2
        dens = np.full(self.n_classes, -np.inf)
        for k in range(self.n_classes):
            ek = e[self.labels == k]
            mx = ek.max()
            dens[k] = mx + np.log(np.exp(ek - mx).sum()) - self.log_count[k]
        return int(np.argmax(dens))


class SklearnPipeline(NumpyPipeline):
    """The Parzen step as scikit-learn's KernelDensity (Gaussian kernel, same width), one
    estimator per class fitted on the model's stored samples."""

    def __init__(self, m):
        super().__init__(m)
        from sklearn.neighbors import KernelDensity

        self.kdes = [
            KernelDensity(kernel="gaussian", bandwidth=m["kernel_width"]).fit(
                self.P[self.labels == k].astype(np.float64)
            )
            for k in range(self.n_classes)
        ]

    def classify(self, img):
        w = self.work(img).ravel()
        if self.normalize is not None and w.sum() > 0:
            w = w * (self.normalize / w.sum())
        f = np.abs(np.fft.rfft(w, n=self.n_fft))
        q = (self.U @ (f - self.mean)).astype(np.float64)[None, :]
        return int(np.argmax([kde.score_samples(q)[0] for kde in self.kdes]))


def time_per_image(pipe, images, repeats):
    times, picks = [], []
    for _ in range(repeats):
        for img in images:
            t0 = time.perf_counter()
            k = pipe.classify(img)
            times.append((time.perf_counter() - t0) * 1e6)
            picks.append(k)
    return statistics.median(times), picks[: len(images)]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", required=True, type=pathlib.Path)
    ap.add_argument("--data", required=True, type=pathlib.Path, help="class folders of PGM images")
    ap.add_argument("--presrs", default="target/release/presrs", help="the presrs binary")
    ap.add_argument("--max-images", type=int, default=400)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()

    model = json.loads(a.model.read_text())
    files = sorted(a.data.glob("*/*.pgm"))[: a.max_images]
    if not files:
        sys.exit(f"no PGM images in class folders under {a.data}; make some with `presrs lab dataset`")
    images = [read_pgm(p) for p in files]
    names = [c["name"] for c in model["classes"]]

    out = subprocess.run(
        [a.presrs, "classify", "--model", str(a.model), *map(str, files)],
        check=True, capture_output=True, text=True,
    ).stdout
    ours = {}
    for line in out.splitlines():
        path, terrain, _conf = line.split("\t")
        ours[path] = terrain
    evaluated = json.loads(
        subprocess.run(
            [a.presrs, "eval", "--model", str(a.model), "--data", str(a.data), "--json"],
            check=True, capture_output=True, text=True,
        ).stdout
    )

    np_med, np_picks = time_per_image(NumpyPipeline(model), images, a.repeats)
    sk_med, sk_picks = time_per_image(SklearnPipeline(model), images, 1)
    # "unknown" from presrs is still the same best class; compare known decisions only.
    disagree = [
        str(p) for p, k in zip(files, np_picks) if ours[str(p)] not in (names[k], "unknown")
    ]
    report = {
        "images": len(images),
        "numpy_version": np.__version__,
        "presrs_classify_us_median": evaluated["classify_us_median"],
        "numpy_classify_us_median": round(np_med, 2),
        "sklearn_kde_classify_us_median": round(sk_med, 2),
        "speedup_vs_numpy": round(np_med / evaluated["classify_us_median"], 1),
        "speedup_vs_sklearn": round(sk_med / evaluated["classify_us_median"], 1),
        "numpy_vs_presrs_disagreements": len(disagree),
        "sklearn_vs_numpy_disagreements": sum(x != y for x, y in zip(np_picks, sk_picks)),
    }
    print(json.dumps(report, indent=2))
    if disagree:
        print("decisions differ for: " + ", ".join(disagree[:10]), file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""An independent Gaussian-process regression for visobjd's preference model tests.

Reads JSON on stdin: {"x": [[...], ...], "kinds": [k, ...], "y": [...],
"length2": [4 values], "signal2": s, "noise2": n, "queries": [[...], ...]} and writes
{"mean": [...], "lml": value}: the posterior mean at each query and the log marginal
likelihood, for a squared-exponential kernel with one squared length scale per kind of
feature, each divided by that kind's feature count, around the ratings' mean. Written
from the textbook formulas (Rasmussen and Williams, Gaussian Processes for Machine
Learning, algorithm 2.1) with numpy's own solve and log-determinant.
"""
import json
import sys

import numpy as np


def main():
    d = json.load(sys.stdin)
    x = np.asarray(d["x"], dtype=float)
    q = np.asarray(d["queries"], dtype=float)
    y = np.asarray(d["y"], dtype=float)
    kinds = np.asarray(d["kinds"], dtype=int)
    counts = np.bincount(kinds, minlength=4).astype(float)
    scale = np.asarray(d["length2"], dtype=float) * np.where(counts > 0, counts, 1.0)
    w = 1.0 / scale[kinds]  # per feature: 1 / (length2 * count of its kind)

    def k(a, b):
        diff = a[:, None, :] - b[None, :, :]
        return d["signal2"] * np.exp(-0.5 * np.einsum("ijk,k->ij", diff * diff, w))

    m = y.mean()
    kxx = k(x, x) + d["noise2"] * np.eye(len(y))
    alpha = np.linalg.solve(kxx, y - m)
    mean = m + k(q, x) @ alpha
    sign, logdet = np.linalg.slogdet(kxx)
    assert sign > 0
    lml = -0.5 * (y - m) @ alpha - 0.5 * logdet - 0.5 * len(y) * np.log(2 * np.pi)
    json.dump({"mean": mean.tolist(), "lml": float(lml)}, sys.stdout)


if __name__ == "__main__":
    main()

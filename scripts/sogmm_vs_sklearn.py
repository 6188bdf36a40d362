#!/usr/bin/env python3
"""Our SOGMM EM side by side with scikit-learn's GaussianMixture on the same data.

For synthetic 160x120 frames (the room corner of actors::mapper::sogmm::synthetic,
three views) and sigma = 0.02 and 0.03, the example binary `sogmm_dump` writes the 4D
points (x, y, z, intensity), the number of components M found by the mean shift and the
k-means++ partition, and runs our EM from that partition. This script starts
sklearn.mixture.GaussianMixture (full covariances, the same M, reg_covar 1e-6, tol 1e-3,
max_iter 100 -- the same convergence rule as ours) from the same partition (weights,
means and precisions of the hard clusters, `means_init` among them), and prints the
mean log-likelihood of the points under both results, their relative difference
(target: within 0.5 %), the single-threaded EM seconds of both and the ratio.

Both run single-threaded (RAYON_NUM_THREADS=1 for ours; OMP/OpenBLAS/MKL threads = 1
for numpy). Times are wall seconds of the EM only (seeding excluded for both).

    pip install scikit-learn
    python3 scripts/sogmm_vs_sklearn.py [--sigmas 0.02 0.03] [--frames 3]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

import numpy as np  # noqa: E402

try:
    from sklearn.mixture import GaussianMixture  # noqa: E402
except ImportError:
    sys.exit("scikit-learn is missing: pip install scikit-learn")

REG_COVAR = 1e-6
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def partition_init(x, assign, m):
    """Weights, means and precisions of the hard clusters (as init_from_partition)."""
    eps = 10 * np.finfo(float).eps
    counts = np.bincount(assign, minlength=m).astype(float)
    means = np.zeros((m, x.shape[1]))
    np.add.at(means, assign, x)
    means /= (counts + eps)[:, None]
    covs = np.zeros((m, x.shape[1], x.shape[1]))
    d = x - means[assign]
    np.add.at(covs, assign, d[:, :, None] * d[:, None, :])
    covs /= (counts + eps)[:, None, None]
    covs += REG_COVAR * np.eye(x.shape[1])
    weights = counts / counts.sum()
    return weights, means, np.linalg.inv(covs)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.02, 0.03])
    ap.add_argument("--frames", type=int, default=3, help="views to compare (1-3)")
    args = ap.parse_args()

    env = dict(os.environ, RAYON_NUM_THREADS="1")
    subprocess.run(
        ["cargo", "build", "--release", "-q", "-p", "troupe-algorithms", "--example", "sogmm_dump"],
        cwd=ROOT, check=True, env=env,
    )
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
    binary = os.path.join(target, "release", "examples", "sogmm_dump")
    rows = []
    with tempfile.TemporaryDirectory() as out:
        proc = subprocess.run(
            [binary, out] + [str(s) for s in args.sigmas],
            check=True, env=env, capture_output=True, text=True,
        )
        for line in proc.stdout.splitlines():
            ours = json.loads(line)
            if ours["frame"] >= args.frames:
                continue
            x = np.fromfile(ours["points"], dtype="<f8").reshape(-1, 4)
            assign = np.fromfile(ours["assign"], dtype="<u4").astype(np.int64)
            m = ours["m"]
            weights, means, precisions = partition_init(x, assign, m)
            gm = GaussianMixture(
                n_components=m, covariance_type="full", reg_covar=REG_COVAR, tol=1e-3,
                max_iter=100, weights_init=weights, means_init=means,
                precisions_init=precisions, init_params="random_from_data", random_state=0,
            )
            start = time.perf_counter()
            gm.fit(x)
            sk_s = time.perf_counter() - start
            sk_ll = gm.score(x)
            rows.append((ours, sk_ll, sk_s, gm.n_iter_))
            print(".", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)

    print("| frame | σ | N | M | mean LL ours | mean LL sklearn | rel. diff | iters ours / sk "
          "| EM s ours | EM s sklearn | sklearn / ours |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for ours, sk_ll, sk_s, sk_it in rows:
        rel = abs(ours["ll"] - sk_ll) / abs(sk_ll)
        worst = max(worst, rel)
        print(f"| {ours['frame']} | {ours['sigma']} | {ours['n']} | {ours['m']} | "
              f"{ours['ll']:.6f} | {sk_ll:.6f} | {100 * rel:.1e} % | "
              f"{ours['iterations']} / {sk_it} | {ours['em_s']:.2f} | {sk_s:.2f} | "
              f"{sk_s / ours['em_s']:.1f}× |")
    print(f"\nlargest relative difference of the mean log-likelihood: {100 * worst:.3f} % "
          f"(target ≤ 0.5 %): {'OK' if worst <= 0.005 else 'NOT MET'}")
    return 0 if worst <= 0.005 else 1


if __name__ == "__main__":
    sys.exit(main())

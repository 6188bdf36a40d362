#!/usr/bin/env python3
"""troupe's reference mean shift against scikit-learn's MeanShift on the same 2D data.

The SOGMM's number of components M is the number of modes of a flat-kernel mean shift
on the (depth, intensity) pixel data (thesis §6.1.3). troupe's default ("reference")
variant follows the authors' published implementation, which is scikit-learn's
`MeanShift(bandwidth=sigma, bin_seeding=True)`. For synthetic room-corner frames (40x30
and three 160x120 views) and cave frames (a flight recorded by the `record_cave`
example: the cave world and camera of `troupe run`, decimated by 2 as the mapper does),
the example `sogmm_modes` writes the 2D data and prints troupe's M (reference and
blurring); this script runs scikit-learn on the same data and checks that the reference
M is within 1 % of scikit-learn's cluster count on every frame (exit status 1 if not).

    python3 -m venv .venv-sogmm && .venv-sogmm/bin/pip install scikit-learn
    .venv-sogmm/bin/python scripts/sogmm_meanshift_vs_sklearn.py [--sigmas 0.02 0.03]
        [--cave-frames 300 --every 60]
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
    import sklearn  # noqa: E402
    from sklearn.cluster import MeanShift  # noqa: E402
except ImportError:
    sys.exit("scikit-learn is missing: pip install scikit-learn")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOLERANCE = 0.01


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.02, 0.03])
    ap.add_argument("--cave-frames", type=int, default=300,
                    help="frames of the recorded cave flight (0: no cave frames)")
    ap.add_argument("--every", type=int, default=60, help="compare every N-th cave frame")
    ap.add_argument("--no-build", action="store_true", help="use the examples as built")
    args = ap.parse_args()

    if not args.no_build:
        subprocess.run(
            ["cargo", "build", "--release", "-q", "-p", "troupe-sims",
             "--example", "sogmm_modes", "--example", "record_cave"],
            cwd=ROOT, check=True,
        )
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
    examples = os.path.join(target, "release", "examples")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        command = [os.path.join(examples, "sogmm_modes"), os.path.join(tmp, "data")]
        command += [str(s) for s in args.sigmas]
        if args.cave_frames > 0:
            seq = os.path.join(tmp, "cave")
            subprocess.run([os.path.join(examples, "record_cave"), seq, str(args.cave_frames)],
                           check=True, capture_output=True)
            command += ["--sequence", seq, "--every", str(args.every)]
        proc = subprocess.run(command, check=True, capture_output=True, text=True)
        for line in proc.stdout.splitlines():
            ours = json.loads(line)
            x = np.fromfile(ours["data"], dtype="<f8").reshape(-1, 2)
            start = time.perf_counter()
            ms = MeanShift(bandwidth=ours["sigma"], bin_seeding=True).fit(x)
            sk_s = time.perf_counter() - start
            rows.append((ours, len(ms.cluster_centers_), sk_s))
            print(".", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)

    print(f"scikit-learn {sklearn.__version__}")
    print("| frame | σ | N | M sklearn | M troupe reference | rel. diff | M troupe blurring "
          "| s sklearn | s troupe |")
    print("|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for ours, m_sk, sk_s in rows:
        rel = abs(ours["m_reference"] - m_sk) / m_sk
        worst = max(worst, rel)
        print(f"| {ours['frame']} | {ours['sigma']} | {ours['n']} | {m_sk} | "
              f"{ours['m_reference']} | {100 * rel:.2f} % | {ours['m_blurring']} | "
              f"{sk_s:.2f} | {ours['reference_s']:.3f} |")
    ok = worst <= TOLERANCE
    print(f"\n{len(rows)} frame/σ pairs; largest relative difference of M: {100 * worst:.2f} % "
          f"(target ≤ {100 * TOLERANCE:.0f} %): {'OK' if ok else 'NOT MET'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

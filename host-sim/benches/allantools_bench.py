"""allantools side of the stability benchmark (docs/benchmarks.md, "Stability and Allan deviation").

    cargo run --release -p accomp-host --example stability_bench -- /tmp/accomp_41d.csv
    python3 host-sim/benches/allantools_bench.py /tmp/accomp_41d.csv

Reads the log the Rust example wrote (load time not part of the comparison: numpy's loadtxt is
slow, and the Rust reader is timed separately), converts output_v to g with the log's
scale_factor_v_per_g, and times, best of 5, what `accomp stability` computes: the standard
deviation, the drift regression (np.polyfit + residual std), allantools.oadev and allantools.mdev
at octave taus on frequency data at 1 Hz. (allantools' oadev/mdev give only dev/sqrt(n) error
bars: the Rust side additionally computes noise IDs and chi-squared intervals.)
"""
import sys
import time

import allantools
import numpy as np


RUNS = 5


def loadavg():
    with open("/proc/loadavg") as f:
        return f.read().strip()


def best_of(n, f):
    best, out = float("inf"), None
    for _ in range(n):
        t0 = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main():
    path = sys.argv[1] if len(sys.argv) > 1 else "/tmp/accomp_41d.csv"
    meta = {}
    with open(path) as f:
        while True:
            line = f.readline()
            if line.startswith("#"):
                k, _, v = line[1:].partition(":")
                meta[k.strip()] = v.strip()
                continue
            header = line.strip().split(",")
            break
        t0 = time.perf_counter()
        cols = (header.index("time_s"), header.index("output_v"))
        data = np.loadtxt(f, delimiter=",", usecols=cols)
        load_s = time.perf_counter() - t0
    t = data[:, 0]
    y = data[:, 1] / float(meta["scale_factor_v_per_g"])

    def stability():
        std = np.std(y, ddof=1)
        b, a = np.polyfit(t, y, 1)
        res = y - (a + b * t)
        s = np.sqrt(np.sum(res * res) / (len(y) - 2))
        return std, b, s

    print("load average before: %s" % loadavg())
    stab_s, (std, slope, s) = best_of(RUNS, stability)
    oadev_s, (taus, ad, _, _) = best_of(
        RUNS, lambda: allantools.oadev(y, rate=1.0, data_type="freq", taus="octave"))
    mdev_s, (mtaus, md, _, _) = best_of(
        RUNS, lambda: allantools.mdev(y, rate=1.0, data_type="freq", taus="octave"))
    print("allantools %s, numpy %s" % (allantools.__version__, np.__version__))
    print("samples                  %d" % len(y))
    print("np.loadtxt               %.3f s" % load_s)
    print("stability (std + regr.)  %.4f s" % stab_s)
    print("oadev octave             %.4f s  (%d taus)" % (oadev_s, len(taus)))
    print("mdev octave              %.4f s  (%d taus)" % (mdev_s, len(mtaus)))
    print("oadev + stability        %.4f s" % (oadev_s + stab_s))
    print("sum                      %.4f s" % (stab_s + oadev_s + mdev_s))
    print("std = %.6e g, slope = %.6e g/s, residual std = %.6e g" % (std, slope, s))
    for tau, d in list(zip(taus, ad))[::4]:
        print("  oadev tau %8d s  %.6e" % (tau, d))
    print("load average after: %s" % loadavg())


if __name__ == "__main__":
    main()

"""Generates the allantools cross-check fixture for host-sim/src/allan/ (tests.rs) (run ONCE; outputs committed).

    python3 host-sim/tests/data/make_allantools_xcheck.py

Writes, next to this file:
  allantools_xcheck_log.csv  -- a 4096-sample accomp log (time_s, output_g), values printed with
                                repr() so Rust parses the identical doubles;
  allantools_xcheck.json     -- allantools' oadev/mdev (taus='octave', data_type='freq', rate=1.0)
                                with its ns and simple errors (ade = dev/sqrt(n)), allantools'
                                SP1065 simple EDF (alpha=0, white FM) and chi-squared 1-sigma
                                intervals for the oadev points, its lag-1 ACF noise IDs, and scipy
                                chi-squared quantiles, plus the versions used.

Input generator (deterministic, also easy to re-implement): 64-bit LCG
    s <- (s * 6364136223846793005 + 1442695040888963407) mod 2^64,  u = (s >> 11) / 2^53,
seed s = 20240301; a normal deviate is (sum of 12 consecutive u) - 6.
    output_g[i] = 1 + 2e-6 * w_i + r_i + 1e-10 * i,   r_i = r_{i-1} + 5e-8 * v_i (r_-1 = 0)
where w_i and v_i are the normal deviates drawn in the order w_0, v_0, w_1, v_1, ...
"""
import json
import os
import sys

import allantools
import allantools.ci as atci
import numpy as np
import scipy
import scipy.stats

HERE = os.path.dirname(os.path.abspath(__file__))
N = 4096
MASK = (1 << 64) - 1


class Lcg:
    def __init__(self, seed):
        self.s = seed

    def uniform(self):
        self.s = (self.s * 6364136223846793005 + 1442695040888963407) & MASK
        return (self.s >> 11) / float(1 << 53)

    def normal(self):
        return sum(self.uniform() for _ in range(12)) - 6.0


def main():
    g = Lcg(20240301)
    y = []
    r = 0.0
    for i in range(N):
        w = g.normal()
        v = g.normal()
        r = r + 5e-8 * v
        y.append(1.0 + 2e-6 * w + r + 1e-10 * i)
    with open(os.path.join(HERE, "allantools_xcheck_log.csv"), "w") as f:
        f.write("# instrument: synthetic (make_allantools_xcheck.py)\n")
        f.write("# start_utc: 2024-03-01T00:00:00Z\n")
        f.write("# input_g: 1\n")
        f.write("time_s,output_g\n")
        for i, v in enumerate(y):
            f.write("%d,%r\n" % (i, v))
    y = np.array(y)

    t_o, ad, ade, adn = allantools.oadev(y, rate=1.0, data_type="freq", taus="octave")
    t_m, md, mde, mdn = allantools.mdev(y, rate=1.0, data_type="freq", taus="octave")
    n_phase = N + 1
    edf_wf = [float(atci.edf_simple(n_phase, float(m), 0)) for m in t_o]
    ci = [atci.confidence_interval(float(d), e) for d, e in zip(ad, edf_wf)]
    noise = []
    for m in t_o:
        if N // int(m) >= 30:
            a_int, _, _, _ = atci.autocorr_noise_id(y, int(m), data_type="freq")
            noise.append(int(a_int))
        else:
            noise.append(None)
    chi2 = []
    for p in (0.15865525393145707, 0.8413447460685429, 0.025, 0.975):
        for nu in (0.7, 1.0, 2.5, 10.0, 137.3, 4000.0, 90000.0):
            chi2.append({"p": p, "nu": nu, "x": float(scipy.stats.chi2.ppf(p, nu))})

    out = {
        "provenance": {
            "generator": "host-sim/tests/data/make_allantools_xcheck.py",
            "allantools": allantools.__version__,
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "python": sys.version.split()[0],
            "calls": "allantools.oadev(y, rate=1.0, data_type='freq', taus='octave'); "
                     "allantools.mdev(same); allantools.ci.edf_simple(N+1, m, 0); "
                     "allantools.ci.confidence_interval(dev, edf); "
                     "allantools.ci.autocorr_noise_id(y, m, data_type='freq'); scipy.stats.chi2.ppf",
        },
        "n_readings": N,
        "oadev": {"tau_s": t_o.tolist(), "dev": ad.tolist(), "ade": ade.tolist(),
                  "n": [int(v) for v in adn], "edf_white_fm": edf_wf,
                  "ci_low_white_fm": [float(c[0]) for c in ci],
                  "ci_high_white_fm": [float(c[1]) for c in ci],
                  "noise_alpha": noise},
        "mdev": {"tau_s": t_m.tolist(), "dev": md.tolist(), "ade": mde.tolist(),
                 "n": [int(v) for v in mdn]},
        "chi2_ppf": chi2,
    }
    with open(os.path.join(HERE, "allantools_xcheck.json"), "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()

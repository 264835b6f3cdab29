"""Cross-check of `accomp discover`'s tidal analysis on the gMetrology record with PyGTide
(ETERNA PREDICT, Hartmann-Wenzel 1995 catalogue): PyGTide predicts the theoretical tide of each
wave group (in phase and 90 deg ahead), numpy fits them with the same B-spline drift and the
pressure channel. Not part of any test; run by hand:
    pip install pygtide numpy; python3 pygtide_tidal_crosscheck.py data/measured/<record>.tsf
"""
import sys, datetime as dt
import numpy as np
import pygtide

LAT, LON, H = 33.98, 116.79, 0.0
GROUPS = [("Q1", 0.5, 0.911), ("O1", 0.911, 0.947), ("M1", 0.947, 0.986),
          ("P1K1", 0.986, 1.016), ("J1", 1.016, 1.5), ("N2", 1.5, 1.916),
          ("M2", 1.916, 1.95), ("L2", 1.95, 1.986), ("S2K2", 1.986, 2.5), ("M3", 2.5, 3.5)]

rows = np.loadtxt(sys.argv[1])
t_unix = np.array([dt.datetime(*map(int, r[:6]), tzinfo=dt.timezone.utc).timestamp()
                   for r in rows]) - 8 * 3600.0           # Beijing time -> UTC
g_nm = rows[:, 6] * 1e4                                    # mGal -> nm/s^2
p_hpa = rows[:, 7]
ok = np.isfinite(g_nm) & np.isfinite(p_hpa) & (np.abs(g_nm) < 9e8) & (p_hpa > 0) & (np.abs(rows[:, 6]) < 9e4)
t_unix, g_nm, p_hpa = t_unix[ok], g_nm[ok], p_hpa[ok]
start = dt.datetime.fromtimestamp(t_unix[0], dt.timezone.utc).date()
t0 = dt.datetime(start.year, start.month, start.day, tzinfo=dt.timezone.utc).timestamp()
hours = int((t_unix[-1] - t0) / 3600) + 2

pt = pygtide.pygtide(msg=False)
def group_tide(i, phase):
    wg = np.array([[a, b, 1.0 if j == i else 0.0, phase if j == i else 0.0]
                   for j, (_, a, b) in enumerate(GROUPS)])
    pt.set_wavegroup(wg)
    pt.predict(LAT, LON, H, start.isoformat(), hours, 60, tidalcompo=0, tidalpoten=7,
               poltidecor=0, lodtidecor=0)
    raw = np.array(pt.raw())
    raw = raw[raw[:, 0] > 0]
    ts = np.array([dt.datetime.strptime("%08d%06d" % (d, s), "%Y%m%d%H%M%S")
                   .replace(tzinfo=dt.timezone.utc).timestamp() for d, s in raw[:, :2]])
    return np.interp(t_unix, ts, raw[:, 2])

cols = []
for i in range(len(GROUPS)):
    cols += [group_tide(i, 0.0), group_tide(i, 90.0)]

# Drift: cubic B-splines with 2-day knots per contiguous segment (gaps > 3 samples).
t = t_unix - t_unix[0]
seg = np.concatenate([[0], np.cumsum(np.diff(t) > 180.0)])
drift = []
for s in np.unique(seg):
    m = seg == s
    a, b = t[m][0], t[m][-1]
    nint = max(1, int(np.ceil((b - a) / 172800.0)))
    h = (b - a) / nint
    x = np.clip((t[m] - a) / h, 0, nint)
    c = np.minimum(np.floor(x).astype(int), nint - 1)
    u = x - c
    basis = [(1 - u) ** 3 / 6, (3 * u**3 - 6 * u**2 + 4) / 6, (-3 * u**3 + 3 * u**2 + 3 * u + 1) / 6, u**3 / 6]
    for k in range(nint + 3):
        col = np.zeros_like(t)
        for q in range(4):
            sel = c == k - q
            idx = np.where(m)[0][sel]
            col[idx] = basis[q][sel]
        drift.append(col)
X = np.column_stack(cols + [p_hpa - p_hpa.mean()] + drift)
beta, *_ = np.linalg.lstsq(X, g_nm, rcond=None)
r = g_nm - X @ beta
print(f"residual std {r.std():.2f} nm/s^2, {len(r)} points")
for i, (name, _, _) in enumerate(GROUPS):
    a, b = beta[2 * i], beta[2 * i + 1]
    print(f"{name:5s} delta {np.hypot(a, b):.4f}  phase {np.degrees(np.arctan2(b, a)):+.3f} deg")
print(f"pressure admittance {beta[2 * len(GROUPS)]:.3f} nm/s^2/hPa")

#!/usr/bin/env python3
"""Pools `uncertainty-coverage --dump` files into the per-parameter before/after table of
docs/uncertainty.md: n, coverage, median |dev|/U (pooled, and the range over configurations),
mean U, RMS deviation, bias.

    pool_coverage.py BEFORE_DUMPS... -- AFTER_DUMPS...   [--uncal] [--config CAMERA/STEP]

The deviations of the two runs are the same scans (same seeds, same options); only U differs.
"""
import math
import sys
from collections import defaultdict


def load(paths, uncal):
    rows = []
    for p in paths:
        for line in open(p):
            f = line.rstrip("\n").split("\t")
            if len(f) < 9:
                continue
            cam, step, seed, spec, label = f[0], f[1], f[2], f[3], f[4]
            dev, u = (float(f[7]), float(f[8])) if uncal else (float(f[5]), float(f[6]))
            rows.append((cam + "/" + step, label.split("(")[0], dev, u))
    return rows


def median(v):
    v = sorted(v)
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def stats(rows):
    by = defaultdict(list)
    for cfg, param, dev, u in rows:
        by[param].append((cfg, dev, u))
    out = {}
    for param, v in by.items():
        n = len(v)
        cov = sum(abs(d) <= u for _, d, u in v)
        ratios = [abs(d) / u if u > 0 else math.inf for _, d, u in v]
        per_cfg = defaultdict(list)
        for (cfg, d, u), r in zip(v, ratios):
            per_cfg[cfg].append(r)
        meds = {c: median(r) for c, r in per_cfg.items()}
        cov_cfg = {c: 100.0 * sum(r <= 1.0 for r in rs) / len(rs) for c, rs in per_cfg.items()}
        out[param] = dict(
            n=n, cov=cov, med=median(ratios), lo=min(meds.values()), hi=max(meds.values()), meds=meds,
            cov_cfg=cov_cfg, meanU=sum(u for _, _, u in v) / n,
            rms=math.sqrt(sum(d * d for _, d, _ in v) / n), bias=sum(d for _, d, _ in v) / n)
    return out


def main():
    args = sys.argv[1:]
    uncal = "--uncal" in args
    args = [a for a in args if a != "--uncal"]
    cfg = None
    if "--config" in args:
        i = args.index("--config")
        cfg = args[i + 1]
        del args[i:i + 2]
    if "--" in args:
        i = args.index("--")
        before_paths, after_paths = args[:i], args[i + 1:]
    else:
        before_paths, after_paths = [], args
    before = load(before_paths, uncal)
    after = load(after_paths, uncal)
    if cfg:
        before = [r for r in before if r[0] == cfg]
        after = [r for r in after if r[0] == cfg]
    b, a = stats(before), stats(after)
    print("  parameter       n | before: cov  median (configs)     mean U | after: cov  median (configs)     mean U |"
          "  RMS dev      bias")
    tb = ta = tn = 0
    for p in sorted(a):
        x = a[p]
        y = b.get(p)
        bs = ("%6.1f%% %5.3f (%5.3f-%5.3f) %10.4g" % (100.0 * y["cov"] / y["n"], y["med"], y["lo"], y["hi"], y["meanU"])
              if y else " " * 40)
        print("  %-12s %4d | %s | %6.1f%% %5.3f (%5.3f-%5.3f) %10.4g | %8.4g %+9.3g" %
              (p, x["n"], bs, 100.0 * x["cov"] / x["n"], x["med"], x["lo"], x["hi"], x["meanU"], x["rms"],
               x["bias"]))
        ta += x["cov"]
        tn += x["n"]
        tb += y["cov"] if y else 0
    if tn:
        print("  all: before %d/%d = %.1f %%, after %d/%d = %.1f %%" %
              (tb, tn, 100.0 * tb / tn, ta, tn, 100.0 * ta / tn))
    cfgs = sorted({r[0] for r in after})
    if len(cfgs) > 1:
        print("\n  per configuration, coverage / median |dev|/U (before -> after):")
        print("  %-12s " % "parameter" + " ".join("%-27s" % c for c in cfgs))
        for p in sorted(a):
            cells = []
            for c in cfgs:
                y = b.get(p)
                x = a[p]
                bc = "%5.1f/%.2f" % (y["cov_cfg"][c], y["meds"][c]) if y and c in y["meds"] else "-"
                ac = "%5.1f/%.2f" % (x["cov_cfg"][c], x["meds"][c]) if c in x["meds"] else "-"
                cells.append("%-27s" % (bc + " -> " + ac))
            print("  %-12s " % p + " ".join(cells))


if __name__ == "__main__":
    main()

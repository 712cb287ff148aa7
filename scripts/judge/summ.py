#!/usr/bin/env python3
"""The judge's comparison of an arm with its baseline (docs/EXPERIMENTS.md, "The judge").

    python3 scripts/judge/summ.py ARM BASE SEEDS [JUDGE_DIR]

ARM and BASE are table tags, SEEDS a comma list; the tables are JUDGE_DIR/t_TAGSEED_SET.md
(scripts/judge/tables.sh; JUDGE_DIR defaults to $JUDGE or out/judge). F1 is that of the
set's mean precision and recall. Prints one row per (seed, set), then what the rules read:
the mean organic/thin change of F1, the smallest change of watertightness on the organic,
thin and validation sets, and the probe's mean F1 (both columns of every shape).
"""
import os
import re
import sys


def mean_row(path):
    for line in open(path):
        if "mean of" in line:
            c = [x.strip() for x in line.split("|")]
            return float(c[2]), float(c[3]), float(c[4])
    raise ValueError(f"{path}: no mean row")


def probe_f1(path):
    f1 = []
    for line in open(path):
        c = [x.strip() for x in line.split("|")]
        if len(c) < 5 or not re.match(r"^\d", c[2] or ""):
            continue
        for cell in c[3:5]:
            p, r, _w = (float(x) for x in cell.split("/"))
            f1.append(0.0 if p + r == 0 else 2 * p * r / (p + r))
    return sum(f1) / len(f1)


def f1(p, r):
    return 0.0 if p + r == 0 else 2 * p * r / (p + r)


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    arm, base, seeds = sys.argv[1], sys.argv[2], sys.argv[3].split(",")
    d = sys.argv[4] if len(sys.argv) > 4 else os.environ.get("JUDGE", "out/judge")
    print(f"| seed | set | {base} P / R / W (F1) | {arm} P / R / W (F1) | ΔF1 | ΔW |")
    print("|---|---|---|---|---|---|")
    judged, dw_judged, probes = [], [], []
    for s in seeds:
        for st in ["organic", "thin", "val", "coarse"]:
            try:
                b = mean_row(f"{d}/t_{base}{s}_{st}.md")
                a = mean_row(f"{d}/t_{arm}{s}_{st}.md")
            except (OSError, ValueError) as e:
                print(f"| {s} | {st} | missing: {e} | | | |")
                continue
            df, dw = f1(a[0], a[1]) - f1(b[0], b[1]), a[2] - b[2]
            if st in ("organic", "thin"):
                judged.append(df)
            if st != "coarse":
                dw_judged.append(dw)
            print(f"| {s} | {st} | {b[0]:.4f} / {b[1]:.4f} / {b[2]:.4f} ({f1(b[0], b[1]):.4f}) | "
                  f"{a[0]:.4f} / {a[1]:.4f} / {a[2]:.4f} ({f1(a[0], a[1]):.4f}) | {df:+.4f} | {dw:+.4f} |")
        try:
            pb, pa = probe_f1(f"{d}/probe_{base}{s}.md"), probe_f1(f"{d}/probe_{arm}{s}.md")
            probes.append(pa - pb)
            print(f"probe, seed {s}: {base} {pb:.4f}, {arm} {pa:.4f} ({pa - pb:+.4f})")
        except (OSError, ValueError, ZeroDivisionError) as e:
            print(f"probe, seed {s}: missing ({e})")
    if judged:
        print(f"mean organic/thin ΔF1 {sum(judged) / len(judged):+.4f} over {len(judged)} pairs")
    if dw_judged:
        print(f"smallest ΔW (organic, thin, val) {min(dw_judged):+.4f}")
    if probes:
        print(f"probe mean ΔF1 {sum(probes) / len(probes):+.4f} over {len(probes)} seeds")


if __name__ == "__main__":
    main()

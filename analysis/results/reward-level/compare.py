"""Paired comparison of two studies over the same replicates (issue 25): each replicate's
mean final return per method, the mean over replicates with a bootstrap interval, and the
probability of improvement P(A > B) of rliable (Mann-Whitney over replicates), with a
bootstrap interval over replicates. Reads the report's protocols.csv.

    python compare.py REPORT/protocols.csv heldout-ranked-floor replicates drex final
"""
import csv
import random
import sys


def per_replicate(rows, study, method, protocol):
    out = {}
    for r in rows:
        p = r["pipeline"]
        base, _, rep = p.partition("/r")
        if base == study and r["method"] == method and r["protocol"] == protocol:
            out[(r["env"], int(rep) if rep else 0)] = float(r["mean"])
    return out


def p_improve(a, b):
    return sum((x > y) + 0.5 * (x == y) for x in a for y in b) / (len(a) * len(b))


def main():
    path, study_a, study_b, method, protocol = sys.argv[1:6]
    rows = list(csv.DictReader(open(path)))
    a, b = per_replicate(rows, study_a, method, protocol), per_replicate(rows, study_b, method, protocol)
    rng = random.Random(0)
    for env in sorted({e for e, _ in a}):
        reps = sorted(r for e, r in a if e == env and (e, r) in b)
        xa, xb = [a[(env, r)] for r in reps], [b[(env, r)] for r in reps]
        boots = []
        for _ in range(10_000):
            idx = [rng.randrange(len(reps)) for _ in reps]
            boots.append(p_improve([xa[i] for i in idx], [xb[i] for i in idx]))
        boots.sort()
        wins = sum(x > y for x, y in zip(xa, xb))
        print(f"{env} {method} {protocol}: replicates {reps}")
        print(f"  {study_a}: " + ", ".join(f"{x:.1f}" for x in xa) + f"; mean {sum(xa) / len(xa):.1f}")
        print(f"  {study_b}: " + ", ".join(f"{x:.1f}" for x in xb) + f"; mean {sum(xb) / len(xb):.1f}")
        print(f"  above on {wins} of {len(reps)} replicates (paired); P({study_a} > {study_b}) = "
              f"{p_improve(xa, xb):.2f} [{boots[249]:.2f}, {boots[9749]:.2f}]")


if __name__ == "__main__":
    main()

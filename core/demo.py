"""`python -m core.demo`: the lecture's worked example, F = integral of exp(sin(3x^2)) over [0, 1], as a table."""

import argparse

from .montecarlo.integrate import LECTURE_TRUE_VALUE, worked_example_table


def format_table(truth, rows):
    lines = [f"true value (Gauss-Legendre, 8 x 200 nodes): {truth:.15f}   (lecture: {LECTURE_TRUE_VALUE})",
             f"{'N':>9} {'F_N':>12} {'error':>12} {'stderr':>11} {'|error|/stderr':>15}"]
    for n, value, err, se in rows:
        z = "" if se != se else f"{abs(err) / se:15.2f}"  # se != se: nan for N = 1
        se_s = "n/a" if se != se else f"{se:.2e}"
        lines.append(f"{n:>9} {value:>12.6f} {err:>12.2e} {se_s:>11} {z}")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--source", default="independent", choices=["independent", "stratified", "sobol", "halton"])
    args = ap.parse_args(argv)
    truth, rows = worked_example_table(seed=args.seed, source=args.source)
    print(format_table(truth, rows))


if __name__ == "__main__":
    main()

"""Share of correctly labelled ideal structures per class, references and weighting (run by hand).

    python tools/eval_structures.py                       # about a minute on 2 cores
    python tools/eval_structures.py --markdown            # tables for docs/structures.md
    python tools/eval_structures.py --samples 1000 --counts 10,25,50 --noise 0.02

For every noise level σ (share of the radius) and expected neighbour count, ``--samples``
fresh randomly rotated samples of each ideal structure (:func:`lidarfx.structures.references.
sample_signatures`, seeds ``[20250, noise index, count, class index]``: the shipped references
use ``[0, prototype, level]``) are labelled by :func:`lidarfx.structures.classify_signatures`
with the default reject threshold and minimum neighbour count, in four variants:

* ``TS`` trained references, structure weighting (the default),
* ``TU`` trained references, uniform weighting,
* ``AS`` analytic references (closed forms), structure weighting,
* ``AU`` analytic references, uniform weighting.

A cell is the share of samples that got their own class (an unclassified or isolated sample
counts as wrong).  Edges are sampled at exactly 90° (no jitter) for the ``edge`` row; the rows
``edge 70°`` and ``edge 120°`` are extra and not in the mean, which is over the seven classes.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

VARIANTS = (("TS", "trained", "structure"), ("TU", "trained", "uniform"),
            ("AS", "analytic", "structure"), ("AU", "analytic", "uniform"))
ROWS = (("plane", "plane", None), ("plane border", "plane_border", None), ("edge 90°", "edge", 90.0),
        ("corner", "corner", None), ("line", "line", None), ("line end", "line_end", None),
        ("volume", "volume", None), ("edge 70°", "edge", 70.0), ("edge 120°", "edge", 120.0))
MEAN_ROWS = 7  # the first seven rows are the classes
SEED = 20250


def _numbers(text: str, kind, what: str) -> list:
    try:
        vals = [kind(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not vals:
        raise argparse.ArgumentTypeError(f"give at least one {what[:-1]}")
    return vals


def evaluate(counts: list[int], noise: list[float], samples: int, variants=VARIANTS) -> dict:
    """``{(noise, count, variant code): shares per row}``."""
    from lidarfx.structures import classify_signatures
    from lidarfx.structures.references import sample_signatures
    from lidarfx.synth.structures import STRUCTURE_IDS

    out: dict = {}
    for i, sigma in enumerate(noise):
        for c in counts:
            shares = {code: [] for code, _, _ in variants}
            for k, (_, structure, angle) in enumerate(ROWS):
                r = sample_signatures(structure, c, angle=angle, noise=[sigma], samples=samples, angle_jitter=0.0,
                                      seed=[SEED, i, c, k])
                for code, refs, weighting in variants:
                    label, _, _ = classify_signatures(r["signature"], r["n"], references=refs, weighting=weighting)
                    shares[code].append(float(np.mean(label == STRUCTURE_IDS[structure])))
            for code in shares:
                out[(sigma, c, code)] = shares[code]
    return out


def table(res: dict, sigma: float, counts: list[int], variants, markdown: bool) -> str:
    cols = [(code, c) for code, _, _ in variants for c in counts]
    head = ["class"] + [f"{code} {c}" for code, c in cols]
    rows = []
    for k, (name, _, _) in enumerate(ROWS):
        rows.append([name] + [f"{100 * res[(sigma, c, code)][k]:.1f}" for code, c in cols])
        if k == MEAN_ROWS - 1:
            rows.append(["**mean**" if markdown else "mean"] +
                        [f"{100 * np.mean(res[(sigma, c, code)][:MEAN_ROWS]):.1f}" for code, c in cols])
    if markdown:
        lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * len(cols)]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
    else:
        w = [max(len(r[j]) for r in rows + [head]) for j in range(len(head))]
        fmt = lambda r: "  ".join(v.ljust(w[0]) if j == 0 else v.rjust(w[j]) for j, v in enumerate(r))  # noqa: E731
        lines = [fmt(head), "-" * len(fmt(head))] + [fmt(r) for r in rows]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("--samples", type=int, default=300, help="samples per class, count and noise level (default 300)")
    ap.add_argument("--counts", type=lambda t: _numbers(t, int, "counts"), default=[25, 50, 100, 400],
                    help="expected points in the sphere, comma-separated (default 25,50,100,400)")
    ap.add_argument("--noise", type=lambda t: _numbers(t, float, "noise levels"), default=[0.0, 0.01, 0.02, 0.05],
                    help="Gaussian σ as a share of the radius, comma-separated (default 0,0.01,0.02,0.05)")
    ap.add_argument("--markdown", action="store_true", help="print Markdown tables")
    args = ap.parse_args(argv)
    if not 2 <= args.samples <= 100_000:
        ap.error("--samples must be from 2 to 100000")
    if any(not 3 <= c <= 100_000 for c in args.counts):
        ap.error("--counts must be from 3 to 100000")
    if any(not 0 <= s <= 0.5 for s in args.noise):
        ap.error("--noise levels must be in [0, 0.5]")

    from lidarfx.structures import DEFAULT_MIN_NEIGHBOURS, DEFAULT_REJECT

    t0 = time.perf_counter()
    res = evaluate(args.counts, args.noise, args.samples)
    took = time.perf_counter() - t0
    legend = ("TS = trained + structure weighting (default), TU = trained + uniform, "
              "AS = analytic + structure, AU = analytic + uniform; column number = expected points in the sphere")
    print(f"Share of correct labels (%), {args.samples} fresh samples per cell, reject {DEFAULT_REJECT:g}, "
          f"min_neighbours {DEFAULT_MIN_NEIGHBOURS}.")
    print(legend + ".")
    for sigma in args.noise:
        print()
        title = f"noise σ = {sigma:g} R"
        print(f"**{title}**" if args.markdown else title)
        print()
        print(table(res, sigma, args.counts, VARIANTS, args.markdown))
    print()
    print(f"({took:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

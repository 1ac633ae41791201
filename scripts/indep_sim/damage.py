#!/usr/bin/env python3
"""Flip single bits in a log, as bit errors on a recorder's storage would.
Usage: python damage.py IN.mcap OUT.mcap [--flips 12] [--seed 5] [--tail 20000]
(the last --tail bytes, the summary section, are left alone)."""
import argparse
import random

ap = argparse.ArgumentParser()
ap.add_argument("inp")
ap.add_argument("out")
ap.add_argument("--flips", type=int, default=12)
ap.add_argument("--seed", type=int, default=5)
ap.add_argument("--tail", type=int, default=20000)
a = ap.parse_args()
b = bytearray(open(a.inp, "rb").read())
random.seed(a.seed)
pos = sorted(random.sample(range(2000, len(b) - a.tail), a.flips))
for p in pos:
    b[p] ^= 1 << random.randrange(8)
open(a.out, "wb").write(b)
print("flipped one bit at offsets", pos)

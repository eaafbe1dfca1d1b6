#!/usr/bin/env python3
"""Render a tier's reference images into the harness's cache (validation/out/cache), without
our renders, ladders or verdicts, so that a later timed run (scripts/refresh-headlines.sh)
spends its time on what it measures. The cache is keyed by the exported scene and the
reference scripts, as `run_cases.py` keys it: run this after the exporters last changed.
References that refuse a scene are reported and skipped.

  validation/.venv/bin/python validation/warm_cache.py full [--only CASES] [--out DIR]
"""
import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from cases import TIERS  # noqa: E402
from run_cases import ROOT, Harness, selected_cases  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("tier", choices=sorted(TIERS))
    ap.add_argument("--pathtracer", default=os.path.join(ROOT, "target", "release", "pathtracer"))
    ap.add_argument("--out", default=os.path.join(HERE, "out"))
    ap.add_argument("--only", default="", help="only cases whose scene name (with its tag) contains one of these comma-separated strings")
    args = ap.parse_args()
    args.backends = "native"
    tier = dict(TIERS[args.tier])
    hz = Harness(args, tier)
    t_all = time.time()
    for case in selected_cases(tier, args.only):
        name = case["scene"] + case.get("tag", "")
        t0 = time.time()
        folder = hz.fresh("warm_cache")
        _, key, ref_dir = hz.export(case, folder)
        if case["kind"] == "geometry":
            # The same calls run_geometry makes, each cached.
            got = [hz.cycles(ref_dir, key, 1, mode, spp=64, renders=8) for mode in ("object-id", "depth", "normal")]
            hz.pov_geometry(ref_dir, key)
        else:
            depths = [case["m"], 1] if case["kind"] == "adaptive" else [case["m"]]
            got = [hz.getref(r, ref_dir, key, m) for r in case["refs"] for m in depths]
        refused = [g["refused"] for g in got if isinstance(g, dict) and "refused" in g]
        print(f"{name} (-m {case.get('m', 1)}): {time.time() - t0:.0f} s" + "".join(f"; refused: {r}" for r in refused), flush=True)
    print(f"warm_cache: the {args.tier} tier's references are in {hz.cache} ({time.time() - t_all:.0f} s)")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""When, at which commit and on which CPU a measurement was made: one definition for the bench,
the harness and the README's tables, so that tables measured together name the same commit and
CPU in the same words.

  python3 validation/provenance.py          # prints "Measured DATE at commit X on CPU."
  python3 validation/provenance.py --clean  # the same, or exit 1 where the tree has uncommitted changes
"""
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _git(*args):
    return subprocess.run(["git", "-C", ROOT, *args], capture_output=True, text=True)


# What a measurement writes, and what cannot change a measurement: the README and the
# documentation. scripts/refresh-headlines.sh writes the bench's tables into them before the
# harness runs, so counting them would mark the harness's own runs "+changes".
DOCUMENTATION = ("README.md", "docs/")


def dirty():
    """Whether tracked files other than the documentation differ from the commit (untracked
    files are not the build's)."""
    r = _git("status", "--porcelain", "--untracked-files=no")
    if r.returncode != 0:
        return True
    changed = [l[3:].split(" -> ")[-1] for l in r.stdout.splitlines() if l.strip()]
    return any(not p.startswith(DOCUMENTATION) for p in changed)


def cpu():
    """'2-vCPU AMD EPYC 9R14': the logical CPUs and /proc/cpuinfo's model name."""
    model = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            model = next((l.split(":", 1)[1].strip() for l in f if l.startswith("model name")), model)
    except OSError:
        pass
    return f"{os.cpu_count()}-vCPU {model}"


def provenance():
    """{date, commit, cpu}; the commit reads 'X+changes' where the tree is dirty."""
    commit = _git("rev-parse", "--short=12", "HEAD").stdout.strip() or "outside git"
    if commit != "outside git" and dirty():
        commit += "+changes"
    return {"date": time.strftime("%Y-%m-%d"), "commit": commit, "cpu": cpu()}


def line(p=None):
    """The sentence every generated table carries."""
    p = p or provenance()
    return f"Measured {p['date']} at commit {p['commit']} on {p['cpu']}."


if __name__ == "__main__":
    if "--clean" in sys.argv and dirty():
        sys.exit("provenance: the tree has uncommitted changes; commit them first, so that the tables name a commit that reproduces them")
    print(line())

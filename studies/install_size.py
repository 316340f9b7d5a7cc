"""What an install of cvxdual weighs, and what each of its dependencies costs.

    python3 -m venv /tmp/v && /tmp/v/bin/pip install .            # or ".[pardiso]", ".[test]"
    /tmp/v/bin/python studies/install_size.py --venv /tmp/v --out reports/install_size.md

Run with the venv's own interpreter: it reads the installed distributions' file lists
(``importlib.metadata``), sums their sizes on disk, and charges each distribution to the direct
requirements of cvxdual that need it: alone (``own``: the requirement and what only it needs) or
together with others (``shared``). ``du -s`` of the whole venv is the total (pip, setuptools and
the interpreter links included).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections import defaultdict
from importlib import metadata
from pathlib import Path


def _name(req: str) -> str:
    return re.split(r"[\s<>=!~;\[(]", req.strip(), maxsplit=1)[0].lower().replace("_", "-")


def _applies(req: str, extras: set[str]) -> bool:
    """Whether a requirement string applies here (its marker: the platform, or an extra we installed)."""
    if ";" not in req:
        return True
    marker = req.split(";", 1)[1]
    m = re.search(r"extra\s*==\s*['\"]([^'\"]+)['\"]", marker)
    if m and m.group(1) not in extras:
        return False
    return True  # platform markers: the distribution is then either installed or not (checked below)


def distributions() -> dict[str, metadata.Distribution]:
    return {d.metadata["Name"].lower().replace("_", "-"): d for d in metadata.distributions()}


def size_of(dist: metadata.Distribution) -> int:
    total = 0
    for f in dist.files or []:
        p = Path(dist.locate_file(f))
        if p.is_file() and not p.is_symlink():
            total += p.stat().st_size
    return total


def closure(name: str, dists: dict, extras: set[str], seen: set | None = None) -> set[str]:
    seen = set() if seen is None else seen
    if name in seen or name not in dists:
        return seen
    seen.add(name)
    for req in dists[name].requires or []:
        if _applies(req, extras if name == "cvxdual" else set()):
            closure(_name(req), dists, extras, seen)
    return seen


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--venv", required=True, help="the virtual environment measured (run with its python)")
    p.add_argument("--extras", nargs="*", default=[], help="extras of cvxdual installed there")
    p.add_argument("--out", default=None, help="markdown file to write (default: print)")
    args = p.parse_args()
    dists = distributions()
    extras = set(args.extras)
    direct = [_name(r) for r in dists["cvxdual"].requires or [] if _applies(r, extras)]
    direct = [d for d in dict.fromkeys(direct) if d in dists]
    needs = {d: closure(d, dists, set()) for d in direct}
    users = defaultdict(set)
    for d, deps in needs.items():
        for x in deps:
            users[x].add(d)
    sizes = {n: size_of(dists[n]) for n in dists}
    mb = 1e6
    rows = []
    for d in direct:
        own = sorted(x for x in needs[d] if users[x] == {d})
        rows.append((sum(sizes[x] for x in own), d, own))
    shared = sorted((x for x in users if len(users[x]) > 1), key=lambda x: -sizes[x])
    du = subprocess.run(["du", "-sm", args.venv], capture_output=True, text=True, check=True).stdout.split()[0]
    lines = [f"# Install size ({'cvxdual' + ('[' + ','.join(sorted(extras)) + ']' if extras else '')}, "
             f"Python {sys.version.split()[0]})", "",
             f"`du -s` of the virtual environment: **{int(du)} MB**. Distributions' files: "
             f"{sum(sizes.values()) / mb:.0f} MB.", "",
             "| direct requirement | MB (it and what only it needs) | of which |", "|---|---|---|"]
    for total, d, own in sorted(rows, reverse=True):
        parts = ", ".join(f"{x} {sizes[x] / mb:.0f}" for x in sorted(own, key=lambda x: -sizes[x]) if sizes[x] >= mb)
        lines.append(f"| {d} | {total / mb:.0f} | {parts or 'itself shared: below'} |")
    lines += ["", "Shared by several requirements (MB): "
              + ", ".join(f"{x} {sizes[x] / mb:.0f} ({', '.join(sorted(users[x]))})" for x in shared
                          if sizes[x] >= mb) + "."]
    text = "\n".join(lines) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

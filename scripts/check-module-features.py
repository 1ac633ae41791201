#!/usr/bin/env python3
"""Fail when the Python module's build would not reuse the test build's compiled tree.

scripts/test.sh builds the workspace's tests with `cargo nextest --workspace`, then the Python
module with `maturin develop`, which builds `stereonav-py` alone. Cargo resolves features over
the packages it builds, so a dependency that the workspace's tests use with more features than
the module does is compiled twice, together with everything that depends on it (minutes on the
2-core CI machine, docs/testing.md). crates/py/Cargo.toml therefore asks for those features too.
This check compares, for every package in the module's tree, its features in both builds and
names what crates/py/Cargo.toml lacks. It needs nothing but cargo and takes seconds.
"""

from __future__ import annotations

import subprocess
import sys


def features(*selection: str) -> dict[str, set[str]]:
    """`name version` -> the features cargo turns on, for a `cargo tree` selection."""
    out = subprocess.run(
        ["cargo", "tree", "--locked", *selection, "-f", "{p}|{f}", "--prefix", "none",
         "--no-dedupe"],
        check=True, capture_output=True, text=True,
    ).stdout
    found: dict[str, set[str]] = {}
    for line in out.splitlines():
        line = line.replace(" (*)", "").strip()
        if not line or "|" not in line:
            continue
        package, feats = line.split("|", 1)
        name_version = " ".join(package.split()[:2])
        found.setdefault(name_version, set()).update(f for f in feats.split(",") if f)
    return found


def main() -> int:
    module = features("-p", "stereonav-py", "-e", "normal,build")
    workspace = features("--workspace", "-e", "normal,build,dev")
    missing = []
    for package, feats in sorted(module.items()):
        extra = workspace.get(package, set()) - feats
        if extra:
            missing.append(f"  {package}: {', '.join(sorted(extra))}")
    if missing:
        print("check-module-features: the workspace's tests build these packages with features the "
              "Python module's build lacks, so maturin would compile them again; add them to "
              "crates/py/Cargo.toml (its last dependencies):", file=sys.stderr)
        print("\n".join(missing), file=sys.stderr)
        return 1
    print(f"check-module-features: the Python module's {len(module)} packages have the test "
          "build's features")
    return 0


if __name__ == "__main__":
    sys.exit(main())

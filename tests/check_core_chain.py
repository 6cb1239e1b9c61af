#!/usr/bin/env python3
"""Checks that the core's folders form a one-way chain: a file in plugin/core/src/ includes only
headers of its own folder or of a folder lower in the chain (docs/architecture.md)."""
import os, re, sys

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
src = os.path.join(root, "plugin", "core", "src")
# Lowest first; folders on one rank include none of each other.
chain = [["tasks"], ["geometry"], ["kernels"], ["state", "prepare"], ["collision", "contact"],
         ["dynamics"], ["integrators"], ["solver"], ["bullet"]]
rank = {folder: level for level, folders in enumerate(chain) for folder in folders}
include = re.compile(r'^\s*#\s*include\s*"([^"]+)"', re.M)
bad = count = 0
for folder in sorted(os.listdir(src)):
    if folder not in rank:
        print(f"plugin/core/src/{folder}/: not in the chain"); bad += 1
        continue
    for name in sorted(os.listdir(os.path.join(src, folder))):
        path = os.path.join(src, folder, name)
        for target in include.findall(open(path, encoding="utf-8").read()):
            count += 1
            if os.path.isfile(os.path.join(src, folder, target)) or "/" not in target:
                continue
            other = target.split("/")[0]
            if other in rank and other != folder and rank[other] >= rank[folder]:
                print(f"plugin/core/src/{folder}/{name}: includes {target}, not lower in the chain")
                bad += 1
print(f"{count} includes in plugin/core/src/, {bad} against the chain")
sys.exit(1 if bad else 0)

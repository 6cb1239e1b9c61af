#!/usr/bin/env python3
"""Checks that the tests outside tests/internal include no target's private header (src/)."""
import os, re, sys
root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
tests = os.path.join(root, "tests")
layers = ["plugin", "adapters", "scenes", "comparisons", "python"]
# The folders allowed a private include directory, and which (tests/internal/README.md).
allowed = {os.path.join(tests, "internal"): os.path.join(root, "plugin", "core", "src"),
           os.path.join(tests, "fuzz"): os.path.join(root, "adapters", "io", "src")}
public, private = [], []
for layer in layers:
    for directory, subdirectories, _ in os.walk(os.path.join(root, layer)):
        for name in subdirectories:
            if name in ("include", "src"):
                (public if name == "include" else private).append(os.path.join(directory, name))
include = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', re.M)
def resolves(name, directories):
    return next((d for d in directories if os.path.isfile(os.path.join(d, name))), None)
bad = 0; count = 0
for directory, _, files in os.walk(tests):
    for f in sorted(files):
        if not f.endswith((".cpp", ".h")): continue
        path = os.path.join(directory, f)
        for name in include.findall(open(path, encoding="utf-8").read()):
            count += 1
            if resolves(name, [directory, tests] + public): continue
            source = resolves(name, private)
            if source and source != allowed.get(directory):
                print(f"{os.path.relpath(path, root)}: includes {name}, private to "
                      f"{os.path.relpath(source, root)}"); bad += 1
print(f"{count} includes in tests/, {bad} of a private header")
sys.exit(1 if bad else 0)

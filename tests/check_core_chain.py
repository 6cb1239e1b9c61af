#!/usr/bin/env python3
"""Checks that the plugin's layers and the core's folders form one-way chains
(docs/architecture.md): a file of plugin/<layer>/ includes no public header of a layer above it
(tasks, then core, then fibres), and a file in plugin/core/src/ includes only headers of its own
folder or of a folder lower in the chain; and that a stage below the solver takes the parts of a
muscle's state it uses, not the whole MuscleState, as do the solver's stages but those named in
kWholeStages."""
import os, re, sys

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
plugin = os.path.join(root, "plugin")
src = os.path.join(plugin, "core", "src")
include = re.compile(r'^\s*#\s*include\s*"([^"]+)"', re.M)
bad = count = 0

# The plugin's layers, lowest first.
layers = ["tasks", "core", "fibres"]
for level, layer in enumerate(layers):
    higher = [os.path.join(plugin, other, "include") for other in layers[level + 1:]]
    for directory, _, files in os.walk(os.path.join(plugin, layer)):
        for name in sorted(files):
            path = os.path.join(directory, name)
            if not name.endswith((".cpp", ".h")): continue
            for target in include.findall(open(path, encoding="utf-8").read()):
                count += 1
                if any(os.path.isfile(os.path.join(h, target)) for h in higher):
                    print(f"{os.path.relpath(path, root)}: includes {target}, of a higher layer")
                    bad += 1

# The core's folders, lowest first; folders on one rank include none of each other.
chain = [["geometry"], ["kernels"], ["state", "prepare"], ["collision", "contact"],
         ["dynamics"], ["integrators"], ["solver"], ["bullet"]]
rank = {folder: level for level, folders in enumerate(chain) for folder in folders}
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
# The stages below the solver take the parts of a muscle's state they use (MuscleState's bases,
# the CollidingMuscle and IntegratedMuscle views), never the whole MuscleState; only the state's
# own folder names it.
whole = re.compile(r"\bMuscleState\s*[&*]")
for folder in sorted(os.listdir(src)):
    if rank.get(folder, len(chain)) >= rank["solver"] or folder == "state": continue
    for name in sorted(os.listdir(os.path.join(src, folder))):
        text = open(os.path.join(src, folder, name), encoding="utf-8").read()
        for number, line in enumerate(text.splitlines(), 1):
            if whole.search(line):
                print(f"plugin/core/src/{folder}/{name}:{number}: takes the whole MuscleState")
                bad += 1
# So do the solver's stages (the functions its headers declare), but for the local step's
# iteration, which reads and writes every part but the chunks and the guard's snapshot.
kWholeStages = {"localIteration"}
declaration = re.compile(r"\b(\w+)\s*\(([^()]*)\)")
for name in sorted(os.listdir(os.path.join(src, "solver"))):
    if not name.endswith(".h"): continue
    text = open(os.path.join(src, "solver", name), encoding="utf-8").read()
    for match in declaration.finditer(text):
        if whole.search(match.group(2)) and match.group(1) not in kWholeStages:
            number = text.count("\n", 0, match.start()) + 1
            print(f"plugin/core/src/solver/{name}:{number}: {match.group(1)} takes the whole "
                  "MuscleState")
            bad += 1
print(f"{count} includes in plugin/, {bad} against the chains")
sys.exit(1 if bad else 0)

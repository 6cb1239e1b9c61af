#!/usr/bin/env python3
"""Checks the relative links (and their #anchors) of every tracked Markdown file."""
import os, re, subprocess, sys, unicodedata
root = subprocess.check_output(["git", "rev-parse", "--show-toplevel"], text=True).strip()
files = subprocess.check_output(["git", "ls-files", "*.md"], cwd=root, text=True).split()
link = re.compile(r"(?<!\!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
def slug(h):
    h = h.strip().lower()
    h = re.sub(r"[^\w\- ]", "", h)  # GitHub drops punctuation but keeps - and _
    return h.replace(" ", "-")
anchors = {}
def anchors_of(path):
    if path not in anchors:
        out, seen = set(), {}
        fence = False
        for line in open(path, encoding="utf-8"):
            if line.startswith("```"): fence = not fence
            if fence: continue
            m = re.match(r"#{1,6}\s+(.*)", line)
            if m:
                s = slug(m.group(1)); n = seen.get(s, 0); seen[s] = n + 1
                out.add(s if n == 0 else f"{s}-{n}")
        anchors[path] = out
    return anchors[path]
bad = 0; count = 0
for f in files:
    text = open(os.path.join(root, f), encoding="utf-8").read()
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    for m in link.finditer(text):
        target = m.group(1) or m.group(2)
        if re.match(r"[a-z]+:", target): continue
        count += 1
        path, _, anchor = target.partition("#")
        full = os.path.normpath(os.path.join(root, os.path.dirname(f), path)) if path else os.path.join(root, f)
        if not os.path.exists(full):
            print(f"{f}: missing {target}"); bad += 1; continue
        if anchor and full.endswith(".md") and anchor not in anchors_of(full):
            print(f"{f}: no anchor {target}"); bad += 1
print(f"{count} relative links in {len(files)} files, {bad} broken")
sys.exit(1 if bad else 0)

#!/usr/bin/env python3
"""Lists the functions longer than a limit (80 lines) in the repository's C++ sources."""
import os, re, sys

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
folders = ["plugin", "adapters", "scenes", "comparisons", "python", "tests"]
limit = 80
literal = re.compile(r'R"(\w*)\((?:.|\n)*?\)\1"|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'|'
                     r'//[^\n]*|/\*(?:.|\n)*?\*/')
scope = re.compile(r'\b(namespace|class|struct|union|enum)\b[^()]*$|extern\s*$|=\s*$')


def blank(match):
    return re.sub(r"[^\n]", " ", match.group(0))


def functions(text):
    """(first line, last line, head) of every function body not inside another one."""
    text = literal.sub(blank, text)
    text = re.sub(r"^\s*#.*$", "", text, flags=re.M)
    stack, start = [], 0  # per open brace: (is a function body or inside one, line, head)
    for i, c in enumerate(text):
        if c in ";{}":
            head = " ".join(text[start:i].split())
            start = i + 1
        if c == "{":
            inside = any(kind for kind, _, _ in stack)
            function = not inside and "(" in head and not scope.search(head.split("(")[0])
            stack.append((inside or function, text.count("\n", 0, i) + 1, head if function else None))
        elif c == "}" and stack:
            kind, line, name = stack.pop()
            if name is not None:
                yield line, text.count("\n", 0, i) + 1, name


long = 0
for folder in folders:
    for directory, _, files in os.walk(os.path.join(root, folder)):
        for f in sorted(files):
            if not f.endswith((".cpp", ".h")):
                continue
            path = os.path.join(directory, f)
            for first, last, head in functions(open(path, encoding="utf-8").read()):
                if last - first + 1 > limit:
                    long += 1
                    print(f"{os.path.relpath(path, root)}:{first}: {last - first + 1} lines: {head[:90]}")
print(f"{long} functions over {limit} lines")
sys.exit(1 if long else 0)

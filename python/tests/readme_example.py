"""Runs README.md's Python example (the ```python block of its "Python" section) in a scratch
directory and checks that it saved the plot it says it saves.

Usage: readme_example.py README.md WORK_DIR (with the build's module on PYTHONPATH)."""
import os
import re
import sys

try:
    import matplotlib  # noqa: F401
    import numpy  # noqa: F401
except ImportError as missing:
    print(f"{missing.name} is not installed: skipped")
    sys.exit(77)


def example(readme):
    """The first ```python block after the "## Python" heading."""
    section = readme.split("\n## Python", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def main(readme_path, work_dir):
    with open(readme_path) as f:
        code = example(f.read())
    saved = re.findall(r"savefig\(\"([^\"]+)\"", code)
    assert saved, "the example saves no plot"
    os.makedirs(work_dir, exist_ok=True)
    os.chdir(work_dir)
    for name in saved:
        if os.path.exists(name):
            os.remove(name)
    exec(compile(code, readme_path, "exec"), {"__name__": "__main__"})
    for name in saved:
        assert os.path.getsize(name) > 1000, f"{name} was not written"
        print(f"wrote {os.path.join(work_dir, name)}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

#!/usr/bin/env python3
"""Checks docs/DESIGN.md's module table ("who may depend on whom") against
the #include lines of the product code: a module may include its own files,
libc/system headers and the public header (module/module.h) of a module its
row names; shaders/ may be included by the modules that list it. Also checks
that no module reaches into another module's private files.

    python3 scripts/check-deps.py        exit 0 ok, 1 violations (listed)
"""
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
ROW = re.compile(r"^\| `([a-z_]+)/` \| .* \| (.*) \|$")
INCLUDE = re.compile(r'^\s*#\s*include\s+"([a-z_]+)/([^"]+)"', re.M)
NOT_MODULES = {"tests", "bench", "docs", "scripts", "cmake", "build"}


def read_table():
    allowed = {}
    with open(os.path.join(ROOT, "docs", "DESIGN.md")) as f:
        for line in f:
            m = ROW.match(line.strip())
            if not m or m.group(1) in NOT_MODULES:
                continue
            deps = m.group(2)
            if "everything" in deps:
                allowed[m.group(1)] = None
                continue
            # "core, gpu (the reference ...), fusion (read-only)": names before
            # any parenthesis, comma separated.
            names = re.sub(r"\([^)]*\)", "", deps)
            allowed[m.group(1)] = {n.strip() for n in names.split(",") if re.fullmatch(r"[a-z_]+", n.strip())}
    return allowed


def main():
    allowed = read_table()
    if not allowed:
        print("check-deps: no module table found in docs/DESIGN.md")
        return 1
    problems = []
    folders = sorted(d for d in os.listdir(ROOT) if os.path.isdir(os.path.join(ROOT, d)) and not d.startswith("."))
    for mod in folders:
        if mod in NOT_MODULES or mod.startswith("build"):
            continue
        has_code = any(n.endswith((".c", ".h")) for n in os.listdir(os.path.join(ROOT, mod)))
        if has_code and mod not in allowed:
            problems.append(f"{mod}/: a module with code but no row in docs/DESIGN.md's table")
            continue
        deps = allowed.get(mod)
        for dirpath, _, files in os.walk(os.path.join(ROOT, mod)):
            for name in files:
                if not name.endswith((".c", ".h", ".cpp")):
                    continue
                path = os.path.join(dirpath, name)
                rel = os.path.relpath(path, ROOT)
                with open(path, errors="replace") as f:
                    text = f.read()
                for other, header in INCLUDE.findall(text):
                    if other == mod:
                        continue
                    if other not in allowed and other != "shaders":
                        continue  # not a module folder (e.g. a system path)
                    if deps is not None and other not in deps:
                        problems.append(f"{rel}: includes {other}/{header}, but {mod}/ may depend on "
                                        f"{', '.join(sorted(deps)) or 'nothing'} only")
                    elif other != "shaders" and header != f"{other}.h":
                        problems.append(f"{rel}: includes {other}/{header}, a private file of {other}/ "
                                        f"(only {other}/{other}.h is public)")
    for p in problems:
        print("check-deps:", p)
    if not problems:
        print(f"check-deps: {len(allowed)} modules, includes match docs/DESIGN.md")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())

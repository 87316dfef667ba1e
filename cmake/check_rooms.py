#!/usr/bin/env python3
"""Fails when a source file includes a header its room may not use.

Input: the rooms table written by cmake/rooms.cmake ("target=folder=dep,dep" per line). A file
belongs to the room whose folder is the longest prefix of its path. It may include headers of its
own room, of every room reachable through the declared dependencies, and the generated API
(inspection/v1/...) only when inspection_proto is reachable. Headers under another room's
internal/ folder are never allowed. Exit status 1 lists every violation as file:line.
"""
import os
import re
import sys

root, table = sys.argv[1], sys.argv[2]
rooms = {}  # target -> (folder, deps)
for line in open(table):
    line = line.strip()
    if not line:
        continue
    target, folder, deps = line.split("=")
    rooms[target] = (folder, [d for d in deps.split(",") if d])
rooms.setdefault("inspection_proto", ("", []))
folders = sorted(((f, t) for t, (f, _) in rooms.items() if f), key=lambda x: -len(x[0]))


def room_of(path):
    for folder, target in folders:
        if path.startswith(folder + "/"):
            return target
    return None


def reachable(target):
    seen, todo = set(), [target]
    while todo:
        t = todo.pop()
        for d in rooms.get(t, ("", []))[1]:
            if d not in seen:
                seen.add(d)
                todo.append(d)
    return seen


include_re = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
errors = []
for folder, target in folders:
    allowed = reachable(target) | {target}
    for dirpath, _, files in os.walk(os.path.join(root, folder)):
        for name in files:
            if not name.endswith((".h", ".cc")):
                continue
            path = os.path.relpath(os.path.join(dirpath, name), root)
            if room_of(path) != target:
                continue  # a nested room's file
            text = open(os.path.join(root, path), encoding="utf-8").read()
            for m in include_re.finditer(text):
                inc = m.group(1)
                line = text.count("\n", 0, m.start()) + 1
                if inc.startswith("inspection/"):
                    if "inspection_proto" not in allowed:
                        errors.append(f"{path}:{line}: {target} may not include the generated API {inc}")
                    continue
                other = room_of(inc)
                if other is None:
                    continue  # a header outside every room (e.g. the build's generated files)
                if other != target and "/internal/" in inc:
                    errors.append(f"{path}:{line}: {inc} is internal to {other}")
                elif other not in allowed:
                    errors.append(f"{path}:{line}: {target} includes {inc} of {other}, not among its declared rooms")
if errors:
    print("room check failed (cmake/rooms.cmake, declared DEPS):", file=sys.stderr)
    for e in errors:
        print("  " + e, file=sys.stderr)
    sys.exit(1)
open(sys.argv[3], "w").write("ok\n")

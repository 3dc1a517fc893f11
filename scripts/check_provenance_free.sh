#!/usr/bin/env bash
# Fails when the user-facing documents or the sources carry measurement provenance that rots
# where it stands: commit hashes, run ids, load-average figures or issue numbers. Those belong
# in dated decision records (docs/decisions/), run folders and the tracker; a doc comment keeps
# the contract and links the record.
#
#   scripts/check_provenance_free.sh [--allow FILE] [PATH...]
#
# PATH: files or folders (searched recursively for text files). Default: README.md,
# ARCHITECTURE.md and every crates/*/src folder of the repository (then allow-list entries
# that matched nothing are noted on stderr, so stale exceptions get removed).
# --allow FILE: the allow-list (default scripts/provenance_allow.txt, if present). One exception
# per line, `GLOB | TEXT | REASON`: a finding in a file whose repository path matches GLOB
# (shell-style, `*` crosses folders), on a line containing TEXT, is accepted. REASON must say
# why; lines starting with `#` and blank lines are ignored.
#
# What is flagged (per line, case-insensitive where it makes sense):
#   hash    7-40 lowercase hex characters standing alone with at least one digit and at least
#           one letter a-f (not 0x constants, not #rgb colour codes, not longer hex strings such
#           as SHA-256 digests, not part of an identifier or a UUID)
#   run-id  a UTC run stamp: 8 digits, T, 6 digits, Z (20261127T012132Z)
#   load    a load figure: `load 1.7`, `load average 3.4`, `load averages of 2` (the words
#           "load average" alone, describing what the harness records, are fine)
#   issue   `issue 14`, `issues 14 and 16`, `issue #14`, or `#14` in prose
#
# Prints `file:line: kind: match` for every finding and exits 1 if there is any (0 otherwise,
# 2 on a usage error). Needs bash and python3 (standard library only).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
allow=""
paths=()
while [ $# -gt 0 ]; do
  case $1 in
    --allow) [ $# -ge 2 ] || { echo "error: --allow needs a file" >&2; exit 2; }; allow=$2; shift 2 ;;
    --help|-h) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "${BASH_SOURCE[0]}"; exit 0 ;;
    --) shift; paths+=("$@"); break ;;
    -*) echo "error: unknown option $1" >&2; exit 2 ;;
    *) paths+=("$1"); shift ;;
  esac
done
if [ -z "$allow" ] && [ -f "$root/scripts/provenance_allow.txt" ]; then
  allow="$root/scripts/provenance_allow.txt"
fi
if [ -n "$allow" ] && [ ! -f "$allow" ]; then
  echo "error: allow-list $allow does not exist" >&2
  exit 2
fi
default_scan=0
if [ ${#paths[@]} = 0 ]; then
  default_scan=1
  paths=("$root/README.md" "$root/ARCHITECTURE.md")
  for d in "$root"/crates/*/src; do [ -d "$d" ] && paths+=("$d"); done
fi

exec python3 - "$root" "$allow" "$default_scan" "${paths[@]}" <<'PY'
import fnmatch
import os
import re
import sys

root, allow_file, default_scan, paths = sys.argv[1], sys.argv[2], sys.argv[3] == "1", sys.argv[4:]

# Hex standing alone: not after a letter, digit or `_` (so not the digits of a 0x constant or an
# identifier), `#` (a colour) or `-` (a UUID group), and not before one (so not a prefix of a
# longer digest).
HEX = re.compile(r"(?<![0-9A-Za-z_#$\-])([0-9a-f]{7,40})(?![0-9A-Za-z_\-])")
RUN_ID = re.compile(r"(?<!\d)\d{8}T\d{6}Z")
LOAD = re.compile(
    r"\bload(?:[ -]+averages?)?(?:\s+(?:of|was|is|at|around|about|near|between|from))?"
    r"(?:\s+(?:start|end))?\s*[:=~]?\s*~?\d",
    re.IGNORECASE,
)
ISSUE = re.compile(r"\bissues?\s+#?\d+|(?<![\w&#/])#\d+\b", re.IGNORECASE)
# `#123` is a colour on lines that style something (CSS, SVG, HTML attributes).
COLOUR_LINE = re.compile(
    r"colou?r|fill|stroke|background|border|style|rgb|shadow|outline|:\s*#[0-9a-fA-F]{3,8}\b",
    re.IGNORECASE,
)
TEXT_EXT = {
    ".rs", ".md", ".toml", ".txt", ".html", ".js", ".css", ".json", ".py", ".sh", ".c", ".h",
    ".svg", ".yml", ".yaml",
}


def load_allow(path):
    rules = []
    if not path:
        return rules
    with open(path, encoding="utf-8") as f:
        for n, raw in enumerate(f, 1):
            line = raw.rstrip("\n")
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            parts = [p.strip() for p in line.split(" | ")]
            if len(parts) != 3 or not all(parts):
                print(f"error: {path}:{n}: expected `GLOB | TEXT | REASON`, got: {line}", file=sys.stderr)
                sys.exit(2)
            rules.append((parts[0], parts[1]))
    return rules


def files(paths):
    for p in paths:
        if os.path.isdir(p):
            for d, dirs, names in os.walk(p):
                dirs.sort()
                for name in sorted(names):
                    if os.path.splitext(name)[1] in TEXT_EXT:
                        yield os.path.join(d, name)
        elif os.path.isfile(p):
            yield p
        else:
            print(f"error: {p} does not exist", file=sys.stderr)
            sys.exit(2)


def findings(line):
    out = []
    for m in HEX.finditer(line):
        tok = m.group(1)
        if not (re.search(r"\d", tok) and re.search(r"[a-f]", tok)):
            continue
        # digits with a single exponent letter are numbers (1e10), not hashes
        if re.fullmatch(r"\d+e\d+", tok):
            continue
        out.append(("hash", tok))
    for m in RUN_ID.finditer(line):
        out.append(("run-id", m.group(0)))
    for m in LOAD.finditer(line):
        out.append(("load", m.group(0)))
    colour = COLOUR_LINE.search(line) is not None
    for m in ISSUE.finditer(line):
        tok = m.group(0)
        if tok.startswith("#") and colour and len(tok) - 1 in (3, 4, 6, 8):
            continue
        out.append(("issue", tok))
    return out


rules = load_allow(allow_file)
total = 0
used = set()
for path in files(paths):
    full = os.path.abspath(path)
    # Paths inside the repository are named from its root (as the allow-list names them).
    rel = os.path.relpath(full, root if full.startswith(root + os.sep) else os.getcwd())
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().split("\n")
    except UnicodeDecodeError:
        continue
    for n, line in enumerate(lines, 1):
        for kind, tok in findings(line):
            allowed = False
            for i, (glob, text) in enumerate(rules):
                if fnmatch.fnmatch(rel, glob) and text in line:
                    allowed = True
                    used.add(i)
                    break
            if not allowed:
                total += 1
                print(f"{rel}:{n}: {kind}: {tok}")
for i, (glob, text) in enumerate(rules):
    # A stale exception is worth a note only when everything it could match was scanned.
    if default_scan and i not in used:
        print(f"note: allow-list entry `{glob} | {text}` matched nothing", file=sys.stderr)
if total:
    print(
        f"{total} finding(s): move measurement provenance (commits, run ids, loads, issue "
        "numbers) into docs/decisions/ and keep the contract here, or add a justified "
        "exception to the allow-list",
        file=sys.stderr,
    )
    sys.exit(1)
PY

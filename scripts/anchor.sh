#!/usr/bin/env bash
# Every external anchor in one command: Embree (scripts/anchor_embree.sh), tinybvh beside
# Embree (scripts/anchor_tinybvh.sh) and fidget (scripts/anchor_fidget.sh) on the current
# build, one after the other, each in its own interleaved rounds on thread CPU time. They
# write the anchor files `marchmesh bench --anchor` and `marchmesh findings --anchor` read;
# this command checks every tool first, records the load average before and after each
# anchor, and files a note listing what it wrote. docs/anchors.md says what each measures.
#
#   scripts/anchor.sh [--quick] [--large] [--only embree,tinybvh,fidget] [--out DIR] [--check]
#
#   --quick   a smoke run: 2 rounds of 3 repeats (the tinybvh anchor on its BVH8 layout
#             only), fidget's 3 repeats. The files record their rounds and repeats, so a
#             quick run is never mistaken for a full one.
#   --large   the mesh anchors also trace the full Stanford dragon (871k triangles; see
#             scripts/anchor_embree.sh for where it is found).
#   --only    a comma-separated subset of the anchors (default: all three).
#   --out     where the files go (default: bench-results/anchors). Never overwritten: each
#             file takes a fresh name (a suffix -2, -3, ... when its second is taken).
#   --check   only check that every tool the chosen anchors need is there, and say what to
#             install when one is not; writes nothing.
#
# The machine is often shared: run it niced (`nice -n 5 scripts/anchor.sh`); the ratios are
# of interleaved rounds, and the load is written beside them. CARGO_TARGET_DIR, CC, CXX,
# TINYBVH_DIR, TINYBVH_GIT_DIR and EMBREE_VENV are honoured as the anchor scripts document.
# Exit status: 0 when every chosen anchor wrote its files, 1 when a tool is missing or an
# anchor failed (the files of those before it stay), 2 on a usage error.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=scripts/anchor_common.sh
. "$root/scripts/anchor_common.sh"

usage() {
    echo "usage: scripts/anchor.sh [--quick] [--large] [--only embree,tinybvh,fidget] [--out DIR] [--check]" >&2
    exit 2
}

quick=0
large=0
check=0
only="embree,tinybvh,fidget"
out="$root/bench-results/anchors"
given="$*"
while [ $# -gt 0 ]; do
    case "$1" in
        --quick) quick=1 ;;
        --large) large=1 ;;
        --check) check=1 ;;
        --only)
            [ $# -ge 2 ] || usage
            only="$2"
            shift
            ;;
        --out)
            [ $# -ge 2 ] && [ -n "$2" ] || usage
            out="$2"
            shift
            ;;
        -h | --help)
            sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'
            exit 0
            ;;
        *)
            echo "scripts/anchor.sh: unknown argument '$1'" >&2
            usage
            ;;
    esac
    shift
done

anchors=()
IFS=',' read -r -a wanted <<<"$only"
for a in "${wanted[@]}"; do
    case "$a" in
        embree | tinybvh | fidget)
            case " ${anchors[*]:-} " in *" $a "*) ;; *) anchors+=("$a") ;; esac
            ;;
        *)
            echo "scripts/anchor.sh: --only: '$a' is not an anchor (embree, tinybvh, fidget)" >&2
            exit 2
            ;;
    esac
done
[ "${#anchors[@]}" -gt 0 ] || usage
wants() { case " ${anchors[*]} " in *" $1 "*) return 0 ;; *) return 1 ;; esac; }

# --- Tools: every missing one is named with what to install, before anything runs. ---
missing=()
need_cmd() { # need_cmd COMMAND WHAT-AND-HOW-TO-INSTALL
    command -v "$1" >/dev/null 2>&1 || missing+=("$2")
}
need_cmd cargo "cargo (Rust): install it with rustup, https://rustup.rs"
if wants embree || wants tinybvh; then
    need_cmd "${CC:-cc}" "a C compiler '${CC:-cc}' for scripts/embree_trace.c: install gcc or clang (Debian/Ubuntu: apt-get install build-essential) or set CC"
    if ! command -v python3 >/dev/null 2>&1; then
        missing+=("python3 (3.9 or newer, with venv) for the Embree and tinybvh anchors: apt-get install python3 python3-venv")
    fi
    if venv="$(anchor_venv embree-venv 2>&1)"; then
        if [ -x "$venv/bin/python" ]; then
            if ! "$venv/bin/python" -c 'import embreex, numpy' >/dev/null 2>&1; then
                missing+=("Embree 4 (the embreex package) and numpy in $venv: $venv/bin/pip install embreex numpy")
            fi
        elif command -v python3 >/dev/null 2>&1 && ! python3 -c 'import venv, ensurepip' >/dev/null 2>&1; then
            missing+=("python3's venv module, to create $venv with Embree 4 (embreex) and numpy: apt-get install python3-venv")
        else
            echo "note: $venv will be created with Embree 4 (embreex) and numpy from the Python package index (network needed once)"
        fi
    else
        missing+=("a Python environment for Embree: $venv")
    fi
fi
if wants tinybvh; then
    need_cmd "${CXX:-c++}" "a C++17 compiler '${CXX:-c++}' for scripts/tinybvh_trace.cpp: install g++ or clang++ (Debian/Ubuntu: apt-get install build-essential) or set CXX"
    tinybvh_git="${TINYBVH_GIT_DIR:-/work/.mirror/jbikker+tinybvh/repo}"
    if [ -n "${TINYBVH_DIR:-}" ]; then
        [ -f "$TINYBVH_DIR/tiny_bvh.h" ] \
            || missing+=("tinybvh's header: TINYBVH_DIR=$TINYBVH_DIR has no tiny_bvh.h (git clone https://github.com/jbikker/tinybvh and set TINYBVH_DIR to the checkout)")
    elif ! { command -v git >/dev/null 2>&1 \
        && git --git-dir="$tinybvh_git" cat-file -e HEAD:tiny_bvh.h 2>/dev/null; }; then
        missing+=("tinybvh's header tiny_bvh.h: neither TINYBVH_DIR is set nor has the git directory $tinybvh_git (TINYBVH_GIT_DIR) the file: git clone https://github.com/jbikker/tinybvh and set TINYBVH_DIR to the checkout")
    fi
fi
if wants fidget && [ ! -f "$root/crates/anchor-fidget/Cargo.toml" ]; then
    missing+=("the fidget anchor's crate crates/anchor-fidget (its Cargo.toml is missing)")
fi
if [ "${#missing[@]}" -gt 0 ]; then
    echo "scripts/anchor.sh: missing what the ${anchors[*]} anchor(s) need:" >&2
    for m in "${missing[@]}"; do
        echo "  - $m" >&2
    done
    exit 1
fi
echo "tools found for: ${anchors[*]}"
if [ "$check" = 1 ]; then
    exit 0
fi

# --- Run. ---
mkdir -p "$out"
out="$(cd "$out" && pwd)"
anchor_private_tmp
note="$(anchor_reserve "$out" anchors)"
export ANCHOR_OUT_DIR="$out"
mesh_flags=()
fidget_flags=()
tinybvh_flags=()
if [ "$quick" = 1 ]; then
    mesh_flags=(--rounds 2 --repeats 3)
    tinybvh_flags=(--layouts bvh8)
    fidget_flags=(--repeats 3)
fi
large_flag=()
if [ "$large" = 1 ]; then
    large_flag=(--large)
fi
{
    echo "# Anchor run, ${note##*/anchors-}"
    echo
    echo "Command: scripts/anchor.sh $given"
    echo
    echo "Commit: $(git -C "$root" rev-parse HEAD 2>/dev/null || echo unknown)"
    echo
    echo "| anchor | load at start | load at end | files |"
    echo "|---|---|---|---|"
} >>"$note.md"

load() { cut -d' ' -f1-3 /proc/loadavg; }
status=0
written=()
for a in "${anchors[@]}"; do
    echo "=== $a anchor (load $(load)) ==="
    start="$(load)"
    log="$anchor_tmp/$a.log"
    case "$a" in
        embree) cmd=("$root/scripts/anchor_embree.sh" "${large_flag[@]}" "${mesh_flags[@]}") ;;
        tinybvh) cmd=("$root/scripts/anchor_tinybvh.sh" "${large_flag[@]}" "${mesh_flags[@]}" "${tinybvh_flags[@]}") ;;
        fidget) cmd=("$root/scripts/anchor_fidget.sh" "${fidget_flags[@]}") ;;
    esac
    if "${cmd[@]}" 2>&1 | tee "$log"; then
        # Each anchor script's last line: "wrote BASE.json ..." naming what it filed.
        files="$(sed -n 's/^wrote \(.*\.json\).*/\1/p' "$log" | tail -n 1)"
        written+=("$files")
        echo "| $a | $start | $(load) | ${files//"$root"\//} |" >>"$note.md"
    else
        status=1
        echo "| $a | $start | $(load) | failed |" >>"$note.md"
        case "$a" in
            fidget) echo "scripts/anchor.sh: the fidget anchor failed: building crates/anchor-fidget needs fidget 0.4 from crates.io (network once) and a C linker; see above" >&2 ;;
            *) echo "scripts/anchor.sh: the $a anchor failed; see above" >&2 ;;
        esac
    fi
done
{
    echo
    echo "Read them with \`marchmesh findings RUN... --anchor FILE.json ...\` or \`marchmesh bench --anchor FILE.json\`."
} >>"$note.md"
echo "load at end: $(uptime)"
echo "anchor note: $note.md"
for f in "${written[@]}"; do
    echo "anchor file: $f"
done
exit "$status"

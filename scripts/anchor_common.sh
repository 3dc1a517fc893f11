# Shared by scripts/anchor_embree.sh and scripts/anchor_fidget.sh (sourced, not run): private
# temporary files, output names that never collide, and a Python environment nobody else
# can plant.

# A private temporary folder (mktemp -d: mode 0700, a fresh name), removed when the script
# exits. Sets $anchor_tmp.
anchor_private_tmp() {
    anchor_tmp="$(mktemp -d "${TMPDIR:-/tmp}/marchmesh-anchor.XXXXXXXX")"
    # shellcheck disable=SC2064
    trap "rm -rf '$anchor_tmp'" EXIT
}

# anchor_reserve DIR PREFIX: prints DIR/PREFIX-<UTC stamp>[-N], the first such name whose
# .md, .json and -depth.json do not exist, reserved by creating its .md without clobbering
# (set -o noclobber), so two runs in the same second get two names.
anchor_reserve() {
    local dir="$1" prefix="$2" stamp base n=1
    stamp="$(date -u +%Y%m%dT%H%M%SZ)"
    base="$dir/$prefix-$stamp"
    while :; do
        if [ ! -e "$base.json" ] && [ ! -e "$base-depth.json" ] \
            && (set -o noclobber; : >"$base.md") 2>/dev/null; then
            printf '%s\n' "$base"
            return 0
        fi
        n=$((n + 1))
        base="$dir/$prefix-$stamp-$n"
        if [ "$n" -gt 1000 ]; then
            echo "cannot reserve an output name in $dir" >&2
            return 1
        fi
    done
}

# anchor_venv NAME: prints the Python environment's folder: $EMBREE_VENV if set, else
# ${XDG_CACHE_HOME:-$HOME/.cache}/marchmesh/NAME (never a shared folder such as /tmp). An
# existing folder must belong to the user and not be writable by others: a planted
# interpreter would run as the caller.
anchor_venv() {
    local venv cache
    if [ -n "${EMBREE_VENV:-}" ]; then
        venv="$EMBREE_VENV"
    else
        cache="${XDG_CACHE_HOME:-}"
        if [ -z "$cache" ]; then
            if [ -z "${HOME:-}" ]; then
                echo "HOME and XDG_CACHE_HOME are unset: set EMBREE_VENV to a private folder" >&2
                return 1
            fi
            cache="$HOME/.cache"
        fi
        venv="$cache/marchmesh/$1"
    fi
    if [ -e "$venv" ] || [ -L "$venv" ]; then
        if [ -L "$venv" ] || [ ! -d "$venv" ] || [ ! -O "$venv" ] \
            || [ -n "$(find "$venv" -maxdepth 0 -perm /022 2>/dev/null)" ]; then
            echo "$venv: not a folder of yours that only you can write: not used" >&2
            return 1
        fi
    fi
    printf '%s\n' "$venv"
}

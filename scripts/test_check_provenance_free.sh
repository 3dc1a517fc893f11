#!/usr/bin/env bash
# Tests scripts/check_provenance_free.sh on made-up files: what must be flagged is, what must
# not be is not, the allow-list accepts a justified exception, and bad usage exits 2.
#
#   scripts/test_check_provenance_free.sh
set -euo pipefail
check="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/check_provenance_free.sh"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cd "$tmp"
fail=0
expect() { # expect STATUS DESCRIPTION -- command...
  local want=$1 what=$2; shift 3
  local got=0
  "$@" >out.txt 2>err.txt || got=$?
  if [ "$got" != "$want" ]; then
    echo "FAIL: $what: exit $got, expected $want"; cat out.txt err.txt; fail=1
  fi
}

cat >flagged.md <<'MD'
measured on f710cab
full a1b2c3d4e5f60718293a4b5c6d7e8f9012345678 here
run 20261127T012132Z-default
load 1.7 at the start
(load average 0.4 -> 1.6)
load averages of 2
see issue 14
issues 15 and 16
fixed in #12.
MD
expect 1 "every kind is flagged" -- "$check" flagged.md
for line in 1 2 3 4 5 6 7 8 9; do
  grep -q "^flagged.md:$line: " out.txt || { echo "FAIL: line $line of flagged.md not flagged"; fail=1; }
done

cat >clean.md <<'MD'
a sha256 e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855 test vector
constants 0xdeadbeef12 and 0x1234abcd, 0xcbf2_9ce4_8422_2325
color: #abc123; fill="#a1b2c3"; stroke: #333
uuid 123e4567-e89b-12d3-a456-426614174000
1e10, 12345e6, x86_64, f32x8, deadbeef, decade, 1234567, 2654435761
the load average exceeded the core count; Load average at the start: {l:.2}
an issue with grazing rays; # Heading; #[derive(Debug)]; r#"raw"#
MD
expect 0 "non-hashes pass" -- "$check" clean.md

printf 'stamp 20231114T221320Z expected\n' >fixture.rs
printf '# comment\n\nfixture.rs | 20231114T221320Z | a test of the stamp formatter\n' >allow.txt
expect 0 "the allow-list accepts a justified exception" -- "$check" --allow allow.txt fixture.rs
printf 'fixture.rs | 20231114T221320Z\n' >bad-allow.txt
expect 2 "an allow-list line without a reason is refused" -- "$check" --allow bad-allow.txt fixture.rs
expect 2 "a missing path is an error" -- "$check" no-such-file.md
expect 2 "an unknown option is an error" -- "$check" --nope

[ "$fail" = 0 ] && echo "check_provenance_free.sh: all tests pass"
exit "$fail"

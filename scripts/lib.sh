# shellcheck shell=bash
# Shared shell helpers; source it (`. scripts/lib.sh`), do not run it.
#
# release_bin_dir: the directory cargo writes this workspace's release binaries to. Scripts ask
# cargo rather than assume ./target, so that CARGO_TARGET_DIR or build.target-dir in a cargo config
# are honoured. Reads `target_directory` from `cargo metadata` (no jq or Python needed: GNU sed, with
# JSON's \\ \" \/ escapes undone; normal paths need no more).
release_bin_dir() {
  local dir
  dir=$(cargo metadata --format-version 1 --no-deps \
    | sed -n 's/.*"target_directory":"\(\([^"\\]\|\\.\)*\)".*/\1/p' \
    | sed -e 's/\\\\/\x01/g' -e 's/\\"/"/g' -e 's/\\\//\//g' -e 's/\x01/\\/g') || return 1
  [ -n "$dir" ] || { echo "release_bin_dir: no target_directory in cargo metadata" >&2; return 1; }
  printf '%s/release\n' "$dir"
}

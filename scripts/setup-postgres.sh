#!/usr/bin/env bash
# Installs PostgreSQL and PostGIS from the distribution's packages, for the catalog's conformance
# tests (catalog/tests/support/postgres.rs starts a throwaway server from them on loopback) and for
# running a fleet catalog locally. Idempotent: does nothing when the server binaries and PostGIS
# are already there. Needs root (CI runs as root); PG_MAJOR picks the version (Debian 12: 15).
set -euo pipefail
major=${PG_MAJOR:-15}

have() {
  for bin in /usr/lib/postgresql/*/bin; do
    v=$(basename "$(dirname "$bin")")
    if [ -x "$bin/initdb" ] && [ -x "$bin/pg_ctl" ] && [ -f "/usr/share/postgresql/$v/extension/postgis.control" ]; then
      return 0
    fi
  done
  return 1
}

if have; then
  exit 0
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "setup-postgres.sh: PostgreSQL $major with PostGIS is missing; run this script as root" >&2
  exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -q
apt-get install -y -q "postgresql-$major" "postgresql-$major-postgis-3"
# Debian's package may create and start a cluster of its own on port 5432; the tests start
# their own in a temporary directory and never use it.
have || { echo "setup-postgres.sh: installed, but no server with PostGIS found" >&2; exit 1; }

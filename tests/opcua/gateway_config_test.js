"use strict";
// The gateway's settings and identities (gateway/opcua/src/config.js, identity.js): every bad
// value is refused with the file and key named, defaults that fall back say so, passwords are
// stored as scrypt hashes and checked in constant time, roles come from inspectd's policy file.
//   node --test tests/opcua/gateway_config_test.js
const test = require("node:test");
const assert = require("node:assert/strict");
const fs = require("fs");
const os = require("os");
const path = require("path");

const src = path.join(__dirname, "..", "..", "gateway", "opcua", "src");
const { loadConfig } = require(path.join(src, "config.js"));
const { Identities, hashPassword, verifyPassword, atLeast } = require(path.join(src, "identity.js"));

const dir = fs.mkdtempSync(path.join(os.tmpdir(), "opcua-config-"));
test.after(() => fs.rmSync(dir, { recursive: true, force: true }));
let n = 0;
function write(doc) {
  const f = path.join(dir, `c${n++}.json`);
  fs.writeFileSync(f, typeof doc === "string" ? doc : JSON.stringify(doc));
  return f;
}
const refused = (doc, message, env = {}) => {
  const f = write(doc);
  assert.throws(() => loadConfig(f, { env }), (e) => {
    assert.equal(e.message, message.replace("FILE", f));
    return true;
  });
};

test("defaults: inspectd from listen, paths under data_dir, each fallback said", () => {
  const c = loadConfig(write({ listen: "0.0.0.0:50077", data_dir: "/srv/insp", opcua: {} }), { env: {} });
  assert.equal(c.port, 4840);
  assert.equal(c.inspectd, "127.0.0.1:50077");
  assert.equal(c.pki_dir, "/srv/insp/opcua/pki");
  assert.equal(c.audit_log, "/srv/insp/audit/opcua-audit.jsonl");
  assert.deepEqual(c.security_modes, ["Sign", "SignAndEncrypt"]);
  assert.equal(c.allow_security_policy_none, false);
  assert.equal(c.allow_anonymous, false);
  assert.deepEqual(c.fallbacks, [
    "inspectd: 127.0.0.1:50077 (from listen '0.0.0.0:50077')",
    "certificate: none configured, a self-signed one is made in /srv/insp/opcua/pki",
    "inspectd connection: plaintext (no grpc_tls_ca)",
  ]);
});

test("inspectd's auth_token_file is the gateway's bearer token unless it names its own", () => {
  const token = write("t0k3n-of-sixteen-chars\n");
  const c = loadConfig(write({ auth_token_file: token, opcua: {} }), { env: {} });
  assert.equal(c.grpc_token_file, token);
  assert.ok(c.fallbacks.includes(`grpc_token_file: inspectd's auth_token_file ${token}`));
});

test("bad values are refused naming the file and the key", () => {
  const broken = write("{");
  // (the parser's own words differ between Node.js versions: only the prefix is ours)
  assert.throws(() => loadConfig(broken, { env: {} }), { message: new RegExp(`^${broken}: not valid JSON: `) });
  refused({ opcua: 4840 }, "FILE: 'opcua' must be a JSON object");
  refused({ opcua: { prot: 1 } }, "FILE: unknown key 'opcua.prot'; known keys: port, hostname, inspectd, grpc_tls_ca, grpc_tls_cert, grpc_tls_key, grpc_server_name, grpc_token_file, certificate, private_key, application_uri, pki_dir, trusted_client_certificates, security_modes, allow_security_policy_none, allow_anonymous, users_file, audit_log, station, log_level, max_part_id_bytes");
  refused({ opcua: { port: "4840" } }, "FILE: 'opcua.port' must be a number, is a string");
  refused({ opcua: { port: 70000 } }, "FILE: 'opcua.port' must be 0..65535");
  refused({ opcua: { security_modes: ["None"] } }, "FILE: 'opcua.security_modes' has 'None': only Sign, SignAndEncrypt (None: allow_security_policy_none)");
  refused({ opcua: { security_modes: [] } }, "FILE: 'opcua.security_modes' is empty and None is off: no endpoint");
  refused({ opcua: { certificate: "/x.crt" } }, "FILE: 'opcua.private_key' is needed with 'certificate'");
  refused({ opcua: { grpc_tls_cert: "/c", grpc_tls_key: "/k" } }, "FILE: 'opcua.grpc_tls_ca' is needed with grpc_tls_cert (mTLS is TLS first)");
  refused({ opcua: { users_file: "/no/such/users.json" } }, "FILE: 'opcua.users_file' '/no/such/users.json' cannot be read");
  refused({ opcua: { trusted_client_certificates: ["/no/such.pem"] } }, "FILE: 'opcua.trusted_client_certificates[0]' '/no/such.pem' cannot be read");
});

test("INSPECT_OPCUA_* variables override the block, strictly parsed", () => {
  const f = write({ opcua: { port: 4840 } });
  const c = loadConfig(f, { env: { INSPECT_OPCUA_PORT: "4841", INSPECT_OPCUA_SECURITY_MODES: '["SignAndEncrypt"]', INSPECT_OPCUA_ALLOW_ANONYMOUS: "false" } });
  assert.equal(c.port, 4841);
  assert.deepEqual(c.security_modes, ["SignAndEncrypt"]);
  refused({ opcua: {} }, "INSPECT_OPCUA_PORT 'x' must be an integer", { INSPECT_OPCUA_PORT: "x" });
  refused({ opcua: {} }, "environment variable INSPECT_OPCUA_PROT names no opcua setting", { INSPECT_OPCUA_PROT: "1" });
});

test("passwords: scrypt hashes, right one accepted, wrong one and unknown users refused", () => {
  const h = hashPassword("correct horse");
  assert.match(h, /^scrypt\$16384\$8\$1\$[A-Za-z0-9+/=]+\$[A-Za-z0-9+/=]+$/);
  assert.notEqual(h, hashPassword("correct horse")); // salted
  assert.equal(verifyPassword("correct horse", h), true);
  assert.equal(verifyPassword("correct horsE", h), false);
  const users = write({ users: [{ name: "station-7", password_hash: h }] });
  const policy = write({ identities: { "station-7": "operator", "qa-lead": "engineer" }, default_role: "viewer" });
  const ids = new Identities({ usersFile: users, policyFile: policy, allowAnonymous: false });
  assert.equal(ids.checkPassword("station-7", "correct horse"), true);
  assert.equal(ids.checkPassword("station-7", "wrong"), false);
  assert.equal(ids.checkPassword("nobody", "correct horse"), false);
  assert.equal(ids.roleOf("qa-lead"), "engineer");
  assert.equal(ids.roleOf("someone-else"), "viewer"); // default_role
  assert.deepEqual(ids.callerOf({ userIdentityToken: { userName: "station-7" } }), { name: "station-7", role: "operator" });
  assert.deepEqual(ids.callerOf({}), { name: "anonymous", role: null });
  assert.equal(atLeast("operator", "viewer"), true);
  assert.equal(atLeast("operator", "engineer"), false);
  assert.equal(atLeast(null, "viewer"), false);
});

test("a users file or policy with a bad entry is refused naming it", () => {
  const users = write({ users: [{ name: "x", password_hash: "plain-text" }] });
  assert.throws(() => new Identities({ usersFile: users }), { message: `users file '${users}': users[0].password_hash must be scrypt$N$r$p$salt$hash (inspect-opcua-gateway hash-password)` });
  const policy = write({ identities: { x: "superuser" } });
  assert.throws(() => new Identities({ policyFile: policy }), { message: `policy file '${policy}': identities.x has unknown role 'superuser'` });
});

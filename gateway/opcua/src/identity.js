"use strict";
// Who an OPC UA session is and what it may do: user names with scrypt-hashed passwords from the
// users file, X.509 user certificates by their CN (as inspectd names mTLS callers), and the role
// of each identity from inspectd's own policy file (docs/security.md), so a person has the same
// role on OPC UA as on gRPC.
const crypto = require("crypto");
const fs = require("fs");

const ROLES = ["viewer", "operator", "engineer", "admin"];
const SCRYPT = { N: 16384, r: 8, p: 1, keylen: 32 };

function hashPassword(password, salt = crypto.randomBytes(16)) {
  const hash = crypto.scryptSync(password, salt, SCRYPT.keylen, { N: SCRYPT.N, r: SCRYPT.r, p: SCRYPT.p });
  return `scrypt$${SCRYPT.N}$${SCRYPT.r}$${SCRYPT.p}$${salt.toString("base64")}$${hash.toString("base64")}`;
}

function verifyPassword(password, encoded) {
  const parts = String(encoded).split("$");
  if (parts.length !== 6 || parts[0] !== "scrypt") return false;
  const [N, r, p] = parts.slice(1, 4).map(Number);
  const salt = Buffer.from(parts[4], "base64");
  const want = Buffer.from(parts[5], "base64");
  const got = crypto.scryptSync(String(password), salt, want.length, { N, r, p, maxmem: 256 * N * r });
  return crypto.timingSafeEqual(got, want);
}

function loadUsers(file) {
  if (!file) return new Map();
  let doc;
  try {
    doc = JSON.parse(fs.readFileSync(file, "utf8"));
  } catch (e) {
    throw new Error(`users file '${file}': ${e.message}`);
  }
  if (!doc || !Array.isArray(doc.users)) throw new Error(`users file '${file}': needs {"users": [...]}`);
  const users = new Map();
  doc.users.forEach((u, i) => {
    if (!u || typeof u.name !== "string" || !u.name) throw new Error(`users file '${file}': users[${i}].name is missing`);
    if (typeof u.password_hash !== "string" || !u.password_hash.startsWith("scrypt$") || u.password_hash.split("$").length !== 6) {
      throw new Error(`users file '${file}': users[${i}].password_hash must be scrypt$N$r$p$salt$hash (inspect-opcua-gateway hash-password)`);
    }
    users.set(u.name, u.password_hash);
  });
  return users;
}

// inspectd's policy file: {"identities": {"name": "role"}, "default_role": "viewer"}.
function loadPolicy(file) {
  if (!file) return null;
  let doc;
  try {
    doc = JSON.parse(fs.readFileSync(file, "utf8"));
  } catch (e) {
    throw new Error(`policy file '${file}': ${e.message}`);
  }
  const identities = (doc && doc.identities) || {};
  for (const [name, role] of Object.entries(identities)) {
    if (!ROLES.includes(role)) throw new Error(`policy file '${file}': identities.${name} has unknown role '${role}'`);
  }
  if (doc.default_role !== undefined && !ROLES.includes(doc.default_role)) {
    throw new Error(`policy file '${file}': default_role '${doc.default_role}' is not a role`);
  }
  return { identities, default_role: doc.default_role || null };
}

class Identities {
  constructor({ usersFile, policyFile, allowAnonymous }) {
    this.users = loadUsers(usersFile);
    this.policy = loadPolicy(policyFile);
    this.allowAnonymous = allowAnonymous;
  }

  // The role of an authenticated identity, or null: without a policy file every identity that
  // authenticated is an operator (inspectd without a policy gives every caller every role; a
  // plant gateway should not, so admin work needs a policy).
  roleOf(name) {
    if (!this.policy) return "operator";
    return this.policy.identities[name] || this.policy.default_role || null;
  }

  checkPassword(name, password) {
    const hash = this.users.get(name);
    if (!hash) {
      verifyPassword(password, hashPassword("x")); // same work for unknown names: no timing oracle
      return false;
    }
    return verifyPassword(password, hash);
  }

  // The caller of a method, from its session's identity token.
  callerOf(session) {
    const token = session && session.userIdentityToken;
    if (!token) return { name: "anonymous", role: this.allowAnonymous ? "viewer" : null };
    if (token.userName !== undefined) return { name: token.userName, role: this.roleOf(token.userName) };
    if (token.certificateData) {
      const name = certificateName(token.certificateData);
      return { name, role: this.roleOf(name) };
    }
    return { name: "anonymous", role: this.allowAnonymous ? "viewer" : null };
  }
}

function certificateName(der) {
  try {
    const cert = new crypto.X509Certificate(der);
    const cn = /(?:^|\n)CN=([^\n]*)/.exec(cert.subject);
    return cn ? cn[1] : cert.subject;
  } catch {
    return "(unreadable certificate)";
  }
}

function atLeast(role, needed) {
  return role !== null && ROLES.indexOf(role) >= ROLES.indexOf(needed);
}

module.exports = { Identities, hashPassword, verifyPassword, certificateName, atLeast, ROLES };

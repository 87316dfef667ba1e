"use strict";
// The gateway's audit trail: one JSON line per OPC UA method call (allowed or not), rejected
// session activation and refused secure channel, with the fields of inspectd's own audit log
// (server/security/audit_log.h): time, identity, role, peer, method, target, code, message. Never
// passwords or certificates. Written synchronously, so a line is on disk before the call answers.
const fs = require("fs");
const path = require("path");
const pino = require("pino");

const MAX_TEXT = 256; // as inspectd: free text is cut

function cut(s) {
  s = String(s === undefined || s === null ? "" : s);
  return Buffer.byteLength(s) <= MAX_TEXT ? s : Buffer.from(s).subarray(0, MAX_TEXT).toString().replace(/\uFFFD+$/, "");
}

class AuditLog {
  constructor(file) {
    fs.mkdirSync(path.dirname(file), { recursive: true, mode: 0o750 });
    this.file = file;
    const dest = pino.destination({ dest: file, sync: true, mkdir: true });
    // `source` first: the lines can be merged with inspectd's own audit log and still say which
    // front door the call came through.
    this.logger = pino(
      {
        base: null,
        timestamp: () => `,"time":"${new Date().toISOString()}"`,
        formatters: { level: () => ({ source: "opcua" }) },
      },
      dest,
    );
  }

  // code: the OPC UA StatusCode name ("Good", "BadNotFound", ...).
  record({ identity, role, peer, method, target, code, message }) {
    this.logger.info({
      identity: cut(identity || "anonymous"),
      role: role || "",
      peer: cut(peer || ""),
      method,
      target: cut(target || ""),
      code,
      message: cut(message || ""),
    });
  }
}

module.exports = { AuditLog };

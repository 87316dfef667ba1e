#!/usr/bin/env node
"use strict";
// inspect-opcua-gateway: an OPC UA server (OPC 40100-1 Machine Vision) for one rig, speaking gRPC
// to its inspectd. Settings: the `opcua` block of inspectd's config file (gateway/opcua/README.md).
//   inspect-opcua-gateway [--config FILE]      (default: $INSPECTD_CONFIG)
//   inspect-opcua-gateway --check-config [--config FILE]   (prints the effective settings; files
//                                              named in them are not opened)
//   inspect-opcua-gateway hash-password        (reads a password on stdin, prints its scrypt hash)
const fs = require("fs");
const path = require("path");
const { loadConfig, ConfigError } = require("./config");
const { Identities, hashPassword, certificateName } = require("./identity");

const CONTENT_NODESET = path.join(__dirname, "..", "nodesets", "Inspection.ResultContent.NodeSet2.xml");

function parseArgs(argv) {
  const a = { config: process.env.INSPECTD_CONFIG || "", command: "serve" };
  for (let i = 0; i < argv.length; i++) {
    if (argv[i] === "--config") a.config = argv[++i] || "";
    else if (argv[i] === "hash-password") a.command = "hash-password";
    else if (argv[i] === "--check-config") a.command = "check-config";
    else if (argv[i] === "--help" || argv[i] === "-h") a.command = "help";
    else throw new ConfigError(`unknown argument '${argv[i]}' (inspect-opcua-gateway [--config FILE] | hash-password)`);
  }
  return a;
}

async function main() {
  let args;
  try {
    args = parseArgs(process.argv.slice(2));
  } catch (e) {
    process.stderr.write(`inspect-opcua-gateway: ${e.message}\n`);
    return 2;
  }
  if (args.command === "help") {
    process.stdout.write("inspect-opcua-gateway [--config FILE] [--check-config] | hash-password  (gateway/opcua/README.md)\n");
    return 0;
  }
  if (args.command === "hash-password") {
    const pw = fs.readFileSync(0, "utf8").replace(/\r?\n$/, "");
    if (!pw) {
      process.stderr.write("inspect-opcua-gateway hash-password: empty password on stdin\n");
      return 2;
    }
    process.stdout.write(hashPassword(pw) + "\n");
    return 0;
  }
  if (!args.config) {
    process.stderr.write("inspect-opcua-gateway: no config file (--config FILE or INSPECTD_CONFIG)\n");
    return 2;
  }
  if (args.command === "check-config") {
    try {
      const c = loadConfig(args.config, { checkFiles: false });
      process.stdout.write(JSON.stringify(c, null, 2) + "\n");
      return 0;
    } catch (e) {
      process.stderr.write(`inspect-opcua-gateway: ${e.message}\n`);
      return 2;
    }
  }
  let config, identities;
  try {
    config = loadConfig(args.config);
    identities = new Identities({ usersFile: config.users_file, policyFile: config.policy, allowAnonymous: config.allow_anonymous });
  } catch (e) {
    process.stderr.write(`inspect-opcua-gateway: ${e.message}\n`);
    return 2;
  }
  // The OPC UA stack only for serving: --check-config and hash-password stay quick.
  const pino = require("pino");
  const { OPCUAServer, OPCUACertificateManager, SecurityPolicy, MessageSecurityMode, nodesets } = require("node-opcua");
  const { AuditLog } = require("./audit");
  const { InspectdClient } = require("./inspectd_client");
  const { VisionSystem } = require("./vision_system");
  const SECURE_POLICIES = [SecurityPolicy.Basic256Sha256, SecurityPolicy.Aes128_Sha256_RsaOaep, SecurityPolicy.Aes256_Sha256_RsaPss];
  const log = pino({ level: config.log_level, base: { service: "inspect-opcua-gateway" } }, pino.destination(2));
  for (const f of config.fallbacks) log.info(`default: ${f}`);
  const audit = new AuditLog(config.audit_log);

  // Trust store: node-opcua's PKI folder layout (trusted/certs, rejected/certs, ...); the
  // configured client certificates are put into trusted/ at every start.
  const serverCertificateManager = new OPCUACertificateManager({ rootFolder: config.pki_dir, automaticallyAcceptUnknownCertificate: false });
  await serverCertificateManager.initialize();
  for (const f of config.trusted_client_certificates) {
    const pem = fs.readFileSync(f);
    await serverCertificateManager.trustCertificate(toDer(pem, f));
  }
  // A refused application certificate ends the secure channel before any session exists: audit
  // it here, where node-opcua decides (the client reads Bad_SecurityChecksFailed; the certificate
  // lands in <pki_dir>/rejected/certs, from where an admin may move it to trusted/certs).
  const checkCertificate = serverCertificateManager.checkCertificate.bind(serverCertificateManager);
  serverCertificateManager.checkCertificate = async (certificate, ...rest) => {
    const statusCode = await checkCertificate(certificate, ...rest);
    if (statusCode.isNotGood()) {
      const name = certificateName(certificate);
      audit.record({ identity: name, method: "OpenSecureChannel", code: "BadSecurityChecksFailed", message: `application certificate refused: ${statusCode.name}` });
      log.warn({ identity: name }, `secure channel refused: application certificate ${statusCode.name}`);
    }
    return statusCode;
  };
  const userCertificateManager = new OPCUACertificateManager({
    rootFolder: path.join(config.pki_dir, "users"),
    automaticallyAcceptUnknownCertificate: false,
  });
  await userCertificateManager.initialize();
  for (const f of config.trusted_client_certificates) await userCertificateManager.trustCertificate(toDer(fs.readFileSync(f), f));

  const securityModes = config.security_modes.map((m) => MessageSecurityMode[m]);
  const securityPolicies = [...SECURE_POLICIES];
  if (config.allow_security_policy_none) {
    securityModes.push(MessageSecurityMode.None);
    securityPolicies.push(SecurityPolicy.None);
    log.warn("security policy None is on: unsigned, unencrypted OPC UA is accepted");
  }

  const userManager = {
    isValidUser(userName, password) {
      const ok = identities.checkPassword(userName, password);
      const role = ok ? identities.roleOf(userName) : null;
      const peer = this && this.channel ? `${this.channel.remoteAddress}:${this.channel.remotePort}` : "";
      if (!ok || !role) {
        const message = !ok ? "wrong user name or password" : `'${userName}' has no role in the policy`;
        audit.record({ identity: userName, role: role || "", peer, method: "ActivateSession", code: "BadUserAccessDenied", message });
        log.warn({ identity: userName, peer }, `session refused: ${message}`);
        return false;
      }
      audit.record({ identity: userName, role, peer, method: "ActivateSession", code: "Good", message: "user name" });
      return true;
    },
  };

  const server = new OPCUAServer({
    port: config.port,
    hostname: config.hostname || undefined,
    nodeset_filename: [nodesets.standard, nodesets.di, nodesets.machineVision, CONTENT_NODESET],
    serverInfo: {
      applicationUri: config.application_uri,
      productUri: "urn:inspection:inspect-opcua-gateway",
      applicationName: { text: "inspectd OPC UA gateway (OPC 40100-1)" },
    },
    buildInfo: { productName: "inspect-opcua-gateway", softwareVersion: require("../package.json").version },
    certificateFile: config.certificate || undefined,
    privateKeyFile: config.private_key || undefined,
    serverCertificateManager,
    userCertificateManager,
    securityModes,
    securityPolicies,
    allowAnonymous: config.allow_anonymous,
    userManager,
  });
  server.on("openSecureChannelFailure", (socketData, channelData) => {
    const peer = socketData ? `${socketData.remoteAddress}:${socketData.remotePort}` : "";
    const reason = (socketData && socketData.reason) || "";
    audit.record({ identity: "", peer, method: "OpenSecureChannel", code: codeFrom(reason), message: reason });
    log.warn({ peer }, `secure channel refused: ${reason}`);
  });
  server.on("session_activated", (session) => {
    const token = session.userIdentityToken;
    if (token && token.certificateData) {
      const who = identities.callerOf(session);
      audit.record({ identity: who.name, role: who.role || "", peer: "", method: "ActivateSession", code: "Good", message: "X.509 user certificate" });
    }
  });

  await server.initialize();
  const inspectd = new InspectdClient(config);
  const vision = new VisionSystem({ server, inspectd, identities, audit, config, log });
  vision.build();
  await server.start();
  const url = server.getEndpointUrl();
  const modes = server.endpoints[0].endpointDescriptions().filter((e) => !e.restricted).map((e) => `${MessageSecurityMode[e.securityMode]}/${e.securityPolicyUri.split("#")[1]}`);
  // The one line a supervisor or test waits for: the bound endpoint and the endpoints offered.
  process.stdout.write(`inspect-opcua-gateway listening on ${url} (port ${server.endpoints[0].port}) endpoints ${[...new Set(modes)].join(" ")}; inspectd ${config.inspectd}; audit ${config.audit_log}\n`);
  vision.start();

  let stopping = false;
  const stop = async (sig) => {
    if (stopping) return;
    stopping = true;
    log.info(`${sig}: shutting down`);
    vision.stop();
    await server.shutdown(1000);
    inspectd.close();
    process.exit(0);
  };
  process.on("SIGTERM", () => stop("SIGTERM"));
  process.on("SIGINT", () => stop("SIGINT"));
  return null;
}

function toDer(buf, file) {
  const text = buf.toString("latin1");
  const m = /-----BEGIN CERTIFICATE-----([\s\S]*?)-----END CERTIFICATE-----/.exec(text);
  if (!m) {
    if (buf[0] === 0x30) return buf;
    throw new ConfigError(`'${file}' is neither a PEM nor a DER certificate`);
  }
  return Buffer.from(m[1].replace(/\s+/g, ""), "base64");
}

function codeFrom(reason) {
  const m = /Bad[A-Za-z]+/.exec(reason || "");
  return m ? m[0] : "BadSecurityChecksFailed";
}

main().then(
  (code) => {
    if (code !== null) process.exit(code);
  },
  (e) => {
    process.stderr.write(`inspect-opcua-gateway: ${e instanceof ConfigError ? e.message : e.stack || e.message}\n`);
    process.exit(1);
  },
);

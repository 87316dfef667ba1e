"use strict";
// The VisionStateMachine of a rig in Error (an independent node-opcua client; the gateway in front
// of a real inspectd whose configured devices are absent, started --degraded): the state is Error
// with the device error in the log, SelectModeAutomatic and StartSingleJob are Bad_InvalidState,
// Reset by an operator is Bad_UserAccessDenied (it would run ResetRig, an admin's), Reset by an
// admin runs ResetRig, which fails while the devices are still absent: the state stays Error.
//   node opcua_rig_error_test.js ENDPOINT_URL PKI_DIR AUDIT_LOG
const fs = require("fs");
const path = require("path");
const assert = require("assert/strict");
const { createRequire } = require("module");

const gatewayRequire = createRequire(path.join(__dirname, "..", "..", "gateway", "opcua", "package.json"));
const { OPCUAClient, MessageSecurityMode, SecurityPolicy, UserTokenType, AttributeIds, DataType, makeBrowsePath, coerceNodeId } =
  gatewayRequire("node-opcua");

const [endpointUrl, pki, auditLog] = process.argv.slice(2);
const MV = "http://opcfoundation.org/UA/MachineVision";
let passes = 0;
let failures = 0;
const say = (line) => process.stdout.write(line + "\n");
async function check(name, fn) {
  try {
    await fn();
    passes++;
    say(`ok   ${name}`);
  } catch (e) {
    failures++;
    say(`FAIL ${name}: ${e.stack || e.message}`);
  }
}

async function session(userName, password) {
  const c = OPCUAClient.create({
    applicationUri: "urn:inspection:test:mes-client",
    securityMode: MessageSecurityMode.SignAndEncrypt,
    securityPolicy: SecurityPolicy.Basic256Sha256,
    certificateFile: path.join(pki, "mes-client.crt"),
    privateKeyFile: path.join(pki, "mes-client.key"),
    endpointMustExist: false,
    connectionStrategy: { maxRetry: 0 },
  });
  await c.connect(endpointUrl);
  const s = await c.createSession({ type: UserTokenType.UserName, userName, password });
  return { c, s };
}

async function main() {
  const op = await session("station-7", "s3cret-operator");
  const admin = await session("it-admin", "s3cret-admin");
  const ns = (await op.s.readNamespaceArray()).indexOf(MV);
  const own = 1;
  const at = async (s, ...names) => {
    const r = await s.translateBrowsePath(makeBrowsePath("ns=0;i=85", "/" + [`${own}:InspectionRig`, ...names].join("/")));
    assert.equal(r.statusCode.name, "Good", names.join("/"));
    return r.targets[0].targetId;
  };
  const sm = await at(op.s, `${ns}:VisionStateMachine`);
  const auto = await at(op.s, `${ns}:VisionStateMachine`, `${ns}:AutomaticModeStateMachine`);
  const state = async () =>
    (await op.s.read({ nodeId: await at(op.s, `${ns}:VisionStateMachine`, "CurrentState"), attributeId: AttributeIds.Value })).value.value.text;
  const cause = [{ dataType: DataType.Int32, value: 0 }, { dataType: DataType.String, value: "test" }];
  const call = async (s, obj, name, inputArguments) => {
    const r = await s.call({ objectId: obj, methodId: await at(s, `${ns}:VisionStateMachine`, ...(obj === auto ? [`${ns}:AutomaticModeStateMachine`] : []), `${ns}:${name}`), inputArguments });
    say(`  call ${name} -> ${r.statusCode.name}`);
    return r.statusCode.name;
  };

  await check("a rig in Error is VisionStateMachine Error", async () => {
    const s = await state();
    say(`  CurrentState ${s}`);
    assert.equal(s, "Error");
  });
  await check("SelectModeAutomatic and StartSingleJob in Error: Bad_InvalidState", async () => {
    assert.equal(await call(op.s, sm, "SelectModeAutomatic", []), "BadInvalidState");
    const ext = (i, f) => op.s.constructExtensionObject(coerceNodeId(`ns=${ns};i=${i}`), f);
    const args = [
      { dataType: DataType.ExtensionObject, value: await ext(3015, { id: "" }) },
      { dataType: DataType.ExtensionObject, value: await ext(3004, { id: "P-1" }) },
      { dataType: DataType.ExtensionObject, value: await ext(3002, { id: "tilt-5deg" }) },
      { dataType: DataType.ExtensionObject, value: await ext(3003, { id: "" }) },
      { dataType: DataType.Variant, arrayType: 1, value: [] },
    ];
    assert.equal(await call(op.s, auto, "StartSingleJob", args), "BadInvalidState");
  });
  await check("Reset of a rig in Error needs admin: Bad_UserAccessDenied for an operator", async () => {
    assert.equal(await call(op.s, sm, "Reset", cause), "BadUserAccessDenied");
    assert.equal(await state(), "Error");
  });
  await check("Reset by an admin runs ResetRig; the devices are still absent: refused, still Error", async () => {
    const code = await call(admin.s, sm, "Reset", cause);
    assert.ok(["BadCommunicationError", "BadInvalidState"].includes(code), code);
    assert.equal(await state(), "Error");
  });
  await check("the refusals are audited", async () => {
    const lines = fs.readFileSync(auditLog, "utf8").split("\n").filter(Boolean).map((l) => JSON.parse(l));
    assert.ok(lines.some((l) => l.method === "Reset" && l.identity === "station-7" && l.code === "BadUserAccessDenied"));
    const adminReset = lines.find((l) => l.method === "Reset" && l.identity === "it-admin");
    assert.ok(adminReset && adminReset.code !== "Good", JSON.stringify(adminReset));
    say(`  ${JSON.stringify(adminReset)}`);
  });
  for (const x of [op, admin]) {
    await x.s.close();
    await x.c.disconnect();
  }
  say(`${passes} passed, ${failures} failed`);
  process.exit(failures ? 1 : 0);
}
main().catch((e) => {
  say(`FAIL: ${e.stack || e.message}`);
  say(`${passes} passed, ${failures + 1} failed`);
  process.exit(1);
});

"use strict";
// An independent OPC UA client (node-opcua's OPCUAClient; no gateway code is used) against the
// gateway in front of a real inspectd on the simulated rig. opcua_gateway_test.sh starts both.
// It browses the address space and checks the OPC 40100-1 type hierarchy, drives the
// VisionStateMachine, runs one inspection (PrepareRecipe, StartSingleJob with a part id), receives
// the ResultReadyEvent and checks its verdict and measurements against the same job's result
// fetched over gRPC, and checks each refused case's status code and its audit line.
//   node opcua_client_test.js ENDPOINT_URL PKI_DIR GRPC_ADDRESS AUDIT_LOG RECIPE_JSON
const fs = require("fs");
const path = require("path");
const assert = require("assert/strict");
const { createRequire } = require("module");

const gatewayRequire = createRequire(path.join(__dirname, "..", "..", "gateway", "opcua", "package.json"));
const {
  OPCUAClient,
  MessageSecurityMode,
  SecurityPolicy,
  UserTokenType,
  AttributeIds,
  NodeClass,
  StatusCodes,
  DataType,
  ClientSubscription,
  ClientMonitoredItem,
  TimestampsToReturn,
  makeBrowsePath,
  BrowseDirection,
  CreateSessionRequest,
  ApplicationType,
  EventFilter,
  coerceNodeId,
} = gatewayRequire("node-opcua");
const grpc = gatewayRequire("@grpc/grpc-js");
const protoLoader = gatewayRequire("@grpc/proto-loader");

const [endpointUrl, pki, grpcAddress, auditLog, recipeFile] = process.argv.slice(2);
const MV = "http://opcfoundation.org/UA/MachineVision";
const PART = "P-OPCUA-0001";
let failures = 0;
let passes = 0;

function transcript(line) {
  process.stdout.write(line + "\n");
}
async function check(name, fn) {
  try {
    await fn();
    passes++;
    transcript(`ok   ${name}`);
  } catch (e) {
    failures++;
    transcript(`FAIL ${name}: ${e.stack || e.message}`);
  }
}
function withDeadline(promise, ms, what) {
  let t;
  return Promise.race([
    promise,
    new Promise((_, reject) => (t = setTimeout(() => reject(new Error(`timed out after ${ms} ms waiting for ${what}`)), ms))),
  ]).finally(() => clearTimeout(t));
}

// --- gRPC (the same job's result, as inspectd stores it) ----------------------------------------
const root = path.join(__dirname, "..", "..", "proto");
const pkg = grpc.loadPackageDefinition(
  protoLoader.loadSync(path.join(root, "inspection", "v1", "inspection.proto"), {
    includeDirs: [root],
    keepCase: true,
    longs: String,
    enums: String,
    defaults: true,
  }),
).inspection.v1;
const grpcStub = new pkg.InspectionService(
  grpcAddress,
  grpc.credentials.createSsl(
    fs.readFileSync(path.join(pki, "grpc-ca.crt")),
    fs.readFileSync(path.join(pki, "mes-grpc.key")),
    fs.readFileSync(path.join(pki, "mes-grpc.crt")),
  ),
  { "grpc.ssl_target_name_override": "localhost" },
);
const rpc = (method, req) =>
  new Promise((resolve, reject) => grpcStub[method](req, { deadline: Date.now() + 20000 }, (e, r) => (e ? reject(e) : resolve(r))));

// --- OPC UA -------------------------------------------------------------------------------------
function client(cert, mode = MessageSecurityMode.SignAndEncrypt, policy = SecurityPolicy.Basic256Sha256) {
  return OPCUAClient.create({
    applicationName: "inspection gateway test client",
    applicationUri: `urn:inspection:test:${cert}`,
    securityMode: mode,
    securityPolicy: policy,
    certificateFile: path.join(pki, `${cert}.crt`),
    privateKeyFile: path.join(pki, `${cert}.key`),
    endpointMustExist: false,
    connectionStrategy: { maxRetry: 0, initialDelay: 50, maxDelay: 100 },
    requestedSessionTimeout: 60000,
    clientCertificateManager: undefined,
  });
}
const USER = { type: UserTokenType.UserName, userName: "station-7", password: "s3cret-operator" };

async function statusOf(promise) {
  try {
    await promise;
    return "Good";
  } catch (e) {
    const m = /Bad[A-Za-z]+/.exec(`${e.message} ${e.response ? e.response.responseHeader.serviceResult.name : ""}`);
    return m ? m[0] : `error without a status code: ${e.message}`;
  }
}

function auditLines() {
  return fs
    .readFileSync(auditLog, "utf8")
    .split("\n")
    .filter(Boolean)
    .map((l) => JSON.parse(l));
}

async function main() {
  transcript(`endpoint ${endpointUrl}; inspectd ${grpcAddress}`);

  // Security: the None policy, an untrusted application certificate, a wrong password.
  await check("SecurityPolicy None is refused by default", async () => {
    const c = client("mes-client", MessageSecurityMode.None, SecurityPolicy.None);
    await c.connect(endpointUrl).catch(() => {});
    const endpoints = await c.getEndpoints().catch(() => []);
    const offered = endpoints.map((e) => `${MessageSecurityMode[e.securityMode]}/${e.securityPolicyUri.split("#")[1]}`);
    transcript(`  endpoints offered: ${offered.join(" ")}`);
    assert.ok(!offered.includes("None/None"), "None/None must not be offered");
    // The high-level createSession refuses locally (no such endpoint); send the request itself so
    // the server's own answer is what is checked.
    const request = new CreateSessionRequest({
      clientDescription: { applicationUri: "urn:inspection:test:mes-client", applicationType: ApplicationType.Client },
      endpointUrl,
      sessionName: "none-policy-probe",
      clientNonce: Buffer.alloc(32),
      requestedSessionTimeout: 10000,
    });
    const code = await statusOf(new Promise((resolve, reject) => c.performMessageTransaction(request, (e, r) => (e ? reject(e) : resolve(r)))));
    transcript(`  CreateSession over a None channel -> ${code}`);
    assert.equal(code, "BadSecurityModeRejected");
    await c.disconnect();
  });
  await check("an untrusted application certificate gets Bad_SecurityChecksFailed", async () => {
    const c = client("rogue-client");
    const code = await statusOf(c.connect(endpointUrl));
    transcript(`  OpenSecureChannel (SignAndEncrypt, rogue-client) -> ${code}`);
    assert.equal(code, "BadSecurityChecksFailed");
    await c.disconnect();
  });
  await check("a wrong password gets Bad_UserAccessDenied", async () => {
    const c = client("mes-client");
    await c.connect(endpointUrl);
    const code = await statusOf(c.createSession({ ...USER, password: "wrong" }));
    transcript(`  ActivateSession station-7 with a wrong password -> ${code}`);
    assert.ok(["BadUserAccessDenied", "BadIdentityTokenRejected"].includes(code), code);
    await c.disconnect();
  });

  const c = client("mes-client");
  await c.connect(endpointUrl);
  const session = await c.createSession(USER);
  transcript(`session: SignAndEncrypt/Basic256Sha256, user station-7`);
  const ns = (await session.readNamespaceArray()).indexOf(MV);
  assert.ok(ns > 0, "MachineVision namespace");
  const qn = (name) => `${ns}:${name}`;
  const child = async (nodeId, ...names) => {
    const r = await session.translateBrowsePath(makeBrowsePath(nodeId, names.map((n) => "/" + n).join("")));
    assert.equal(r.statusCode.name, "Good", `browse path ${names.join("/")}`);
    return r.targets[0].targetId;
  };
  const typeDefinitionName = async (nodeId) => {
    const r = await session.browse({ nodeId, referenceTypeId: "HasTypeDefinition", browseDirection: BrowseDirection.Forward, resultMask: 0x3f });
    return r.references[0].browseName.toString();
  };

  let rig;
  await check("browse: a VisionSystemType instance with its state machine, recipe and result management", async () => {
    const objects = await session.browse({ nodeId: "ns=0;i=85", resultMask: 0x3f });
    const found = [];
    for (const ref of objects.references) {
      if (ref.nodeClass === NodeClass.Object && (await typeDefinitionName(ref.nodeId)) === qn("VisionSystemType")) found.push(ref);
    }
    assert.equal(found.length, 1, "one VisionSystemType instance under Objects");
    rig = found[0].nodeId;
    transcript(`  Objects/${found[0].browseName.toString()} : ${qn("VisionSystemType")}`);
    const tree = async (nodeId, depth, prefix) => {
      const r = await session.browse({ nodeId, referenceTypeId: "HierarchicalReferences", includeSubtypes: true, browseDirection: BrowseDirection.Forward, nodeClassMask: 1 | 4, resultMask: 0x3f });
      for (const ref of r.references.sort((a, b) => a.browseName.name.localeCompare(b.browseName.name))) {
        const isMethod = ref.nodeClass === NodeClass.Method;
        transcript(`  ${prefix}${ref.browseName.toString()}${isMethod ? "()" : " : " + (await typeDefinitionName(ref.nodeId))}`);
        if (!isMethod && depth > 0) await tree(ref.nodeId, depth - 1, prefix + "  ");
      }
    };
    await tree(rig, 2, "  ");
    const sm = await child(rig, qn("VisionStateMachine"));
    assert.equal(await typeDefinitionName(sm), qn("VisionStateMachineType"));
    const auto = await child(rig, qn("VisionStateMachine"), qn("AutomaticModeStateMachine"));
    assert.equal(await typeDefinitionName(auto), qn("VisionAutomaticModeStateMachineType"));
    assert.equal(await typeDefinitionName(await child(rig, qn("RecipeManagement"))), qn("RecipeManagementType"));
    assert.equal(await typeDefinitionName(await child(rig, qn("ResultManagement"))), qn("ResultManagementType"));
    const smType = (await session.browse({ nodeId: sm, referenceTypeId: "HasTypeDefinition" })).references[0].nodeId;
    const comps = (await session.browse({ nodeId: smType, referenceTypeId: "HasComponent", resultMask: 0x3f })).references.map((r) => r.browseName.toString());
    for (const s of ["Preoperational", "Halted", "Error", "Operational"]) assert.ok(comps.includes(qn(s)), `VisionStateMachineType has no state ${s}`);
    const autoType = (await session.browse({ nodeId: auto, referenceTypeId: "HasTypeDefinition" })).references[0].nodeId;
    const autoComps = (await session.browse({ nodeId: autoType, referenceTypeId: "HasComponent", resultMask: 0x3f })).references.map((r) => r.browseName.toString());
    for (const s of ["Initialized", "Ready", "SingleExecution"]) assert.ok(autoComps.includes(qn(s)), `no automatic-mode state ${s}`);
    transcript(`  VisionStateMachineType states: ${comps.filter((n) => /Preoperational$|Halted$|Error$|Operational$/.test(n)).join(" ")}; automatic mode: ${autoComps.filter((n) => /(Initialized|Ready|SingleExecution|ContinuousExecution)$/.test(n)).join(" ")}`);
  });
  await check("types: VisionStateMachineType is a FiniteStateMachineType, ResultReadyEventType a BaseEventType", async () => {
    const superOf = async (nodeId) => {
      const r = await session.browse({ nodeId, referenceTypeId: "HasSubtype", browseDirection: BrowseDirection.Inverse, resultMask: 0x3f });
      return r.references[0];
    };
    const smType = await session.browse({ nodeId: (await child(rig, qn("VisionStateMachine"))), referenceTypeId: "HasTypeDefinition" });
    const chain = [];
    let n = smType.references[0].nodeId;
    for (let i = 0; i < 6 && n; i++) {
      const s = await superOf(n);
      if (!s) break;
      chain.push(s.browseName.toString());
      n = s.nodeId;
    }
    transcript(`  VisionStateMachineType -> ${chain.join(" -> ")}`);
    assert.ok(chain.includes("FiniteStateMachineType"));
    const evChain = [];
    n = coerceNodeId(`ns=${ns};i=1024`);
    const evName = (await session.read({ nodeId: n, attributeId: AttributeIds.BrowseName })).value.value.toString();
    assert.equal(evName, qn("ResultReadyEventType"));
    for (let i = 0; i < 6 && n; i++) {
      const s = await superOf(n);
      if (!s) break;
      evChain.push(s.browseName.toString());
      n = s.nodeId;
    }
    transcript(`  ResultReadyEventType -> ${evChain.join(" -> ")}`);
    assert.equal(evChain[0], "BaseEventType");
  });

  const smNode = await child(rig, qn("VisionStateMachine"));
  const autoNode = await child(rig, qn("VisionStateMachine"), qn("AutomaticModeStateMachine"));
  const recipeMgmt = await child(rig, qn("RecipeManagement"));
  const resultMgmt = await child(rig, qn("ResultManagement"));
  const method = async (parent, name) => child(parent, qn(name));
  const state = async () => {
    const top = (await session.read({ nodeId: await child(smNode, "CurrentState"), attributeId: AttributeIds.Value })).value.value;
    const sub = (await session.read({ nodeId: await child(autoNode, "CurrentState"), attributeId: AttributeIds.Value })).value.value;
    return `${top && top.text}${sub && sub.text ? "/" + sub.text : ""}`;
  };
  const waitState = async (want, ms) => {
    const end = Date.now() + ms;
    for (;;) {
      const s = await state();
      if (s === want) return s;
      if (Date.now() > end) throw new Error(`state is ${s}, expected ${want}`);
      await new Promise((r) => setTimeout(r, 50));
    }
  };
  const ext = (type, fields) => session.constructExtensionObject(coerceNodeId(`ns=${ns};i=${type}`), fields);
  const recipeIdType = 3002;
  const partIdType = 3004;
  const measIdType = 3015;
  const productIdType = 3003;
  const call = async (obj, name, inputArguments, s = session) => {
    const r = await s.call({ objectId: obj, methodId: await method(obj, name), inputArguments });
    const args = inputArguments.map((a) => (a.value && a.value.id !== undefined ? a.value.id : a.value));
    transcript(`  call ${name}(${args.map((a) => JSON.stringify(typeof a === "string" && a.length > 40 ? a.slice(0, 12) + `...(${a.length} bytes)` : a)).join(", ")}) -> ${r.statusCode.name}${r.inputArgumentResults && r.inputArgumentResults.some((x) => x.name !== "Good") ? " inputArgumentResults " + r.inputArgumentResults.map((x) => x.name).join(",") : ""}`);
    return r;
  };
  const startArgs = async (part, recipe) => [
    { dataType: DataType.ExtensionObject, value: await ext(measIdType, { id: "" }) },
    { dataType: DataType.ExtensionObject, value: await ext(partIdType, { id: part }) },
    { dataType: DataType.ExtensionObject, value: await ext(recipeIdType, { id: recipe }) },
    { dataType: DataType.ExtensionObject, value: await ext(productIdType, { id: "" }) },
    { dataType: DataType.Variant, arrayType: 1, value: [] },
  ];
  const recipeArgs = async (id) => [
    { dataType: DataType.ExtensionObject, value: await ext(recipeIdType, { id }) },
    { dataType: DataType.ExtensionObject, value: await ext(3013, { id: "" }) },
  ];

  const recipe = JSON.parse(fs.readFileSync(recipeFile, "utf8"));
  await rpc("CreateRecipe", { recipe }).catch((e) => {
    if (e.code !== grpc.status.ALREADY_EXISTS) throw e;
  });
  transcript(`gRPC CreateRecipe ${recipe.recipe_id} (as mes-verifier)`);

  await check("StartSingleJob while not Ready is Bad_InvalidState", async () => {
    assert.equal(await waitState("Preoperational", 10000), "Preoperational");
    const r = await call(autoNode, "StartSingleJob", await startArgs(PART, recipe.recipe_id));
    assert.equal(r.statusCode.name, "BadInvalidState");
  });
  await check("SelectModeAutomatic: Preoperational -> Operational/Initialized", async () => {
    const r = await call(smNode, "SelectModeAutomatic", []);
    assert.equal(r.statusCode.name, "Good");
    assert.equal(await state(), "Operational/Initialized");
  });
  await check("PrepareRecipe of an unknown recipe is Bad_NotFound, nothing prepared", async () => {
    const r = await call(recipeMgmt, "PrepareRecipe", await recipeArgs("no-such-recipe"));
    assert.equal(r.statusCode.name, "BadNotFound");
    assert.equal(await state(), "Operational/Initialized");
  });
  await check("a viewer may not PrepareRecipe: Bad_UserAccessDenied", async () => {
    const c2 = client("mes-client");
    await c2.connect(endpointUrl);
    const s2 = await c2.createSession({ type: UserTokenType.UserName, userName: "viewer-1", password: "s3cret-viewer" });
    const r = await call(recipeMgmt, "PrepareRecipe", await recipeArgs(recipe.recipe_id), s2);
    assert.equal(r.statusCode.name, "BadUserAccessDenied");
    await s2.close();
    await c2.disconnect();
    assert.equal(await state(), "Operational/Initialized");
  });
  let internalId;
  await check("PrepareRecipe of the stored recipe: Operational/Ready", async () => {
    const r = await call(recipeMgmt, "PrepareRecipe", await recipeArgs(recipe.recipe_id));
    assert.equal(r.statusCode.name, "Good");
    internalId = r.outputArguments[0].value;
    transcript(`    InternalIdOut ${internalId.id} IsCompleted ${r.outputArguments[1].value}`);
    assert.equal(internalId.id, `${recipe.recipe_id}@1`);
    assert.equal(await state(), "Operational/Ready");
  });
  await check("an oversized part id is Bad_InvalidArgument (PartId Bad_OutOfRange), no job started", async () => {
    const before = (await rpc("ListJobs", {})).jobs.length;
    const r = await call(autoNode, "StartSingleJob", await startArgs("x".repeat(300), recipe.recipe_id));
    assert.equal(r.statusCode.name, "BadInvalidArgument");
    assert.equal(r.inputArgumentResults[1].name, "BadOutOfRange");
    assert.equal((await rpc("ListJobs", {})).jobs.length, before);
    assert.equal(await state(), "Operational/Ready");
  });

  // The inspection: subscribe to ResultReadyEvents, start the job, wait for the event.
  const fields = ["EventType", "Message", "ResultId", "ResultState", "JobId", "InternalRecipeId", "ExternalRecipeId", "PartId", "CreationTime", "ProcessingTimes", "ResultContent", "IsPartial", "InternalConfigurationId"];
  const subscription = ClientSubscription.create(session, { requestedPublishingInterval: 100, requestedMaxKeepAliveCount: 20, publishingEnabled: true });
  const eventFilter = {
    selectClauses: fields.map((f) => ({
      typeDefinitionId: f === "EventType" || f === "Message" ? "ns=0;i=2041" : `ns=${ns};i=1024`,
      browsePath: [{ namespaceIndex: f === "EventType" || f === "Message" ? 0 : ns, name: f }],
      attributeId: AttributeIds.Value,
    })),
  };
  const events = [];
  let onEvent;
  const item = ClientMonitoredItem.create(
    subscription,
    { nodeId: rig, attributeId: AttributeIds.EventNotifier },
    { samplingInterval: 0, discardOldest: true, queueSize: 10, filter: new EventFilter(eventFilter) },
    TimestampsToReturn.Neither,
  );
  item.on("changed", (values) => {
    const e = {};
    values.forEach((v, i) => (e[fields[i]] = v.value));
    events.push(e);
    if (onEvent) onEvent();
  });
  await withDeadline(new Promise((r) => item.once("initialized", r)), 10000, "the event monitored item");

  let jobId;
  let event;
  await check("StartSingleJob with a part id: SingleExecution, then a ResultReadyEvent", async () => {
    const got = new Promise((r) => (onEvent = () => events.some((e) => e.JobId && e.JobId.id === jobId) && r()));
    const r = await call(autoNode, "StartSingleJob", await startArgs(PART, recipe.recipe_id));
    assert.equal(r.statusCode.name, "Good");
    jobId = r.outputArguments[0].value.id;
    transcript(`    JobId ${jobId}`);
    const s = await state();
    assert.ok(["Operational/SingleExecution", "Operational/Ready"].includes(s), s);
    transcript(`    state after StartSingleJob: ${s}`);
    await withDeadline(got, 60000, "the ResultReadyEvent");
    event = events.find((e) => e.JobId && e.JobId.id === jobId);
    const content = event.ResultContent;
    transcript(`  ResultReadyEvent:`);
    transcript(`    EventType ${event.EventType.toString()}  Message "${event.Message.text}"`);
    transcript(`    ResultId ${event.ResultId.id}  ResultState ${event.ResultState}  IsPartial ${event.IsPartial}`);
    transcript(`    JobId ${event.JobId.id}  PartId ${event.PartId.id}`);
    transcript(`    InternalRecipeId ${event.InternalRecipeId.id} (version ${event.InternalRecipeId.version})  ExternalRecipeId ${event.ExternalRecipeId.id}`);
    transcript(`    InternalConfigurationId ${event.InternalConfigurationId.id}`);
    transcript(`    CreationTime ${event.CreationTime.toISOString()}`);
    const pt = event.ProcessingTimes;
    transcript(`    ProcessingTimes start ${pt.startTime.toISOString()} end ${pt.endTime.toISOString()} acquisition ${pt.acquisitionDuration.toFixed(1)} ms processing ${pt.processingDuration.toFixed(1)} ms`);
    transcript(`    ResultContent ${content.constructor.name}: recipe ${content.recipeId} v${content.recipeVersion} verdict ${content.verdict} sequence ${content.sequence}`);
    for (const m of content.measurements) {
      transcript(`      ${m.name} ${m.parameter} = ${m.value} ${m.unit}  u ${m.standardUncertainty}  U ${m.expandedUncertainty}  coverage ${m.coveragePercent} %  ${m.verdict}`);
    }
  });
  await check("the event's verdict and measurements equal the gRPC result of the same job", async () => {
    assert.ok(event, "no event");
    const listed = (await rpc("ListResults", { part_id: PART })).results;
    const g = listed.find((x) => x.job_id === jobId);
    assert.ok(g, `ListResults has no result of job ${jobId}`);
    const c = event.ResultContent;
    transcript(`  gRPC ListResults(part_id ${PART}): job ${g.job_id} verdict ${g.verdict} sequence ${g.sequence}`);
    assert.equal(event.ResultState, 1); // Completed
    assert.equal(event.PartId.id, g.part_id);
    assert.equal(event.JobId.id, g.job_id);
    assert.equal(event.InternalRecipeId.id, `${g.recipe_id}@${g.recipe_version}`);
    assert.equal(event.CreationTime.getTime(), Number(g.finish_time.seconds) * 1000 + Math.floor(g.finish_time.nanos / 1e6));
    assert.equal(`VERDICT_${c.verdict}`, g.verdict);
    assert.equal(c.verdict, "OK"); // skew5: a 5.000 deg tilt within 5 +- 0.5 deg
    assert.equal(String(c.sequence[1] ?? c.sequence), String(g.sequence));
    assert.equal(c.measurements.length, g.measurements.length);
    g.measurements.forEach((m, i) => {
      const o = c.measurements[i];
      transcript(`    ${m.name}: gRPC ${m.value} u ${m.standard_uncertainty} ${m.verdict} | OPC UA ${o.value} u ${o.standardUncertainty} ${o.verdict}`);
      assert.equal(o.name, m.name);
      assert.equal(o.value, m.value); // the same double, bit for bit
      assert.equal(o.standardUncertainty, m.standard_uncertainty);
      assert.equal(o.expandedUncertainty, m.expanded_uncertainty);
      assert.equal(o.coveragePercent, m.coverage_percent);
      assert.equal(`VERDICT_${o.verdict}`, m.verdict);
      assert.equal(o.unit, m.unit);
    });
    assert.ok(Math.abs(g.measurements[0].value - 5.0) < 0.5, `tilt ${g.measurements[0].value}`);
  });
  await check("GetResultById returns the same result; the state is Ready again", async () => {
    const r = await call(resultMgmt, "GetResultById", [
      { dataType: DataType.ExtensionObject, value: await ext(3021, { id: jobId }) },
      { dataType: DataType.Int32, value: 1000 },
    ]);
    assert.equal(r.statusCode.name, "Good");
    const res = r.outputArguments[1].value;
    assert.equal(res.jobId.id, jobId);
    assert.equal(res.partId.id, PART);
    const content = res.resultContent[0].value;
    assert.deepEqual(content.measurements.map((m) => m.value), event.ResultContent.measurements.map((m) => m.value));
    assert.equal(await waitState("Operational/Ready", 10000), "Operational/Ready");
  });
  await check("GetResultById of an unknown id is Bad_NotFound", async () => {
    const r = await call(resultMgmt, "GetResultById", [
      { dataType: DataType.ExtensionObject, value: await ext(3021, { id: "no-such-job" }) },
      { dataType: DataType.Int32, value: 1000 },
    ]);
    assert.equal(r.statusCode.name, "BadNotFound");
  });
  await check("UnprepareRecipe: back to Initialized; Abort there is Bad_InvalidState", async () => {
    assert.equal((await call(recipeMgmt, "UnprepareRecipe", await recipeArgs(recipe.recipe_id))).statusCode.name, "Good");
    assert.equal(await state(), "Operational/Initialized");
    assert.equal((await call(autoNode, "Abort", [{ dataType: DataType.Int32, value: 0 }, { dataType: DataType.String, value: "test" }])).statusCode.name, "BadInvalidState");
  });
  await check("an X.509 user certificate (qa-lead, engineer) may AddRecipe; an operator may not", async () => {
    const c3 = client("mes-client");
    await c3.connect(endpointUrl);
    const pem = fs.readFileSync(path.join(pki, "qa-lead.crt"), "utf8");
    const der = Buffer.from(pem.replace(/-----[^-]+-----/g, "").replace(/\s+/g, ""), "base64");
    const s3 = await c3.createSession({ type: UserTokenType.Certificate, certificateData: der, privateKey: fs.readFileSync(path.join(pki, "qa-lead.key"), "utf8") });
    transcript("  session: user certificate CN qa-lead");
    const add = async (id, sess) =>
      call(recipeMgmt, "AddRecipe", [
        { dataType: DataType.ExtensionObject, value: await ext(recipeIdType, { id }) },
        { dataType: DataType.ExtensionObject, value: await ext(productIdType, { id: "" }) },
      ], sess);
    const r = await add(recipe.recipe_id, s3);
    assert.equal(r.statusCode.name, "Good");
    assert.equal(r.outputArguments[0].value.id, `${recipe.recipe_id}@1`);
    assert.equal(r.outputArguments[3].value, false); // TransferRequired: the recipe is stored in inspectd
    assert.equal((await add("no-such-recipe", s3)).statusCode.name, "BadNotFound");
    assert.equal((await add(recipe.recipe_id, session)).statusCode.name, "BadUserAccessDenied");
    await s3.close();
    await c3.disconnect();
  });
  await check("Halt: Halted refuses StartSingleJob (Bad_InvalidState); Reset: Preoperational", async () => {
    const cause = [{ dataType: DataType.Int32, value: 0 }, { dataType: DataType.String, value: "test" }];
    assert.equal((await call(smNode, "Halt", cause)).statusCode.name, "Good");
    assert.equal(await state(), "Halted");
    assert.equal((await call(autoNode, "StartSingleJob", await startArgs(PART, recipe.recipe_id))).statusCode.name, "BadInvalidState");
    assert.equal((await call(smNode, "Reset", cause)).statusCode.name, "Good");
    assert.equal(await state(), "Preoperational");
  });
  await check("every call and refusal is audited with identity, role, method and code", async () => {
    const lines = auditLines();
    const has = (pred, what) => assert.ok(lines.some(pred), `no audit line for ${what}: ${JSON.stringify(lines.slice(-5))}`);
    has((l) => l.method === "PrepareRecipe" && l.code === "BadNotFound" && l.identity === "station-7" && l.role === "operator" && l.target === "no-such-recipe", "PrepareRecipe BadNotFound");
    has((l) => l.method === "PrepareRecipe" && l.code === "BadUserAccessDenied" && l.identity === "viewer-1", "viewer PrepareRecipe");
    has((l) => l.method === "StartSingleJob" && l.code === "BadInvalidState", "StartSingleJob BadInvalidState");
    has((l) => l.method === "StartSingleJob" && l.code === "BadInvalidArgument", "oversized part id");
    has((l) => l.method === "StartSingleJob" && l.code === "Good" && l.target === jobId, "the started job");
    has((l) => l.method === "ActivateSession" && l.code === "BadUserAccessDenied" && l.identity === "station-7", "wrong password");
    has((l) => l.method === "OpenSecureChannel" && l.code === "BadSecurityChecksFailed" && l.identity === "rogue-client", "the untrusted certificate");
    has((l) => l.method === "AddRecipe" && l.code === "Good" && l.identity === "qa-lead" && l.role === "engineer", "AddRecipe by certificate");
    assert.ok(!fs.readFileSync(auditLog, "utf8").includes("s3cret"), "a password in the audit log");
    transcript(`  audit log ${auditLog}: ${lines.length} lines, e.g.`);
    transcript(`    ${JSON.stringify(lines.find((l) => l.method === "PrepareRecipe" && l.code === "BadNotFound"))}`);
  });

  await subscription.terminate();
  await session.close();
  await c.disconnect();
  grpcStub.close();
  transcript(`${passes} passed, ${failures} failed`);
  process.exit(failures ? 1 : 0);
}

main().catch((e) => {
  transcript(`FAIL: ${e.stack || e.message}`);
  transcript(`${passes} passed, ${failures + 1} failed`);
  process.exit(1);
});

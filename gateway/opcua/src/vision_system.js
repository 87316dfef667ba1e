"use strict";
// One rig as an OPC 40100-1 VisionSystemType instance: the VisionStateMachine follows the rig's
// state from gRPC, the methods map onto inspectd's RPCs, and every stored inspection result
// (WatchResults) becomes a ResultReadyEvent. Each method call is authorized by the caller's role
// and audited, allowed or not.
const { StatusCodes, DataType, Variant, NodeId, promoteToStateMachine } = require("node-opcua");
const { grpc } = require("./inspectd_client");
const { atLeast } = require("./identity");

const MV_URI = "http://opcfoundation.org/UA/MachineVision";
const CONTENT_URI = "urn:inspection:opcua:result-content";
const RESULT_COMPLETED = 1; // ResultStateDataType (OPC 40100-1 12.19)
const RIG_POLL_MS = 1000;

// The role each method needs, as inspectd's roles (docs/security.md): reading results is a
// viewer's, running the rig an operator's, adding recipes an engineer's, resetting a rig in
// Error an admin's (ResetRig); a Reset that only leaves Halted or Preoperational is an operator's.
const METHOD_ROLES = {
  SelectModeAutomatic: "operator",
  Halt: "operator",
  Reset: "operator",
  AddRecipe: "engineer",
  PrepareRecipe: "operator",
  UnprepareRecipe: "operator",
  GetRecipeListFiltered: "viewer",
  StartSingleJob: "operator",
  Abort: "operator",
  Stop: "operator",
  GetResultById: "viewer",
  GetResultListFiltered: "viewer",
};

class MethodError extends Error {
  constructor(statusCode, message, inputArgumentResults) {
    super(message);
    this.statusCode = statusCode;
    this.inputArgumentResults = inputArgumentResults;
  }
}

// gRPC status -> OPC UA StatusCode (OPC 10000-4 method result codes).
function fromGrpc(err) {
  switch (err.code) {
    case grpc.status.NOT_FOUND:
      return StatusCodes.BadNotFound;
    case grpc.status.INVALID_ARGUMENT:
      return StatusCodes.BadInvalidArgument;
    case grpc.status.FAILED_PRECONDITION:
    case grpc.status.ABORTED:
      return StatusCodes.BadInvalidState;
    case grpc.status.RESOURCE_EXHAUSTED:
      return StatusCodes.BadResourceUnavailable;
    case grpc.status.DEADLINE_EXCEEDED:
      return StatusCodes.BadTimeout;
    case grpc.status.UNAVAILABLE:
      return StatusCodes.BadCommunicationError;
    case grpc.status.PERMISSION_DENIED:
    case grpc.status.UNAUTHENTICATED:
      return StatusCodes.BadConfigurationError; // the gateway's own identity lacks the role
    default:
      return StatusCodes.BadInternalError;
  }
}

function verdictName(v) {
  return String(v || "VERDICT_UNSPECIFIED").replace(/^VERDICT_/, "");
}

function timestampToDate(ts) {
  if (!ts) return null;
  return new Date(Number(ts.seconds || 0) * 1000 + Math.floor(Number(ts.nanos || 0) / 1e6));
}

class VisionSystem {
  constructor({ server, inspectd, identities, audit, config, log }) {
    this.server = server;
    this.addressSpace = server.engine.addressSpace;
    this.inspectd = inspectd;
    this.identities = identities;
    this.audit = audit;
    this.config = config;
    this.log = log;
    this.rig = null; // last RigStatus
    this.connected = false;
    this.everConnected = false;
    this.mode = "preoperational"; // preoperational | automatic | halted
    this.prepared = new Map(); // recipe_id -> {version, description}
    this.job = null; // the running single job: {jobId, recipeId, partId}
    this.results = new Map(); // job_id -> InspectionResult, newest last (bounded)
    this.lastSequence = 0;
    this.stateText = "";
  }

  build() {
    const as = this.addressSpace;
    this.ns = as.getNamespaceIndex(MV_URI);
    this.contentNs = as.getNamespaceIndex(CONTENT_URI);
    if (this.ns < 0) throw new Error("the MachineVision nodeset is not loaded");
    const type = as.findObjectType("VisionSystemType", this.ns);
    this.node = type.instantiate({
      browseName: { name: "InspectionRig", namespaceIndex: as.getOwnNamespace().index },
      displayName: "Inspection rig (shape from focus)",
      description: "One microscope rig of inspectd, as an OPC 40100-1 vision system",
      organizedBy: as.rootFolder.objects,
      optionals: [
        "RecipeManagement",
        "RecipeManagement.AddRecipe",
        "ResultManagement",
        "VisionStateMachine.AutomaticModeStateMachine",
        "VisionStateMachine.SelectModeAutomatic",
      ],
      eventNotifier: 1,
    });
    const server = as.rootFolder.objects.server;
    server.addReference({ referenceType: "HasNotifier", nodeId: this.node.nodeId });

    const c = (parent, name) => {
      const n = parent.getComponentByName(name, this.ns);
      if (!n) throw new Error(`${parent.browseName.toString()} has no ${name}`);
      return n;
    };
    this.stateMachineNode = c(this.node, "VisionStateMachine");
    this.autoNode = c(this.stateMachineNode, "AutomaticModeStateMachine");
    this.recipeManagement = c(this.node, "RecipeManagement");
    this.resultManagement = c(this.node, "ResultManagement");
    this.sm = promoteToStateMachine(this.stateMachineNode);
    this.auto = promoteToStateMachine(this.autoNode);
    this.sm.setState("Preoperational");
    this.auto.setState(null);

    const m = (parent, name, fn) => {
      const method = parent.getMethodByName(name, this.ns);
      if (!method) throw new Error(`${parent.browseName.toString()} has no method ${name}`);
      method.bindMethod((args, context) => this.call(name, method, args, context, fn));
    };
    m(this.stateMachineNode, "SelectModeAutomatic", (a, who) => this.selectModeAutomatic(who));
    m(this.stateMachineNode, "Halt", (a, who) => this.halt(who, a));
    m(this.stateMachineNode, "Reset", (a, who) => this.reset(who, a));
    m(this.recipeManagement, "AddRecipe", (a, who) => this.addRecipe(a, who));
    m(this.recipeManagement, "PrepareRecipe", (a, who) => this.prepareRecipe(a, who));
    m(this.recipeManagement, "UnprepareRecipe", (a, who) => this.unprepareRecipe(a, who));
    m(this.recipeManagement, "GetRecipeListFiltered", (a, who) => this.getRecipeListFiltered(a, who));
    m(this.autoNode, "StartSingleJob", (a, who) => this.startSingleJob(a, who));
    m(this.autoNode, "Abort", (a, who) => this.abort("Abort", who));
    m(this.autoNode, "Stop", (a, who) => this.abort("Stop", who));
    m(this.autoNode, "StartContinuous", () => {
      throw new MethodError(StatusCodes.BadNotImplemented, "continuous execution is not mapped: use StartSingleJob per part");
    });
    m(this.resultManagement, "GetResultById", (a, who) => this.getResultById(a, who));
    m(this.resultManagement, "GetResultListFiltered", (a, who) => this.getResultListFiltered(a, who));
    m(this.resultManagement, "GetResultComponentsById", () => {
      throw new MethodError(StatusCodes.BadNotImplemented, "use GetResultById");
    });
    this.resultReadyType = as.findEventType("ResultReadyEventType", this.ns);
  }

  // --- method plumbing ---------------------------------------------------------------------
  async call(name, method, args, context, fn) {
    const who = this.identities.callerOf(context.session);
    const peer = peerOf(context.session);
    const needed = METHOD_ROLES[name] || "admin";
    let outcome;
    let target = "";
    try {
      if (!atLeast(who.role, needed)) {
        throw new MethodError(
          StatusCodes.BadUserAccessDenied,
          `${name} needs role ${needed}; '${who.name}' has role ${who.role || "none"}`,
        );
      }
      const r = (await fn(args, who)) || {};
      target = r.target || "";
      outcome = {
        statusCode: StatusCodes.Good,
        outputArguments: (r.outputs || []).concat([{ dataType: DataType.Int32, value: 0 }]),
      };
      this.audit.record({ identity: who.name, role: who.role, peer, method: name, target, code: "Good", message: r.message || "" });
    } catch (e) {
      const statusCode = e instanceof MethodError ? e.statusCode : StatusCodes.BadInternalError;
      if (!(e instanceof MethodError)) this.log.error({ err: e, method: name }, "method failed");
      else this.log.info({ method: name, identity: who.name, code: statusCode.name }, e.message);
      target = (e && e.target) || "";
      this.audit.record({ identity: who.name, role: who.role, peer, method: name, target, code: statusCode.name, message: e.message });
      outcome = { statusCode };
      if (e.inputArgumentResults) outcome.inputArgumentResults = e.inputArgumentResults;
    }
    return outcome;
  }

  ext(typeName, fields, ns = this.ns) {
    const dt = this.addressSpace.findDataType(typeName, ns);
    return this.addressSpace.constructExtensionObject(dt, fields);
  }

  // --- state ---------------------------------------------------------------------------------
  start() {
    const poll = async () => {
      try {
        this.rig = await this.inspectd.getRigStatus();
        if (!this.connected) this.log.info({ inspectd: this.inspectd.address, rig: this.rig.state }, "connected to inspectd");
        this.connected = this.everConnected = true;
        this.connectionError = "";
      } catch (e) {
        if (this.connected || this.connectionError !== e.message) this.log.warn({ inspectd: this.inspectd.address }, `inspectd unreachable: ${e.message}`);
        this.connected = false;
        this.connectionError = e.message;
      }
      this.updateState();
      this.pollTimer = setTimeout(poll, RIG_POLL_MS);
    };
    poll();
    this.followResults();
  }

  stop() {
    clearTimeout(this.pollTimer);
    clearTimeout(this.watchTimer);
    this.stopped = true;
    if (this.watch) this.watch.cancel();
  }

  rigState() {
    return this.rig ? this.rig.state : "RIG_STATE_UNSPECIFIED";
  }

  // The VisionStateMachine state from the rig's state and this gateway's mode.
  updateState() {
    let top;
    let sub = null;
    let why;
    const rig = this.rigState();
    if (!this.connected) {
      top = this.everConnected ? "Error" : "Preoperational";
      why = `inspectd at ${this.inspectd.address} unreachable: ${this.connectionError}`;
    } else if (rig === "RIG_STATE_ERROR") {
      top = "Error";
      why = `rig in Error: ${this.rig.state_detail || "device failure"} (Reset with role admin resets it)`;
    } else if (rig === "RIG_STATE_INITIALIZING" || rig === "RIG_STATE_UNSPECIFIED") {
      top = "Preoperational";
      why = "rig initializing";
    } else if (this.mode === "halted") {
      top = "Halted";
      why = "halted by Halt";
    } else if (this.mode === "preoperational") {
      top = "Preoperational";
      why = "waiting for SelectModeAutomatic";
    } else {
      top = "Operational";
      sub = this.job ? "SingleExecution" : this.prepared.size ? "Ready" : "Initialized";
      why = this.job ? `job ${this.job.jobId}` : this.prepared.size ? `prepared: ${[...this.prepared.keys()].join(", ")}` : "no recipe prepared";
    }
    const text = `${top}${sub ? "/" + sub : ""}`;
    if (text !== this.stateText) {
      this.log.info({ state: text, rig }, `vision state ${text}: ${why}`);
      this.stateText = text;
    }
    if (stateName(this.sm) !== top) this.sm.setState(top);
    if (sub === null) {
      if (stateName(this.auto) !== null) this.auto.setState(null);
    } else if (stateName(this.auto) !== sub) {
      this.auto.setState(sub);
    }
  }

  requireState(top, sub, name) {
    this.updateState();
    const cur = stateName(this.sm);
    const curSub = stateName(this.auto);
    const okTop = Array.isArray(top) ? top.includes(cur) : cur === top;
    const okSub = !sub || (Array.isArray(sub) ? sub.includes(curSub) : curSub === sub);
    if (!okTop || !okSub) {
      throw new MethodError(StatusCodes.BadInvalidState, `${name} needs ${[].concat(top).join("|")}${sub ? "/" + [].concat(sub).join("|") : ""}; the vision system is ${this.stateText}`);
    }
  }

  // --- VisionStateMachine --------------------------------------------------------------------
  async selectModeAutomatic() {
    this.requireState(["Preoperational", "Operational"], null, "SelectModeAutomatic");
    if (this.rigState() !== "RIG_STATE_READY" && this.rigState() !== "RIG_STATE_BUSY") {
      throw new MethodError(StatusCodes.BadInvalidState, `SelectModeAutomatic: the rig is ${this.rigState()}`);
    }
    this.mode = "automatic";
    this.updateState();
    return { message: this.stateText };
  }

  async halt(who) {
    if (this.job) await this.cancelJob();
    this.mode = "halted";
    this.updateState();
    return { message: this.stateText };
  }

  async reset(who) {
    if (this.job) await this.cancelJob();
    if (this.rigState() === "RIG_STATE_ERROR") {
      if (!atLeast(who.role, "admin")) {
        throw new MethodError(StatusCodes.BadUserAccessDenied, `Reset of a rig in Error runs ResetRig, which needs role admin; '${who.name}' has role ${who.role}`);
      }
      try {
        this.rig = await this.inspectd.resetRig();
      } catch (e) {
        // The rig went through Initializing: answer with the state it is in now, not the last poll's.
        this.rig = await this.inspectd.getRigStatus().catch(() => this.rig);
        this.updateState();
        throw new MethodError(fromGrpc(e), `ResetRig: ${e.details || e.message}`);
      }
    }
    this.mode = "preoperational";
    this.prepared.clear();
    this.updateState();
    return { message: this.stateText };
  }

  // --- recipes -------------------------------------------------------------------------------
  async lookupRecipe(externalId, internalId, argIndex, nargs) {
    let id = externalId && externalId.id;
    let version = externalId && externalId.version ? externalId.version : "";
    if (!id && internalId && internalId.id) {
      const at = internalId.id.lastIndexOf("@");
      id = at > 0 ? internalId.id.slice(0, at) : internalId.id;
      version = at > 0 ? internalId.id.slice(at + 1) : internalId.version || "";
    }
    const results = new Array(nargs).fill(StatusCodes.Good);
    if (!id) {
      results[argIndex] = StatusCodes.BadInvalidArgument;
      throw new MethodError(StatusCodes.BadInvalidArgument, "ExternalId.Id is empty (the recipe_id of a stored recipe)", results);
    }
    if (version && !/^[0-9]+$/.test(version)) {
      results[argIndex] = StatusCodes.BadOutOfRange;
      throw new MethodError(StatusCodes.BadInvalidArgument, `ExternalId.Version '${version}' must be a recipe version number`, results);
    }
    try {
      return await this.inspectd.getRecipe(id, version ? Number(version) : 0);
    } catch (e) {
      const err = new MethodError(fromGrpc(e), `recipe '${id}'${version ? " version " + version : ""}: ${e.details || e.message}`);
      err.target = id;
      throw err;
    }
  }

  internalId(recipe) {
    return this.ext("RecipeIdInternalDataType", {
      id: `${recipe.recipe_id}@${recipe.version}`,
      version: String(recipe.version),
      description: { text: recipe.description || "" },
    });
  }

  async addRecipe(args) {
    const [externalId] = args.map((a) => a.value);
    const recipe = await this.lookupRecipe(externalId, null, 0, 2).catch((e) => {
      if (e.statusCode === StatusCodes.BadNotFound) {
        e.message += "; AddRecipe registers a recipe stored in inspectd (inspectctl recipe create): recipe transfer over OPC UA is not offered";
      }
      throw e;
    });
    return {
      target: recipe.recipe_id,
      message: `recipe ${recipe.recipe_id} v${recipe.version}`,
      outputs: [
        { dataType: DataType.ExtensionObject, value: this.internalId(recipe) },
        { dataType: DataType.NodeId, value: NodeId.nullNodeId },
        { dataType: DataType.NodeId, value: NodeId.nullNodeId },
        { dataType: DataType.Boolean, value: false },
      ],
    };
  }

  async prepareRecipe(args) {
    const [externalId, internalIdIn] = args.map((a) => a.value);
    this.requireState("Operational", ["Initialized", "Ready"], "PrepareRecipe");
    const recipe = await this.lookupRecipe(externalId, internalIdIn, 0, 2);
    this.prepared.set(recipe.recipe_id, { version: recipe.version, description: recipe.description });
    this.updateState();
    return {
      target: recipe.recipe_id,
      message: `prepared ${recipe.recipe_id} v${recipe.version}`,
      outputs: [
        { dataType: DataType.ExtensionObject, value: this.internalId(recipe) },
        { dataType: DataType.Boolean, value: true },
      ],
    };
  }

  async unprepareRecipe(args) {
    const [externalId, internalIdIn] = args.map((a) => a.value);
    let id = (externalId && externalId.id) || (internalIdIn && internalIdIn.id ? internalIdIn.id.replace(/@[0-9]+$/, "") : "");
    const p = this.prepared.get(id);
    if (!p) {
      const e = new MethodError(StatusCodes.BadNotFound, `recipe '${id}' is not prepared`);
      e.target = id;
      throw e;
    }
    if (this.job && this.job.recipeId === id) throw new MethodError(StatusCodes.BadInvalidState, `recipe '${id}' runs job ${this.job.jobId}`);
    this.prepared.delete(id);
    this.updateState();
    return {
      target: id,
      outputs: [{ dataType: DataType.ExtensionObject, value: this.internalId({ recipe_id: id, version: p.version, description: p.description }) }],
    };
  }

  async getRecipeListFiltered(args) {
    const [externalId, , isPrepared, maxResults, startIndex] = args.map((a) => a.value);
    let list;
    try {
      list = (await this.inspectd.listRecipes()).recipes;
    } catch (e) {
      throw new MethodError(fromGrpc(e), `ListRecipes: ${e.details || e.message}`);
    }
    list = list.filter((r) => !(externalId && externalId.id) || r.recipe_id === externalId.id);
    if (isPrepared === 1) list = list.filter((r) => this.prepared.has(r.recipe_id));
    if (isPrepared === 0) list = list.filter((r) => !this.prepared.has(r.recipe_id));
    const start = startIndex || 0;
    const page = list.slice(start, maxResults ? start + maxResults : undefined);
    return {
      outputs: [
        { dataType: DataType.Boolean, value: start + page.length >= list.length },
        { dataType: DataType.UInt32, value: page.length },
        { dataType: DataType.UInt32, value: 0 },
        { dataType: DataType.ExtensionObject, arrayType: 1, value: page.map((r) => this.internalId(r)) },
      ],
    };
  }

  // --- jobs ----------------------------------------------------------------------------------
  async startSingleJob(args, who) {
    const [measId, partId, recipeId] = args.map((a) => a.value);
    const results = new Array(args.length).fill(StatusCodes.Good);
    const part = (partId && partId.id) || "";
    const max = this.config.max_part_id_bytes;
    if (Buffer.byteLength(part) > max) {
      results[1] = StatusCodes.BadOutOfRange;
      throw new MethodError(StatusCodes.BadInvalidArgument, `PartId.Id is ${Buffer.byteLength(part)} bytes, at most ${max}`, results);
    }
    const meas = (measId && measId.id) || "";
    if (Buffer.byteLength(meas) > max) {
      results[0] = StatusCodes.BadOutOfRange;
      throw new MethodError(StatusCodes.BadInvalidArgument, `MeasId.Id is ${Buffer.byteLength(meas)} bytes, at most ${max}`, results);
    }
    this.requireState("Operational", "Ready", "StartSingleJob");
    let id = recipeId && recipeId.id;
    if (!id && this.prepared.size === 1) id = [...this.prepared.keys()][0];
    const prepared = this.prepared.get(id);
    if (!prepared) {
      results[2] = StatusCodes.BadNotFound;
      throw new MethodError(StatusCodes.BadInvalidArgument, `RecipeId '${id || ""}' is not prepared (PrepareRecipe first)`, results);
    }
    const request = {
      recipe_id: id,
      recipe_version: prepared.version,
      part_id: part,
      station: `${this.config.station}:${who.name}`.slice(0, max),
      label: meas ? `MeasId ${meas}` : "",
    };
    this.job = { jobId: null, recipeId: id, partId: part };
    this.updateState();
    let jobId;
    try {
      jobId = await this.inspectd.scan(request, (job, err) => this.jobEnded(jobId, job, err));
    } catch (e) {
      this.job = null;
      this.updateState();
      const err = new MethodError(fromGrpc(e), `Scan: ${e.details || e.message}`);
      err.target = id;
      throw err;
    }
    if (this.job) this.job.jobId = jobId;
    this.log.info({ job_id: jobId, recipe: id, part_id: part, identity: who.name }, "single job started");
    return {
      target: jobId,
      message: `recipe ${id} v${prepared.version} part '${part}'`,
      outputs: [{ dataType: DataType.ExtensionObject, value: this.ext("JobIdDataType", { id: jobId }) }],
    };
  }

  jobEnded(jobId, job, err) {
    if (err) this.log.warn({ job_id: jobId }, `job stream: ${err.details || err.message}`);
    else this.log.info({ job_id: jobId, state: job && job.state, error: job && job.error_message }, "single job ended");
    if (this.job && (this.job.jobId === jobId || this.job.jobId === null)) this.job = null;
    this.updateState();
  }

  async cancelJob() {
    const jobId = this.job && this.job.jobId;
    if (!jobId) return;
    try {
      await this.inspectd.cancelJob(jobId);
    } catch (e) {
      throw new MethodError(fromGrpc(e), `CancelJob ${jobId}: ${e.details || e.message}`);
    }
  }

  async abort(name) {
    this.requireState("Operational", "SingleExecution", name);
    const jobId = this.job.jobId;
    await this.cancelJob();
    return { target: jobId, message: `cancelled ${jobId}` };
  }

  // --- results -------------------------------------------------------------------------------
  async followResults() {
    let after = 0;
    for (;;) {
      try {
        const newest = await this.inspectd.listResults({ page_size: 1 });
        after = newest.results.length ? Number(newest.results[0].sequence) : 0;
        break;
      } catch (e) {
        if (this.stopped) return;
        await new Promise((r) => (this.watchTimer = setTimeout(r, RIG_POLL_MS)));
      }
    }
    this.lastSequence = after;
    const subscribe = () => {
      if (this.stopped) return;
      this.watch = this.inspectd.watchResults(
        this.lastSequence,
        (result) => this.onResult(result),
        (err) => {
          if (this.stopped || err.code === grpc.status.CANCELLED) return;
          this.log.warn(`WatchResults: ${err.details || err.message}; resubscribing after ${this.lastSequence}`);
          this.watchTimer = setTimeout(subscribe, RIG_POLL_MS);
        },
      );
    };
    subscribe();
  }

  onResult(result) {
    const seq = Number(result.sequence);
    if (seq <= this.lastSequence) return;
    this.lastSequence = seq;
    this.results.set(result.job_id, result);
    while (this.results.size > 1000) this.results.delete(this.results.keys().next().value);
    const fields = this.resultFields(result);
    this.node.raiseEvent(this.resultReadyType, {
      message: { dataType: DataType.LocalizedText, value: { text: `part '${result.part_id}' recipe ${result.recipe_id}: ${verdictName(result.verdict)}` } },
      severity: { dataType: DataType.UInt16, value: result.verdict === "VERDICT_OK" ? 100 : 500 },
      resultId: { dataType: DataType.ExtensionObject, value: fields.ResultId },
      isPartial: { dataType: DataType.Boolean, value: false },
      isSimulated: { dataType: DataType.Boolean, value: fields.IsSimulated },
      resultState: { dataType: DataType.Int32, value: RESULT_COMPLETED },
      partId: { dataType: DataType.ExtensionObject, value: fields.PartId },
      externalRecipeId: { dataType: DataType.ExtensionObject, value: fields.ExternalRecipeId },
      internalRecipeId: { dataType: DataType.ExtensionObject, value: fields.InternalRecipeId },
      internalConfigurationId: { dataType: DataType.ExtensionObject, value: fields.InternalConfigurationId },
      jobId: { dataType: DataType.ExtensionObject, value: fields.JobId },
      creationTime: { dataType: DataType.DateTime, value: fields.CreationTime },
      processingTimes: { dataType: DataType.ExtensionObject, value: fields.ProcessingTimes },
      resultContent: { dataType: DataType.ExtensionObject, value: fields.ResultContent },
    });
    this.log.info({ job_id: result.job_id, sequence: seq, verdict: result.verdict }, "ResultReadyEvent raised");
  }

  resultFields(r) {
    const end = timestampToDate(r.finish_time) || new Date();
    const t = r.timings || {};
    const total = (Number(t.queue_seconds || 0) + Number(t.scan_seconds || 0) + Number(t.measure_seconds || 0)) * 1000;
    const content = this.ext(
      "InspectionResultContentDataType",
      {
        recipeId: r.recipe_id,
        recipeVersion: r.recipe_version,
        verdict: verdictName(r.verdict),
        measurements: (r.measurements || []).map((m) =>
          this.ext(
            "MeasurementResultDataType",
            {
              name: m.name,
              parameter: m.parameter,
              measured: !!m.measured,
              value: Number(m.value),
              unit: m.unit,
              standardUncertainty: Number(m.standard_uncertainty),
              expandedUncertainty: Number(m.expanded_uncertainty),
              coveragePercent: Number(m.coverage_percent),
              verdict: verdictName(m.verdict),
              reason: m.reason,
            },
            this.contentNs,
          ),
        ),
        sequence: [0, Number(r.sequence)],
        station: r.station,
        calibrationId: r.calibration_id,
        reportArtifactId: r.report_artifact_id,
      },
      this.contentNs,
    );
    return {
      ResultId: this.ext("ResultIdDataType", { id: r.job_id }),
      IsSimulated: !!(this.rig && this.rig.simulated),
      PartId: this.ext("PartIdDataType", { id: r.part_id }),
      ExternalRecipeId: this.ext("RecipeIdExternalDataType", { id: r.recipe_id, version: String(r.recipe_version) }),
      InternalRecipeId: this.ext("RecipeIdInternalDataType", { id: `${r.recipe_id}@${r.recipe_version}`, version: String(r.recipe_version) }),
      InternalConfigurationId: this.ext("ConfigurationIdDataType", { id: r.calibration_id || "uncalibrated", version: "" }),
      JobId: this.ext("JobIdDataType", { id: r.job_id }),
      CreationTime: end,
      ProcessingTimes: this.ext("ProcessingTimesDataType", {
        startTime: new Date(end.getTime() - total + Number(t.queue_seconds || 0) * 1000),
        endTime: end,
        acquisitionDuration: (Number(t.scan_seconds || 0) - Number(t.engine_seconds || 0)) * 1000,
        processingDuration: (Number(t.engine_seconds || 0) + Number(t.measure_seconds || 0)) * 1000,
      }),
      ResultContent: content,
    };
  }

  resultDataType(r) {
    const f = this.resultFields(r);
    return this.ext("ResultDataType", {
      resultId: f.ResultId,
      isPartial: false,
      isSimulated: f.IsSimulated,
      resultState: RESULT_COMPLETED,
      partId: f.PartId,
      externalRecipeId: f.ExternalRecipeId,
      internalRecipeId: f.InternalRecipeId,
      internalConfigurationId: f.InternalConfigurationId,
      jobId: f.JobId,
      creationTime: f.CreationTime,
      processingTimes: f.ProcessingTimes,
      resultContent: [new Variant({ dataType: DataType.ExtensionObject, value: f.ResultContent })],
    });
  }

  async findResult(jobId) {
    if (this.results.has(jobId)) return this.results.get(jobId);
    let token = "";
    for (let page = 0; page < 20; page++) {
      const r = await this.inspectd.listResults({ page_size: 500, page_token: token });
      const hit = r.results.find((x) => x.job_id === jobId);
      if (hit) return hit;
      if (!r.next_page_token) return null;
      token = r.next_page_token;
    }
    return null;
  }

  async getResultById(args) {
    const [resultId] = args.map((a) => a.value);
    const id = (resultId && resultId.id) || "";
    let r;
    try {
      r = await this.findResult(id);
    } catch (e) {
      throw new MethodError(fromGrpc(e), `ListResults: ${e.details || e.message}`);
    }
    if (!r) {
      const e = new MethodError(StatusCodes.BadNotFound, `no result with ResultId '${id}' (the scan job's id)`);
      e.target = id;
      throw e;
    }
    return {
      target: id,
      outputs: [
        { dataType: DataType.UInt32, value: 0 },
        { dataType: DataType.ExtensionObject, value: this.resultDataType(r) },
      ],
    };
  }

  async getResultListFiltered(args) {
    const v = args.map((a) => a.value);
    const partId = v[2] && v[2].id;
    const recipeId = (v[3] && v[3].id) || (v[4] && v[4].id ? v[4].id.replace(/@[0-9]+$/, "") : "");
    const jobId = v[8] && v[8].id;
    const maxResults = v[9] || 50;
    const startIndex = v[10] || 0;
    let list;
    try {
      list = (await this.inspectd.listResults({ part_id: partId || "", recipe_id: recipeId || "", page_size: 500 })).results;
    } catch (e) {
      throw new MethodError(fromGrpc(e), `ListResults: ${e.details || e.message}`);
    }
    if (jobId) list = list.filter((r) => r.job_id === jobId);
    const page = list.slice(startIndex, startIndex + Math.min(maxResults, 500));
    return {
      outputs: [
        { dataType: DataType.Boolean, value: startIndex + page.length >= list.length },
        { dataType: DataType.UInt32, value: page.length },
        { dataType: DataType.UInt32, value: 0 },
        { dataType: DataType.ExtensionObject, arrayType: 1, value: page.map((r) => this.resultDataType(r)) },
      ],
    };
  }
}

// "Ready" for the current state node "2:Ready"; null when the machine has no active state.
function stateName(machine) {
  const s = machine.getCurrentState();
  return s === null ? null : s.replace(/^[0-9]+:/, "");
}

function peerOf(session) {
  try {
    const ch = session && session.channel;
    return ch && ch.remoteAddress ? `${ch.remoteAddress}:${ch.remotePort}` : "";
  } catch {
    return "";
  }
}

module.exports = { VisionSystem, MethodError, METHOD_ROLES, MV_URI, CONTENT_URI };

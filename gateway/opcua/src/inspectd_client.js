"use strict";
// gRPC to inspectd (inspection.v1, proto/inspection/v1/inspection.proto), with the gateway's own
// mTLS identity. Thin promise wrappers over @grpc/grpc-js; no field is renamed (proto names kept).
const fs = require("fs");
const path = require("path");
const grpc = require("@grpc/grpc-js");
const protoLoader = require("@grpc/proto-loader");

// The repository's proto, or the copy beside the gateway in the image (deploy/Containerfile).
function protoRoot() {
  for (const dir of [path.join(__dirname, "..", "proto"), path.join(__dirname, "..", "..", "..", "proto")]) {
    if (fs.existsSync(path.join(dir, "inspection", "v1", "inspection.proto"))) return dir;
  }
  throw new Error("inspection/v1/inspection.proto not found beside the gateway or in the repository");
}

function loadPackage() {
  const root = protoRoot();
  const def = protoLoader.loadSync(path.join(root, "inspection", "v1", "inspection.proto"), {
    includeDirs: [root],
    keepCase: true,
    longs: String,
    enums: String,
    defaults: true,
    oneofs: true,
  });
  return grpc.loadPackageDefinition(def).inspection.v1;
}

class InspectdClient {
  constructor(config) {
    const pkg = loadPackage();
    let creds;
    if (config.grpc_tls_ca) {
      creds = grpc.credentials.createSsl(
        fs.readFileSync(config.grpc_tls_ca),
        config.grpc_tls_key ? fs.readFileSync(config.grpc_tls_key) : null,
        config.grpc_tls_cert ? fs.readFileSync(config.grpc_tls_cert) : null,
      );
    } else {
      creds = grpc.credentials.createInsecure();
    }
    const options = {};
    if (config.grpc_server_name) options["grpc.ssl_target_name_override"] = config.grpc_server_name;
    this.address = config.inspectd;
    this.stub = new pkg.InspectionService(config.inspectd, creds, options);
    this.metadata = new grpc.Metadata();
    if (config.grpc_token_file) {
      const token = fs.readFileSync(config.grpc_token_file, "utf8").split(/\r?\n/)[0].trim();
      this.metadata.set("authorization", `Bearer ${token}`);
    }
  }

  unary(method, request, timeoutMs = 15000) {
    return new Promise((resolve, reject) => {
      this.stub[method](request, this.metadata, { deadline: Date.now() + timeoutMs }, (err, response) =>
        err ? reject(err) : resolve(response),
      );
    });
  }

  getRigStatus() {
    return this.unary("GetRigStatus", {});
  }
  resetRig() {
    return this.unary("ResetRig", {}, 120000);
  }
  getRecipe(recipeId, version = 0) {
    return this.unary("GetRecipe", { recipe_id: recipeId, version });
  }
  listRecipes() {
    return this.unary("ListRecipes", {});
  }
  cancelJob(jobId) {
    return this.unary("CancelJob", { job_id: jobId });
  }
  listResults(request) {
    return this.unary("ListResults", request);
  }

  // Starts a scan; resolves with the job id from the first event, and calls onEnd(job, error)
  // once with the terminal event's job (or the stream's error).
  scan(request, onEnd) {
    return new Promise((resolve, reject) => {
      const call = this.stub.Scan(request, this.metadata);
      let jobId = null;
      let ended = false;
      const end = (job, err) => {
        if (!ended) {
          ended = true;
          onEnd(job, err);
        }
      };
      call.on("data", (event) => {
        if (!jobId) {
          jobId = event.job_id;
          resolve(jobId);
        }
        if (["JOB_STATE_SUCCEEDED", "JOB_STATE_FAILED", "JOB_STATE_CANCELLED"].includes(event.state)) end(event.job, null);
      });
      call.on("error", (err) => {
        if (!jobId) reject(err);
        else end(null, err);
      });
      call.on("end", () => {
        if (!jobId) reject(new Error("Scan stream ended without an event"));
      });
    });
  }

  // Follows the result feed after `afterSequence`; onResult(result) for each, onError(err) once
  // when the stream breaks (the caller resubscribes after the last sequence it saw).
  watchResults(afterSequence, onResult, onError) {
    const call = this.stub.WatchResults({ after_sequence: String(afterSequence) }, this.metadata);
    call.on("data", onResult);
    call.on("error", onError);
    call.on("end", () => onError(new Error("WatchResults ended")));
    return call;
  }

  close() {
    this.stub.close();
  }
}

module.exports = { InspectdClient, grpc };

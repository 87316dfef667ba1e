// inspectd dashboard: polls the server's JSON endpoints (/api/status, /api/live, /api/jobs) and
// redraws in place, so the page never reloads. Jobs and rig status are the gRPC API's messages
// as proto3 JSON (lowerCamelCase fields, enums by name). Read-only: it only ever GETs.
"use strict";

const LIVE_POLL_MS = 400;     // frame counter and statistics of a running scan
const STATUS_POLL_MS = 1500;  // rig, queue
const JOBS_POLL_MS = 3000;    // recent jobs (also refreshed when a live job ends)

const $ = (id) => document.getElementById(id);
const TOKEN_KEY = "inspectd-token";
let needToken = false;
const previewUrls = new Map();  // job id -> object URL of its depth preview (fetched once)
let liveJobIds = [];
let thumbnailBusy = false;
let thumbnailIndex = null;

function enumName(value, prefix) {
  return typeof value === "string" && value.startsWith(prefix) ? value.slice(prefix.length) : String(value ?? "-");
}
function fixed(value, digits, unit) {
  return typeof value === "number" && isFinite(value) ? value.toFixed(digits) + (unit ? " " + unit : "") : "-";
}
function badge(el, text, cls) {
  el.textContent = text;
  el.className = "badge " + (cls || "");
}
function cell(row, content) {
  const td = row.insertCell();
  if (content instanceof Node) td.appendChild(content); else td.textContent = content ?? "";
  return td;
}

// GET with the bearer token when one is stored; a 401/403 asks for a token once.
async function get(path) {
  const headers = {};
  const token = sessionStorage.getItem(TOKEN_KEY);
  if (token) headers["Authorization"] = "Bearer " + token;
  const res = await fetch(path, { headers, cache: "no-store" });
  if (res.status === 401 || res.status === 403) {
    needToken = true;
    $("token-form").hidden = false;
    $("token-error").textContent = token ? (await res.text()).trim() : "";
    throw new Error("unauthorized");
  }
  return res;
}
async function getJson(path) {
  const res = await get(path);
  if (!res.ok) throw new Error(path + ": HTTP " + res.status);
  return res.json();
}

function showConnection(ok, text) {
  badge($("connection"), text, ok ? "ok" : "bad");
}

async function refreshStatus() {
  const s = await getJson("/api/status");
  $("server-version").textContent = s.server_version;
  const rig = s.rig;
  const tbody = $("devices").tBodies[0];
  tbody.replaceChildren();
  if (!rig) {
    badge($("rig-state"), "no rig", "");
    $("rig-detail").textContent = "This inspectd runs with --no-rig: reconstructs only.";
    $("rig-facts").textContent = "";
  } else {
    const state = enumName(rig.state, "RIG_STATE_");
    badge($("rig-state"), state, "state-" + state);
    $("rig-detail").textContent = rig.stateDetail || "";
    for (const d of rig.devices || []) {
      const row = tbody.insertRow();
      [d.role, d.driver, d.model, d.serial, d.connected ? "yes" : "no"].forEach((v) => cell(row, v));
      if (!d.connected) row.className = "bad";
    }
    const facts = [];
    if (rig.simulated) facts.push("simulated, specimen " + rig.specimen);
    facts.push("pixel " + fixed(rig.pixelSizeUm, 3, "µm"));
    facts.push("calibration " + (rig.activeCalibrationId || "none"));
    if (rig.verificationState) {
      const v = enumName(rig.verificationState, "VERIFICATION_STATE_").toLowerCase();
      facts.push((v === "verified" ? "verified" : "verification " + v) + (rig.verificationDetail ? " (" + rig.verificationDetail + ")" : ""));
    }
    facts.push("queue " + rig.queuedJobs + " / " + rig.queueCapacity);
    $("rig-facts").textContent = facts.join(" · ");
  }
  const queue = $("queue");
  queue.replaceChildren();
  for (const job of s.queue) {
    const li = document.createElement("li");
    const state = enumName(job.state, "JOB_STATE_");
    li.textContent = enumName(job.kind, "JOB_KIND_").toLowerCase() + " " + job.jobId + (job.label ? " (" + job.label + ")" : "") + " ";
    const b = document.createElement("span");
    badge(b, state, "state-" + state);
    li.appendChild(b);
    queue.appendChild(li);
  }
  $("queue-count").textContent = String(s.queue.length);
}

async function refreshThumbnail(jobId, index) {
  if (thumbnailBusy || index === thumbnailIndex) return;
  thumbnailBusy = true;
  try {
    const res = await get("/api/jobs/" + encodeURIComponent(jobId) + "/frame.png");
    if (!res.ok) return;
    const shown = res.headers.get("X-Frame-Index");
    const url = URL.createObjectURL(await res.blob());
    const img = $("live-thumbnail");
    if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
    img.src = url;
    thumbnailIndex = index;
    $("live-thumbnail-caption").textContent = "stored frame " + shown;
  } finally {
    thumbnailBusy = false;
  }
}

async function refreshLive() {
  const live = await getJson("/api/live");
  const ids = live.jobs.map((j) => j.job_id);
  const ended = liveJobIds.some((id) => !ids.includes(id));
  liveJobIds = ids;
  if (ended) refreshJobs().catch(() => {});  // a job just finished: show it at once
  // The job with frames (a scan or reconstruct) is the interesting one; else any.
  const job = live.jobs.find((j) => j.frame_event) || live.jobs[0];
  $("live-view").hidden = !job;
  $("live-empty").hidden = !!job;
  if (!job) {
    $("live-job-id").textContent = "";
    thumbnailIndex = null;
    return;
  }
  const e = job.event;
  $("live-job-id").textContent = job.job_id;
  $("live-phase").textContent = enumName(e.phase, "JOB_PHASE_").toLowerCase();
  $("live-progress").value = e.progress || 0;
  $("live-remaining").textContent = e.remainingSeconds >= 0 ? fixed(e.remainingSeconds, 1, "s") : "-";
  const counter = $("frame-counter");
  counter.dataset.frameEvents = String(job.frame_events);
  if (!job.frame_event) {
    counter.textContent = "-";
    return;
  }
  const f = job.frame_event.frame;
  counter.textContent = (f.frameIndex + 1) + " / " + f.frameCount;
  const st = f.statistics || {};
  $("live-z").textContent = fixed(f.zUm, 2, "µm");
  $("live-exposure").textContent = fixed(f.exposureUs, 0, "µs");
  $("live-mean").textContent = fixed(st.meanGrey, 1);
  $("live-stddev").textContent = fixed(st.stddevGrey, 1);
  $("live-saturated").textContent = fixed(st.saturatedPercent, 2, "%");
  $("live-under").textContent = fixed(st.underexposedPercent, 2, "%");
  if (enumName(job.frame_event.phase, "JOB_PHASE_") === "ACQUIRING") {
    refreshThumbnail(job.job_id, f.frameIndex).catch(() => {});
  }
}

async function previewImage(job) {
  const hasPreview = (job.result?.artifacts || []).some((a) => a.kind === "ARTIFACT_KIND_DEPTH_PREVIEW_PNG");
  if (!hasPreview) return null;
  if (!previewUrls.has(job.jobId)) {
    const res = await get("/api/jobs/" + encodeURIComponent(job.jobId) + "/preview.png");
    if (!res.ok) return null;  // asked again at the next refresh
    previewUrls.set(job.jobId, URL.createObjectURL(await res.blob()));
  }
  const url = previewUrls.get(job.jobId);
  const img = document.createElement("img");
  img.src = url;
  img.alt = "depth preview of " + job.jobId;
  return img;
}

function depthText(job) {
  const d = job.result?.depth;
  if (!d || !d.width) return "";
  let text = d.width + "×" + d.height + ", z " + fixed(d.zMinUm, 1) + "…" + fixed(d.zMaxUm, 1, "µm") +
             ", valid " + fixed(d.validPercent, 1, "%");
  if (d.hasGroundTruth) text += ", RMSE " + fixed(d.rmseUm, 2, "µm");
  return text;
}

// The overall verdict of a scan that ran a recipe (JobResult.inspection): OK, NOT OK or NOT
// DECIDABLE; nothing for other jobs.
function verdictBadge(job) {
  const inspection = job.result?.inspection;
  if (!inspection) return "";
  const verdict = enumName(inspection.verdict, "VERDICT_");
  const b = document.createElement("span");
  badge(b, verdict.replace(/_/g, " "), "verdict-" + verdict);
  return b;
}

async function refreshJobs() {
  const { jobs } = await getJson("/api/jobs?limit=15");
  const rows = [];
  for (const job of jobs) {
    const row = document.createElement("tr");
    row.dataset.jobId = job.jobId;
    const state = enumName(job.state, "JOB_STATE_");
    row.dataset.state = state;
    cell(row, job.jobId);
    cell(row, enumName(job.kind, "JOB_KIND_").toLowerCase());
    cell(row, job.label);
    const stateBadge = document.createElement("span");
    badge(stateBadge, state, "state-" + state);
    const stateCell = cell(row, stateBadge);
    if (job.errorMessage) stateCell.title = job.errorMessage;
    const verdictCell = cell(row, verdictBadge(job));
    verdictCell.className = "verdict";
    if (job.result?.inspection) {
      const i = job.result.inspection;
      row.dataset.verdict = enumName(i.verdict, "VERDICT_");
      verdictCell.title = "recipe " + i.recipeId + " v" + i.recipeVersion + (i.partId ? ", part " + i.partId : "");
    }
    cell(row, job.endTime ? new Date(job.endTime).toLocaleTimeString() : "");
    cell(row, depthText(job));
    cell(row, (await previewImage(job).catch(() => null)) || "");
    rows.push(row);
  }
  $("jobs").tBodies[0].replaceChildren(...rows);
}

// Each panel polls on its own timer; a failed poll shows in the header and is retried.
function poll(fn, interval) {
  const run = async () => {
    if (!needToken) {
      try {
        await fn();
        showConnection(true, "live");
      } catch (err) {
        if (!needToken) showConnection(false, "no connection");
      }
    }
    setTimeout(run, interval);
  };
  run();
}

$("token-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  sessionStorage.setItem(TOKEN_KEY, $("token-input").value.trim());
  needToken = false;
  $("token-form").hidden = true;
  previewUrls.clear();
});

poll(refreshStatus, STATUS_POLL_MS);
poll(refreshLive, LIVE_POLL_MS);
poll(refreshJobs, JOBS_POLL_MS);
